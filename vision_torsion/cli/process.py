"""``vision-torsion process``: measure a session folder into measurements.csv."""

from __future__ import annotations

import sys

from . import add_common_options, failure_line, one_line, progress_enabled
from .options import add_jobs_option

__all__ = ["register", "run"]


def register(subparsers) -> None:
    """Add the ``process`` subcommand."""
    p = subparsers.add_parser(
        "process",
        help="measure every image of a session folder into measurements.csv",
        description="Validate the whole session (session.toml, manifest.csv, image "
        "files) and stop with every problem listed if anything is wrong; then measure "
        "every image in parallel and write measurements.csv to the output folder. "
        "Re-running measures only new or changed images (cache in OUT_DIR/.vision-torsion-cache). "
        "A partly shot session is not an error: rows whose image does not exist yet "
        "are written with status 'pending' and listed, as are image files no row "
        "names. Exit status: 0 no image failed (pending rows included), 1 some image "
        "failed, 2 unusable session.",
    )
    p.add_argument("session_dir", metavar="SESSION_DIR", help="the session folder")
    p.add_argument("-o", "--out-dir", metavar="OUT_DIR",
                   help="output folder (default: SESSION_DIR/results)")
    add_jobs_option(p)
    add_common_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Process the session; 0 when every image was measured, 1 when some failed."""
    from ..session.process import process_session
    from ..session.worker import reuse_freed_memory

    reuse_freed_memory()  # this process measures and ends: its page faults were 0.3 s of a demo run
    result = process_session(args.session_dir, out_dir=args.out_dir, jobs=args.jobs,
                             progress=progress_enabled(args))
    for (image, message), status in zip(result.failures, result.failure_statuses):
        print(failure_line(image, message, status=status), file=sys.stderr)
    print_pending(result, quiet=args.quiet)
    print(f"{result.measurements_path}: {result.n_ok} ok, {result.n_failed} failed, "
          f"{result.n_pending} pending of {result.n_images} images ({result.n_measured} "
          f"measured, {result.n_cached} from the cache)")
    return 0 if result.ok else 1


def print_pending(result, *, quiet: bool = False, limit: int = 10) -> None:
    """List the rows still to photograph and the image files no row names."""
    if result.pending and not quiet:
        print(f"{result.n_pending} row(s) pending (not photographed yet), first: "
              + ", ".join(image for image, _ in result.pending[:limit])
              + (" ..." if result.n_pending > limit else ""))
    for name in result.unlisted:
        print(one_line(f"not in the manifest: {name}"), file=sys.stderr)
