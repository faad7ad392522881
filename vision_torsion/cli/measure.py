"""``vision-torsion measure IMAGE_DIR --reference FILE [-o OUT_DIR]``."""

from __future__ import annotations

import sys

from . import add_common_options, failure_line, progress_enabled
from .options import add_marker_options, add_output_option, settings_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "measure",
        help="measure the rotation of every image in a folder against a reference image",
        description=(
            "Measure every image of IMAGE_DIR (natural name order) against the reference image "
            "and write angles.csv (image, angle_deg, angle_std_deg, status, message, marker "
            "centres, radii and residuals). Exit status 1 if any image failed."
        ),
    )
    p.add_argument("image_dir", metavar="IMAGE_DIR", help="folder of images")
    p.add_argument("--reference", required=True, metavar="FILE", help="the reference image (angle 0)")
    add_output_option(p, "IMAGE_DIR/results; not IMAGE_DIR itself")
    add_marker_options(p)
    add_common_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..measure import measure_folder

    res = measure_folder(
        args.image_dir,
        reference=args.reference,
        out_dir=args.out_dir,
        settings=settings_from_args(args),
        progress=progress_enabled(args),
    )
    print(f"{res.n_ok} of {res.n_ok + res.n_failed} images measured; wrote {res.path}")
    for row in res.table.itertuples():
        if row.status != "ok":
            print(f"  {failure_line(row.image, row.message)}", file=sys.stderr)
    return 1 if res.n_failed else 0
