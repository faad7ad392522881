"""``vision-torsion check-accuracy DIR [-o OUT_DIR] [--tolerance DEG] [--spec FILE]``."""

from __future__ import annotations

import sys
from dataclasses import replace

from . import add_common_options, progress_enabled
from .options import add_marker_options, add_output_option


def register(sub) -> None:
    p = sub.add_parser(
        "check-accuracy",
        help="check the angle measurement against reference angles (reference.csv)",
        description=(
            "Measure every image listed in DIR/reference.csv (image,reference_angle_deg; the first row "
            "is the reference image) against the first, and write accuracy.csv, accuracy.json and "
            "accuracy.png to OUT_DIR (default DIR/results). Exit status 0 when every error is within "
            "the tolerance, 1 when not (or an image failed), 2 for unusable input."
        ),
    )
    p.add_argument("folder", metavar="DIR", help="folder with the images and reference.csv")
    add_output_option(p, "DIR/results; DIR itself is refused: nothing is written among the images")
    p.add_argument("--tolerance", type=float, metavar="DEG", help="pass band ±DEG (default: the spec's, else 0.02)")
    p.add_argument(
        "--spec",
        metavar="FILE",
        help="a check spec (TOML file), or the name of a ready one: rotary_stage, synthetic_selfcheck",
    )
    add_marker_options(p)
    # marker options given on the command line override the spec's; unset ones do not
    p.set_defaults(polarity=None, fit=None, pair=None, func=run)
    add_common_options(p)


def run(args) -> int:
    from ..calibration.accuracy import AccuracySpec, check_accuracy, load_spec
    from ..settings import MeasureSettings

    spec = load_spec(args.spec) if args.spec else AccuracySpec()
    given = {k: v for k, v in (("polarity", args.polarity), ("fit", args.fit), ("pair", args.pair)) if v is not None}
    if args.radius_range:
        given["radius_range"] = tuple(args.radius_range)
    settings = replace(spec.settings or MeasureSettings(), **given)
    res = check_accuracy(
        args.folder,
        out_dir=args.out_dir,
        tolerance_deg=args.tolerance,
        spec=spec,
        settings=settings,
        correction=args.correction,
        progress=progress_enabled(args),
    )
    verdict = "PASSED" if res.passed else "FAILED"
    print(
        f"{verdict}: n = {res.n}, bias {res.bias_deg:+.5f}°, RMS {res.rms_deg:.5f}°, "
        f"max |error| {res.max_abs_error_deg:.5f}°, U95 {res.u95_deg:.5f}° (k = {res.coverage_factor:.2f}), "
        f"tolerance ±{res.tolerance_deg:g}°; wrote {res.out_dir}"
    )
    for row in res.table.itertuples():
        if row.status.startswith("failed"):
            print(f"  {row.image}: {row.status}", file=sys.stderr)
    return 0 if res.passed else 1
