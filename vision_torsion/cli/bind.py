"""``vision-torsion bind SESSION_DIR CAMERA_DIR [--by time|name]``."""

from __future__ import annotations

import sys

from . import add_common_options, one_line

__all__ = ["register", "run"]


def register(subparsers) -> None:
    """Add the ``bind`` subcommand."""
    p = subparsers.add_parser(
        "bind",
        help="bind a camera's files (IMG_0001.JPG ...) to the session's manifest rows",
        description="Assign the photographs of CAMERA_DIR, in capture order, to the rows of "
        "the session's manifest in protocol order, and write SESSION_DIR/binding.json (the "
        "camera folder is only read: nothing is renamed, copied or written there). Copies "
        "and non-images are set aside; leftover files and rows without a file are listed. "
        "Every photograph is measured (sharing process's cache) and each angle step is "
        "checked against the plan: an extra or a missed shot, two swapped shots are found and the "
        "fix proposed, naming the file and the row; an inverted angle_sign, a camera bump, "
        "blurred, saturated or unreadable photographs are named. Exit status: 0 everything fits, 1 something to look "
        "at (leftovers, rows without a file, steps that do not fit), 2 unusable input.",
    )
    p.add_argument("session_dir", metavar="SESSION_DIR", help="the session folder")
    p.add_argument("camera_dir", metavar="CAMERA_DIR", help="the camera's folder of photographs")
    p.add_argument("--by", choices=("time", "name"), default="time",
                   help="capture order: EXIF capture time then file time (default), or "
                        "natural name order (IMG_2 < IMG_10)")
    p.add_argument("--skip", action="append", default=[], metavar="FILE",
                   help="leave this camera file out (an extra shot); repeatable")
    p.add_argument("--missing", action="append", default=[], type=int, metavar="LINE",
                   help="this manifest line (CSV line number) was not photographed; repeatable")
    p.add_argument("--swap", action="append", default=[], nargs=2, metavar=("FILE", "OTHER"),
                   help="these two camera files were taken the other way round: exchange their "
                        "places in the capture order; repeatable")
    p.add_argument("--dry-run", action="store_true", help="check and propose; write nothing")
    add_common_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Bind; 0 when everything fits, 1 when something needs a look."""
    from ..session.bind import bind_session

    def say(text, file=None):  # one line each: a newline in a camera file name must not forge another
        print(one_line(text), file=file)

    res = bind_session(args.session_dir, args.camera_dir, by=args.by, skip=args.skip,
                       missing=args.missing, swap=args.swap, write=not args.dry_run)
    err = sys.stderr
    for name, why in res.ignored:
        say(f"set aside: {name}: {why}", file=err)
    n_bound = len(res.binding.images)
    say(f"{res.n_files} photograph(s), {res.n_rows} row(s): {n_bound} bound"
        + (f"; wrote {res.binding_path}" if res.binding_path else " (dry run, nothing written)"))
    if res.leftovers:
        say(f"{len(res.leftovers)} file(s) left over after the last row: "
            + ", ".join(res.leftovers), file=err)
    declared = set(res.binding.missing)
    gaps = [(line, image) for line, image in res.unphotographed if line not in declared]
    if gaps:
        say(f"{len(gaps)} row(s) without a photograph: "
            + ", ".join(f"line {line} ({image})" for line, image in gaps[:10])
            + (" ..." if len(gaps) > 10 else ""), file=err)
    for text in res.diagnoses:
        say(f"check: {text}", file=err)
    for text in res.warnings:
        say(f"step does not fit: {text}", file=err)
    for fix in res.fixes:
        say(f"proposed fix: {fix.message}")
    if res.command:
        say(f"to apply: {res.command}")
    if res.fixes:
        for text in res.remaining:
            say(f"not explained by the binding (re-take that step?): {text}", file=err)
    return 0 if res.ok else 1
