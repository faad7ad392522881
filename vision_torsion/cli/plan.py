"""``vision-torsion plan``: write a new session folder for the six-orientation protocol."""

from __future__ import annotations

import argparse

from . import add_common_options

__all__ = ["register", "run"]


def register(subparsers) -> None:
    """Add the ``plan`` subcommand."""
    p = subparsers.add_parser(
        "plan",
        help="plan a test session (session.toml, manifest.csv, capture sheet)",
        description="Write session.toml, manifest.csv (every image of the protocol in "
        "capture order, with the file name to save it under) and a printable "
        "capture_sheet.md into OUT_DIR. Per orientation: a reference image at zero "
        "load, an unphotographed pre-load to +Tmax, then CYCLES x (positive unloading, "
        "negative loading, negative unloading, positive loading). Torque is "
        "tau = 2*m*g*r with m the mass on each pan.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("out_dir", metavar="OUT_DIR", help="session folder to create")
    size = p.add_mutually_exclusive_group(required=True)
    size.add_argument("--max-torque", type=float, metavar="NM",
                      help="largest torque magnitude in N·m (snapped down to whole steps; the "
                           "nearest achievable maxima are named)")
    size.add_argument("--steps", type=int, metavar="N",
                      help="steps per phase instead of --max-torque")
    p.add_argument("--step-mass", type=float, required=True, metavar="KG",
                   help="mass added to or removed from each pan per step, kg")
    p.add_argument("--arm-radius", type=float, required=True, metavar="M",
                   help="radius of the torque disk at the wires, m")
    p.add_argument("--orientations", type=float, nargs="+", metavar="DEG",
                   default=[0, 60, 120, 180, 240, 300],
                   help="flexspline orientations, degrees")
    p.add_argument("--cycles", type=int, default=1, help="cycles per orientation")
    p.add_argument("--gravity", type=float, default=9.81, metavar="M_PER_S2",
                   help="local gravitational acceleration, m/s²")
    p.add_argument("--gravity-std", type=float, default=0.0, metavar="M_PER_S2",
                   help="1σ uncertainty of g, m/s²")
    p.add_argument("--arm-radius-std", type=float, default=0.0, metavar="M",
                   help="1σ uncertainty of the arm radius, m")
    p.add_argument("--mass-tolerance", type=float, default=1e-4, metavar="KG",
                   help="± tolerance of one weight piece, kg (uniform: σ = tol/√3)")
    p.add_argument("--friction-std", type=float, default=0.0, metavar="NM",
                   help="1σ uncertainty of the pulley friction torque, N·m")
    p.add_argument("--polarity", choices=("dark", "bright"), default="dark",
                   help="dark markers on a bright disk, or the reverse")
    p.add_argument("--radius-range", type=float, nargs=2, metavar=("MIN", "MAX"),
                   help="marker radius range in pixels")
    p.add_argument("--target", default="equal", metavar="equal|distinct|NAME|FILE",
                   help="two equal markers; two of clearly different radii (recommended for two: "
                        "which marker is which is then certain at any angle); or an N-marker target, "
                        "a ready one (ring16, ring8, grid5, pair_distinct) or a target TOML file "
                        "(print it with `vision-torsion target`), written to session.toml as [target]")
    p.add_argument("--angle-sign", type=int, choices=(1, -1), default=1,
                   help="factor making positive torque give a positive angle")
    p.add_argument("--image-type", default=".png", metavar="SUFFIX",
                   help="file type of the images to save")
    p.add_argument("--force", action="store_true",
                   help="overwrite an existing session.toml and manifest.csv, and files "
                        "vision-torsion did not write")
    p.add_argument("--preconditioning", type=int, default=0, metavar="N",
                   help="full cycles to ±Tmax before each reference image (not photographed)")
    p.add_argument("--closing", action="store_true",
                   help="end each orientation with a zero-torque 'closing' image")
    p.add_argument("--rated-torque", type=float, metavar="NM",
                   help="the gear's rated torque T_R, N·m: names the lost-motion levels at ±3 %% "
                        "and ±4 %% of it (whole numbers of step masses; refused when the pieces "
                        "cannot realise them)")
    p.add_argument("--catalogue", metavar="FILE.toml",
                   help="the gear type's catalogue values: [gear] ratio, rated_torque_nm, t1_nm, t2_nm and [spec] "
                        "limits, copied into session.toml (the report judges the gear against them)")
    g = p.add_argument_group("the test's identity: on the capture sheet (blank lines when not given), in "
                             "session.toml's [gear]/[test], the report and summary.json")
    for key in ("gear", "serial", "operator", "date", "notes"):
        g.add_argument(f"--{key}", metavar="TEXT")
    p.add_argument("--no-pdf", action="store_true",
                   help="write capture_sheet.html only (default: also capture_sheet.pdf when "
                        "Chromium is installed)")
    add_common_options(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Plan the session; returns 0."""
    import contextlib
    from pathlib import Path

    from ..fileio import check_output_dir
    from ..session.plan import plan_config, plan_session

    created = not Path(args.out_dir).exists()
    check_output_dir(args.out_dir)  # writable, with space, before anything is written
    try:
        plan = plan_session(_config(args, plan_config), args.out_dir, image_suffix=args.image_type,
                            overwrite=args.force, preconditioning_cycles=args.preconditioning,
                            closing=args.closing, pdf=not args.no_pdf)
    except BaseException:
        if created:  # a refused plan leaves no empty folder behind (only the one this run made)
            with contextlib.suppress(OSError):
                Path(args.out_dir).rmdir()
        raise
    print(f"{plan.folder}: {len(plan.rows)} images in "
          f"{len(plan.config.protocol.orientations_deg)} orientations, "
          f"{plan.steps_per_phase} steps per phase, max torque "
          f"{plan.max_torque_nm:.5f} N·m"
          + ("" if plan.exact else
             f" (requested {plan.requested_max_torque_nm:g} N·m is not a whole number of "
             f"steps; the nearest achievable maxima are {plan.nearest_max_torques_nm[0]:.5f} "
             f"N·m with {plan.steps_per_phase} steps and {plan.nearest_max_torques_nm[1]:.5f} "
             f"N·m with {plan.steps_per_phase + 1}; or give --steps)"))
    if plan.rated_torque_nm is not None:
        print(plan.lost_motion_text())
    pdf = plan.folder / "capture_sheet.pdf"
    sheet = pdf if pdf.is_file() and not args.no_pdf else plan.folder / "capture_sheet.html"
    print(f"print {sheet} and save each image under the name it gives (or keep the "
          "camera's names and run `vision-torsion bind` or `watch`)")
    return 0


def _config(args, plan_config):
    """The session's configuration from the command line's options."""
    return plan_config(
        max_torque_nm=args.max_torque, steps=args.steps, step_mass_kg=args.step_mass,
        arm_radius_m=args.arm_radius, orientations_deg=args.orientations,
        cycles=args.cycles, gravity_m_per_s2=args.gravity,
        gravity_std_m_per_s2=args.gravity_std, arm_radius_std_m=args.arm_radius_std,
        mass_tolerance_kg=args.mass_tolerance, friction_torque_std_nm=args.friction_std,
        polarity=args.polarity, radius_range=args.radius_range,
        angle_sign=args.angle_sign, target=args.target,
        header={k: getattr(args, k) for k in ("gear", "serial", "operator", "date", "notes")
                if getattr(args, k)},
        rated_torque_nm=args.rated_torque, catalogue=args.catalogue)
