"""``vision-torsion watch SESSION_DIR [--camera-dir DIR]``."""

from __future__ import annotations

from . import add_common_options
from .options import add_output_option

__all__ = ["register", "run"]


def register(subparsers) -> None:
    """Add the ``watch`` subcommand."""
    p = subparsers.add_parser(
        "watch",
        help="follow a test while it is shot: each photograph measured, checked and shown live",
        description="Follow the camera's folder (--camera-dir, else SESSION_DIR/images) while the "
        "test is shot. Each photograph is measured as soon as the camera has finished writing "
        "it (closed the file, or its size stopped changing), bound to the next planned row, printed "
        "(row, torque, angle, Δangle) and drawn on a "
        "live page, OUT_DIR/live.html, that reloads itself. Warnings come at that image or the "
        "next, naming it: no movement or the wrong direction, a step out of line with its "
        "neighbours (a forgotten or extra weight, a missed shot; the next image tells it from the "
        "gear's own change of stiffness), two shots swapped (with the bind fix), an inverted "
        "angle_sign (one line), the camera or the target moved, markers not found, a blurred or "
        "saturated image. A file still being written holds back the files after it; one that "
        "stays incomplete for --give-up seconds keeps its row, as failed. A photograph replaced "
        "under its name is measured again and said so. The camera folder is only read. Ctrl-C stops (run it again to "
        "resume; measurements are shared with process through its cache) and the report is "
        "written. Exit status (after Ctrl-C too): 0 no photograph had a warning, 1 some did, "
        "2 unusable input.",
    )
    p.add_argument("session_dir", metavar="SESSION_DIR", help="the session folder")
    p.add_argument("--camera-dir", metavar="DIR",
                   help="the camera's folder (read only); default SESSION_DIR/images")
    add_output_option(p, "SESSION_DIR/results")
    p.add_argument("--poll", type=float, default=0.5, metavar="S",
                   help="longest time between looks at the folder (a file closed in it is seen at once, "
                        "through the filesystem's notifications)")
    p.add_argument("--no-events", action="store_true",
                   help="only look at the folder every --poll seconds, without the filesystem's "
                        "notifications (chosen by itself, and said so, when the watchdog package is "
                        "missing, the folder is on a network share, or the notification limit is reached)")
    p.add_argument("--settle", type=float, default=1.0, metavar="S",
                   help="seconds a file must stay unchanged before it is read")
    p.add_argument("--give-up", type=float, default=10.0, metavar="S",
                   help="seconds a settled file may stay incomplete (a slow card, a network "
                        "share) before it is bound to its row as failed; the files after it "
                        "wait for it meanwhile, so none takes its row")
    p.add_argument("--no-report", action="store_true", help="do not write the report at the end")
    add_common_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Watch until Ctrl-C or every planned image is in; 1 when a photograph had a warning."""
    from ..session.watch import watch_session

    def report(session_dir, out_dir):
        from ..report.session_report import report_session

        rep = report_session(session_dir, out_dir=out_dir, jobs=1)
        print(f"report: {rep.files.report_html}")
        return rep

    res = watch_session(args.session_dir, camera_dir=args.camera_dir, out_dir=args.out_dir,
                        poll_s=args.poll, settle_s=args.settle, give_up_s=args.give_up,
                        finish=None if args.no_report else report,
                        events="poll" if args.no_events else "auto")
    print(f"{res.n_bound} of {res.n_rows} planned images bound; {res.n_warnings} with warnings; "
          f"live page {res.page}")
    return 1 if res.n_warnings else 0
