"""``vision-torsion report SESSION_DIR [-o OUT_DIR]``."""

from __future__ import annotations

from . import add_common_options, progress_enabled
from .options import add_jobs_option


def register(sub) -> None:
    p = sub.add_parser(
        "report",
        help="process a session (if needed) and write its hysteresis report",
        description=(
            "Measure what is new in SESSION_DIR, analyse the torque-angle data and write summary.json, "
            "stiffness_table.csv, figures and a self-contained report.html. Exit status 1 if any image failed."
        ),
    )
    p.add_argument("session_dir", metavar="SESSION_DIR")
    p.add_argument("-o", "--out-dir", metavar="OUT_DIR", help="output folder (default SESSION_DIR/results)")
    add_jobs_option(p)
    add_common_options(p)
    p.set_defaults(func=run)


def print_summary(rep) -> None:
    """What a user needs after a report: where it is and what went wrong."""
    print(f"{rep.n_images - rep.n_failed} of {rep.n_images} images measured; {rep.n_issues} figure(s) not computable (reasons in the report)")
    print(f"report: {rep.files.report_html}")


def run(args) -> int:
    from ..report.session_report import report_session

    rep = report_session(args.session_dir, out_dir=args.out_dir, jobs=args.jobs, progress=progress_enabled(args))
    print_summary(rep)
    return 1 if rep.n_failed else 0
