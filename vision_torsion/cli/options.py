"""Command-line options shared by several commands (markers, jobs, -o, --force).

``--force`` is consistent: commands that create a new folder (``plan``, ``synth
accuracy``, ``synth session``, ``demo``) refuse an existing non-empty one without it;
commands that write results into an output folder (``measure``, ``process``,
``report``, ``check-accuracy``, ``stiffness``, ``calibrate``, ``analyze``, ``bind``,
``watch``) replace their own result files there and need no ``--force``. A file in
the way that the tool cannot prove it wrote (the folder contract,
:mod:`vision_torsion.fileio`) is refused by every command, by name, unless ``--force``.
"""

from __future__ import annotations

from ..settings import FIT_METHODS, POLARITIES, MeasureSettings

__all__ = ["add_marker_options", "add_jobs_option", "settings_from_args", "add_output_option",
           "add_force_option", "check_new_folder"]


def add_marker_options(parser) -> None:
    """--polarity, --radius-range, --fit, --pair and --correction."""
    g = parser.add_argument_group("markers")
    g.add_argument(
        "--polarity",
        choices=POLARITIES,
        default="dark",
        help="dark markers on a bright disk (default) or bright on dark",
    )
    g.add_argument("--radius-range", nargs=2, type=float, metavar=("MIN", "MAX"), help="marker radius range in pixels")
    g.add_argument(
        "--fit",
        choices=FIT_METHODS,
        default="pixels",
        help="marker fit: pixels (default: the disc model fitted to the pixels), or a fit to "
        "edge points: geometric, algebraic (the paper's), ellipse",
    )
    g.add_argument(
        "--pair",
        choices=("largest", "distinct"),
        default="largest",
        help="the target: the two largest markers of equal radius (default), or two of "
        "clearly different radii (identity certain at any angle)",
    )
    g.add_argument(
        "--correction",
        metavar="FILE",
        help="plane/lens correction (TOML or JSON from `calibrate`) applied to the marker centres",
    )


def add_jobs_option(parser) -> None:
    """-j/--jobs: how many images are read and decoded at once."""
    parser.add_argument(
        "-j",
        "--jobs",
        type=int,
        metavar="N",
        help="images read and decoded at once (default: all cores); up to 3 "
        "as threads of this process, more as worker processes",
    )


def settings_from_args(args) -> MeasureSettings:
    """MeasureSettings from parsed marker options."""
    return MeasureSettings(
        polarity=args.polarity,
        radius_range=tuple(args.radius_range) if args.radius_range else None,
        fit=args.fit,
        pair=getattr(args, "pair", "largest") or "largest",
        correction=getattr(args, "correction", None),
    )


def add_output_option(parser, default: str) -> None:
    """-o/--out-dir OUT_DIR: the output folder; one meaning in every command."""
    parser.add_argument("-o", "--out-dir", metavar="OUT_DIR", help=f"output folder (default: {default})")


def add_force_option(parser, what: str = "the folder") -> None:
    """--force: a command that creates a new folder refuses a non-empty one without it."""
    parser.add_argument("--force", action="store_true",
                        help=f"write into {what} even if it exists and is not empty, replacing files "
                             "vision-torsion did not write")


def check_new_folder(path, *, force: bool) -> None:
    """Refuse a non-empty existing folder (a command that creates one) unless `force`.

    Raises
    ------
    OutputError
        The folder exists and holds files, and `force` is false; or it is a file.
    """
    from pathlib import Path

    from ..errors import OutputError

    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{p}: cannot write there: it is a file, not a folder")
    if not force and p.is_dir() and any(p.iterdir()):
        raise OutputError(f"{p}: folder exists and is not empty; use --force to write into it")
