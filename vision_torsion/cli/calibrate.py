"""``vision-torsion calibrate plane|target ...``: compute and save a plane correction."""

from __future__ import annotations

from . import add_common_options, progress_enabled
from .options import add_marker_options, add_output_option, settings_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "calibrate",
        help="compute a plane/lens correction (self-calibration or a target) and save it",
        description="Compute a correction for a camera not square to the disk and save it (TOML or JSON by suffix).",
    )
    kinds = p.add_subparsers(dest="kind", metavar="KIND")
    kinds.required = True
    plane = kinds.add_parser(
        "plane",
        help="self-calibrate from a rotation sequence (no target needed)",
        description=(
            "Fit the disk-plane homography from the markers' motion over a rotation sequence: the "
            "images of IMAGE_DIR in natural name order after the reference. The disk must turn by "
            "at least 40 degrees in total."
        ),
    )
    plane.add_argument("image_dir", metavar="IMAGE_DIR", help="folder of the rotation sequence")
    plane.add_argument("--reference", required=True, metavar="FILE", help="the reference image (first of the sequence)")
    _add_output(plane, "plane_correction.toml")
    plane.add_argument("--fit-k1", action="store_true", help="also fit radial distortion k1 (weakly determined)")
    plane.add_argument("--k1", type=float, default=0.0, help="known radial distortion k1 (default 0)")
    plane.add_argument(
        "--focal-length", type=float, metavar="PX", help="f of the distortion model (default max(width, height))"
    )
    add_marker_options(plane)
    add_common_options(plane)
    plane.set_defaults(func=run_plane)
    target = kinds.add_parser(
        "target",
        help="calibrate from chessboard or circle-grid images",
        description="Lens distortion (3+ views) and the plane homography (the first view, target on the disk).",
    )
    target.add_argument(
        "images", nargs="+", metavar="IMAGE", help="target images; the first shows the target on the disk"
    )
    target.add_argument("--pattern", choices=("chessboard", "circles"), default="chessboard")
    target.add_argument(
        "--pattern-size", nargs=2, type=int, required=True, metavar=("COLS", "ROWS"), help="inner corners or circles"
    )
    target.add_argument("--square-mm", type=float, default=1.0, help="pattern pitch in mm (does not affect angles)")
    _add_output(target, "target_correction.toml")
    add_common_options(target)
    target.set_defaults(func=run_target)


def _add_output(parser, default_name: str) -> None:
    add_output_option(parser, "the current folder")
    parser.add_argument(
        "--name",
        default=default_name,
        metavar="FILE",
        help=f"file name of the correction in OUT_DIR; .toml or .json (default {default_name})",
    )


def _destination(args):
    """OUT_DIR/NAME, its suffix checked and the folder writable, before any work."""
    from pathlib import Path

    from ..correction import check_suffix
    from ..errors import CalibrationError
    from ..fileio import check_output_dir

    name = Path(args.name)
    if name.name != args.name:
        raise CalibrationError(f"--name {args.name}: a file name, not a path (the folder is -o OUT_DIR)")
    check_suffix(name)
    out = check_output_dir(Path(args.out_dir) if args.out_dir else Path.cwd(), replaces=[name.name])
    return out / name


def _report(corr, path) -> int:
    shown = {k: v for k, v in corr.info.items() if not isinstance(v, list) or len(v) <= 2}
    print(
        f"wrote {path} ({corr.method}); "
        + ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in shown.items())
    )
    return 0


def run_plane(args) -> int:
    from pathlib import Path

    from ..calibration.selfcal import calibrate_plane
    from ..measure import list_images

    destination = _destination(args)  # refuse a bad name or folder before the work
    ref = Path(args.reference)
    files = [f for f in list_images(args.image_dir) if f.resolve() != ref.resolve()]
    corr = calibrate_plane(
        [ref, *files],
        settings=settings_from_args(args),
        fit_k1=args.fit_k1,
        k1=args.k1,
        focal_length_px=args.focal_length,
        progress=progress_enabled(args),
    )
    return _report(corr, corr.save(destination))


def run_target(args) -> int:

    from ..calibration.target import calibrate_from_target

    destination = _destination(args)
    corr = calibrate_from_target(
        args.images, pattern=args.pattern, pattern_size=tuple(args.pattern_size), square_mm=args.square_mm
    )
    return _report(corr, corr.save(destination))
