"""``vision-torsion demo [OUT_DIR]``: synthetic session → measurement → report."""

from __future__ import annotations

from . import add_common_options, progress_enabled
from .options import add_jobs_option


def register(sub) -> None:
    p = sub.add_parser(
        "demo",
        help="render a paper-like synthetic session, process it and write the report",
        description=(
            "Render the paper-like synthetic test session (six flexspline orientations, the bilinear "
            "stiffness-switching model), measure every image, analyse and write the report."
        ),
    )
    p.add_argument(
        "out_dir",
        nargs="?",
        default="vision-torsion-demo",
        metavar="OUT_DIR",
        help="demo folder (default ./vision-torsion-demo)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the synthetic session")
    p.add_argument("--force", action="store_true",
                   help="render the session again even if OUT_DIR holds one rendered with the same seed "
                        "(without it that session is reused and only what changed is measured); also "
                        "write into a non-empty OUT_DIR that is not a demo folder, replacing files "
                        "vision-torsion did not write")
    p.add_argument("--target", metavar="NAME|FILE",
                   help="an N-marker target in place of the two markers: a ready target's name (ring16, ring8, "
                        "grid5) or a target file; every image is measured from all its dots")
    add_jobs_option(p)
    add_common_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..report.session_report import run_demo
    from .report import print_summary

    rep = run_demo(args.out_dir, seed=args.seed, jobs=args.jobs, progress=progress_enabled(args), force=args.force,
                   target=args.target)
    print_summary(rep)
    return 1 if rep.n_failed else 0
