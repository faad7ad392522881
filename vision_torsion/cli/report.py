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
            "stiffness_table.csv, figures and a self-contained report.html. A partly shot session is "
            "reported from the images that exist, the rest listed as pending. Exit status 0 when no "
            "image failed (pending rows included), 1 if any image failed, 2 unusable session."
        ),
    )
    p.add_argument("session_dir", metavar="SESSION_DIR")
    p.add_argument("-o", "--out-dir", metavar="OUT_DIR", help="output folder (default SESSION_DIR/results)")
    add_jobs_option(p)
    p.add_argument("--campaign", metavar="DB", help="also add the report to this campaign database")
    add_common_options(p)
    p.set_defaults(func=run)


def print_summary(rep) -> None:
    """What a user needs after a report: where it is and what went wrong."""
    pending = f", {rep.n_pending} pending (not photographed yet)" if rep.n_pending else ""
    from ..report.analyze import describe_withheld

    withheld = ("every figure withheld until the angle sign is right" if rep.angle_sign_advice
                else describe_withheld(rep.withheld_by_kind))
    print(f"{rep.n_images - rep.n_failed - rep.n_pending} of {rep.n_images} images measured{pending}; {withheld}")
    if rep.angle_sign_advice:
        print(rep.angle_sign_advice)
    for name in rep.unlisted:
        print(f"not in the manifest: {name}")
    print_verdict(rep)
    print(f"report: {rep.files.report_html}")


def print_verdict(res) -> None:
    """The conformity verdict (when session.toml has a [spec]) and the report's copy to send."""
    if res.verdicts is not None:
        from ..analysis.conformity import describe

        print(f"verdict against the catalogue: {describe(res.verdicts)}")
    if res.files.export_html is not None:
        print(f"report to send: {res.files.export_html}")


def run(args) -> int:
    from ..report.session_report import report_session

    rep = report_session(args.session_dir, out_dir=args.out_dir, jobs=args.jobs, progress=progress_enabled(args))
    print_summary(rep)
    if args.campaign:
        add_to_campaign(args.campaign, rep.files.out_dir)
    return 1 if rep.n_failed else 0


def add_to_campaign(db, folder) -> None:
    """Add a report folder just written to a campaign database, and say what it became."""
    from ..campaign import add_reports
    from .campaign import describe_added

    print(f"campaign {db}: {describe_added(add_reports(db, [folder]).results[0])}")
