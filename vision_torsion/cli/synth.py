"""``vision-torsion synth accuracy|session OUT_DIR --scene FILE``: synthetic test folders."""

from __future__ import annotations

from . import add_common_options, progress_enabled
from .options import add_force_option, check_new_folder


def register(sub) -> None:
    p = sub.add_parser(
        "synth",
        help="render synthetic image folders of known rotation",
        description="Render synthetic camera images of a torque disk whose rotation is known exactly.",
    )
    kinds = p.add_subparsers(dest="kind", metavar="KIND")
    kinds.required = True
    a = kinds.add_parser(
        "accuracy",
        help="an accuracy-check folder: images, reference.csv and truth.csv",
        description="Render images at the scene's sweep angles (or --angles) with reference.csv and truth.csv.",
    )
    a.add_argument("out_dir", metavar="OUT_DIR")
    a.add_argument(
        "--scene",
        required=True,
        metavar="FILE",
        help="scene TOML file, or the name of a ready scene: standard, small_target, low_contrast, "
        "distractors, jpeg, twelve_bit, tilted",
    )
    a.add_argument("--angles", nargs="+", type=float, metavar="DEG", help="rotation angles in degrees (CCW)")
    a.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    add_force_option(a, "OUT_DIR")
    add_common_options(a)
    a.set_defaults(func=run_accuracy)
    s = kinds.add_parser(
        "session",
        help="a full test session folder whose angles follow the bilinear hysteresis model",
        description=(
            "Render a session folder (session.toml, manifest.csv, images, truth.csv) whose angles follow "
            "the paper's bilinear stiffness-switching model at every load step."
        ),
    )
    s.add_argument("out_dir", metavar="OUT_DIR")
    s.add_argument(
        "--scene",
        required=True,
        metavar="FILE",
        help="scene TOML file with a [session] table, or a ready scene's name: paper_session",
    )
    s.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    s.add_argument("--target", metavar="NAME|FILE",
                   help="an N-marker target in place of the scene's two markers: a ready target's name (ring16, "
                        "ring8, grid5) or a target file; the dot farthest from the shaft at the scene's marker "
                        "distance")
    add_force_option(s, "OUT_DIR")
    add_common_options(s)
    s.set_defaults(func=run_session)


def run_accuracy(args) -> int:
    from ..synthetic import load_scene
    from ..synthetic.folders import write_accuracy_folder

    check_new_folder(args.out_dir, force=args.force)
    from ..fileio import check_output_dir

    check_output_dir(args.out_dir)  # writable, with space, before rendering

    out = write_accuracy_folder(
        load_scene(args.scene), args.out_dir, angles_deg=args.angles, seed=args.seed, progress=progress_enabled(args)
    )
    print(f"wrote accuracy folder {out}")
    return 0


def run_session(args) -> int:
    from ..synthetic.session import load_session_scene, write_session_folder

    check_new_folder(args.out_dir, force=args.force)
    from ..fileio import check_output_dir

    check_output_dir(args.out_dir)  # writable, with space, before rendering
    scene, spec = load_session_scene(args.scene)
    out = write_session_folder(
        scene, spec, args.out_dir, seed=args.seed, progress=progress_enabled(args), overwrite=args.force,
        target=args.target,
    )
    print(f"wrote session folder {out}")
    return 0
