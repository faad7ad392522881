"""``vision-torsion target OUT.pdf``: print an N-marker target at true scale."""

from __future__ import annotations

import argparse

from . import add_common_options

__all__ = ["register", "run"]

#: Index dot diameter over the other dots' (a clear 25 %, above the 15 % minimum).
INDEX_RATIO = 1.25


def register(subparsers) -> None:
    """Add the ``target`` subcommand."""
    p = subparsers.add_parser(
        "target",
        help="write a printable N-marker target (vector PDF at true scale, with a scale bar)",
        description="Write a ring or a grid of dots (or a ready/own target description) as a one-page "
        "vector PDF at true scale, with a 50 mm scale bar to check the print and a cross on the shaft "
        "axis. Dot 0 is the index mark (25 % larger) unless --no-index. Lengths take mm, cm or in "
        "(80mm, 8cm; a bare number is mm). Prints the [target] table for session.toml.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("out", metavar="OUT.pdf", help="the PDF to write")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--layout", choices=("ring", "grid"), help="a ring about the shaft or a grid centred on it")
    src.add_argument("--target", metavar="NAME|FILE",
                     help="a ready target (ring16, ring8, grid5, pair_distinct) or a target TOML file")
    p.add_argument("--markers", type=int, default=16, help="ring: number of dots")
    p.add_argument("--diameter", default="80mm", metavar="LEN", help="ring: diameter of the circle of dot centres")
    p.add_argument("--rows", type=int, default=5, help="grid: rows")
    p.add_argument("--columns", type=int, default=5, help="grid: columns")
    p.add_argument("--pitch", default="10mm", metavar="LEN", help="grid: centre-to-centre spacing")
    p.add_argument("--dot-diameter", metavar="LEN",
                   help="dot diameter (default: ring, the largest that keeps a gap of one radius beside the "
                        "index dot, at most 12 %% of the ring; grid, 40 %% of the pitch)")
    p.add_argument("--no-index", action="store_true",
                   help="all dots equal (the target then repeats under a turn: its images come out ambiguous)")
    p.add_argument("--page", choices=("a4", "a3", "letter"), default="a4", help="paper size")
    p.add_argument("--force", action="store_true", help="overwrite OUT.pdf if it exists")
    add_common_options(p)
    p.set_defaults(func=run)


def build_target(args):
    """The :class:`~vision_torsion.targets.Target` the options describe."""
    from ..targets import grid_target, load_target, ring_dot_diameter_mm, ring_target
    from ..targetsheet import parse_length_mm

    if args.target:
        return load_target(args.target)
    if args.layout == "ring":
        diameter = parse_length_mm(args.diameter, name="--diameter")
        dot = (parse_length_mm(args.dot_diameter, name="--dot-diameter") if args.dot_diameter
               else ring_dot_diameter_mm(max(args.markers, 2), diameter))
        return ring_target(args.markers, diameter_mm=diameter, dot_diameter_mm=round(dot, 3),
                           index_diameter_mm=None if args.no_index else round(INDEX_RATIO * dot, 3))
    pitch = parse_length_mm(args.pitch, name="--pitch")
    dot = parse_length_mm(args.dot_diameter, name="--dot-diameter") if args.dot_diameter else 0.4 * pitch
    return grid_target(args.rows, args.columns, pitch_mm=pitch, dot_diameter_mm=round(dot, 3),
                       index_diameter_mm=None if args.no_index else round(INDEX_RATIO * dot, 3))


def run(args) -> int:
    """Write the PDF and print the target's [target] table; returns 0."""
    from ..targetsheet import write_target_pdf

    target = build_target(args)
    out = write_target_pdf(args.out, target, page=args.page, overwrite=args.force)
    if not args.quiet:
        print(f"{out}: target {target.name!r}, {target.n_markers} dots ({target.layout}); print at actual "
              "size and check the 50 mm scale bar")
        turns = target.symmetry_turns_deg()
        if turns:
            print(f"warning: the target maps onto itself under turns of {turns[0]:g}°: which dot is which "
                  "cannot be told, its images will be reported ambiguous")
        print("for session.toml:\n" + target.to_toml())
    return 0
