"""``vision-torsion measure IMAGE_DIR --reference FILE [-o OUT_DIR] [--order sequence|independent]``."""

from __future__ import annotations

import sys

from . import add_common_options, failure_line, one_line, progress_enabled
from .options import add_marker_options, add_output_option, settings_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "measure",
        help="measure the rotation of every image in a folder against a reference image",
        description=(
            "Measure every image of IMAGE_DIR (natural name order) against the reference image "
            "and write angles.csv (image, angle_deg, angle_std_deg, status, message, marker "
            "centres, radii and residuals). Exit status 1 if any image failed or is ambiguous."
        ),
    )
    p.add_argument("image_dir", metavar="IMAGE_DIR", help="folder of images")
    p.add_argument("--reference", required=True, metavar="FILE", help="the reference image (angle 0)")
    add_output_option(p, "IMAGE_DIR/results; not IMAGE_DIR itself")
    p.add_argument(
        "--order", choices=("sequence", "independent"), default="sequence",
        help="sequence (default): images in name order were taken in small steps; identity is tracked, and "
             "with two equal markers an image that turned more than --max-step from the previous one is "
             "'ambiguous'. independent: each image is the smallest rotation from the reference (within ±90°)",
    )
    p.add_argument("--max-step", type=float, default=30.0, metavar="DEG",
                   help="sequence order: the largest turn between consecutive images taken as certain (default 30)")
    p.add_argument("--target", metavar="NAME|FILE",
                   help="an N-marker target (a ready one: ring16, ring8, grid5, pair_distinct; or a target "
                        "TOML file): the angle of each image from all its markers by a weighted rigid fit, "
                        "identity from the layout's index mark (no tracking; --order and --max-step do not "
                        "apply), and the shaft axis' shift (a camera bump) per image")
    p.add_argument("--overlay", metavar="DIR",
                   help="also write each image (and the reference) with its detected markers and "
                        "fitted circles drawn, as DIR/<name>_overlay.png")
    add_marker_options(p)
    add_common_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..measure import measure_folder

    if args.target:
        from ..rigid import measure_target_folder

        res = measure_target_folder(args.image_dir, reference=args.reference, target=args.target,
                                    out_dir=args.out_dir, settings=settings_from_args(args),
                                    progress=progress_enabled(args))
        for row in res.table.itertuples():
            if row.bump and row.status == "ok":
                print(one_line(f"  {row.image}: {row.message}"), file=sys.stderr)
    else:
        res = measure_folder(
            args.image_dir,
            reference=args.reference,
            out_dir=args.out_dir,
            settings=settings_from_args(args),
            progress=progress_enabled(args),
            order=args.order,
            max_step_deg=args.max_step,
        )
    print(f"{res.n_ok} of {res.n_ok + res.n_failed} images measured; wrote {res.path}")
    if args.overlay:
        from pathlib import Path

        from ..measure import list_images
        from ..overlay import write_overlays

        files = [Path(args.reference)] + [f for f in list_images(args.image_dir)
                                          if f.resolve() != Path(args.reference).resolve()]
        written = write_overlays(files, args.overlay, settings=settings_from_args(args),
                                 inputs=[args.image_dir, Path(args.reference).parent])
        print(f"wrote {len(written)} overlay(s) to {args.overlay}")
    for row in res.table.itertuples():
        if row.status != "ok":
            print(f"  {failure_line(row.image, row.message, status=row.status)}", file=sys.stderr)
    return 1 if res.n_failed else 0
