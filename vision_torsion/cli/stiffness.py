"""``vision-torsion stiffness``: stiffness curve, dead zone and meshing pairs of a record.

A thin layer over :func:`vision_torsion.stiffness.analyze_stiffness_curve`.
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path

from . import add_common_options

__all__ = ["register", "run", "default_output_dir"]

log = logging.getLogger(__name__)


def default_output_dir(data) -> Path:
    """``<DATA stem>_stiffness/`` beside DATA (the only thing created next to the input)."""
    p = Path(data)
    return p.with_name(f"{p.stem}_stiffness")


def register(subparsers) -> None:
    """Add the ``stiffness`` subcommand."""
    parser = subparsers.add_parser(
        "stiffness",
        help="stiffness curve K(T), backlash dead zone and meshing tooth pairs of a record",
        description=(
            "Analyse a torque-angle record: an encoder/torque-sensor CSV (time_s, torque_nm, "
            "input_pulses or input_angle_deg; needs --rig) or a camera-rig measurements.csv. "
            "Each cycle (camera: each loop) is analysed on its own, the virgin first loading "
            "apart, then summarised; a measurements.csv also gets stiffness_steps.csv "
            "(delta-torque/delta-angle per load step of every loop). "
            "Writes stiffness_curve.csv, stiffness_summary.json and three PNG plots."
        ),
    )
    parser.add_argument("data", metavar="DATA", help="record CSV or measurements.csv")
    parser.add_argument("--rig", metavar="FILE",
                        help="rig constants TOML ([rig] and [meshing] tables)")
    parser.add_argument("-o", "--out-dir", "--output", dest="out_dir", metavar="OUT_DIR",
                        help="output folder (default: <DATA stem>_stiffness/ beside DATA)")
    parser.add_argument("--method", choices=("polynomial", "spline"), default=None,
                        help="loading-branch fit (default: polynomial for an encoder record; "
                             "none for a measurements.csv, whose stiffness is given per load step)")
    parser.add_argument("--order", type=int, default=7, help="polynomial order (default: 7)")
    parser.add_argument("--cutoff-hz", type=float, default=None,
                        help="low-pass cut-off in Hz (default: 5%% of the sampling rate, at most 20 Hz)")
    parser.add_argument("--filter-order", type=int, default=4,
                        help="Butterworth order (default: 4)")
    parser.add_argument("--threshold-nm", type=float, default=None,
                        help="half-width of the zero-torque band in N·m (default: 5 noise stds)")
    parser.add_argument("--hold-speed", type=float, default=None, metavar="DEG_PER_S",
                        help="drive-speed dead-band in output deg/s: slower samples are holds "
                             "(default: a tenth of the typical drive speed)")
    add_common_options(parser)
    parser.set_defaults(func=run)


def run(args) -> int:
    """Run the analysis and write the results (replaced as a set or not at all);
    returns the exit status."""
    from ..fileio import check_output_dir, output_set, write_csv, write_json
    from ..plotting import save_figure
    from ..report.stiffness_figures import plot_meshing, plot_step_stiffness, plot_stiffness, plot_torque_angle
    from ..stiffness.analysis import analyze_stiffness_curve
    from ..stiffness.per_step import step_stiffness, summarise_steps
    from ..stiffness.rig import load_rig

    rig = load_rig(args.rig) if args.rig else None
    out = Path(args.out_dir) if args.out_dir else default_output_dir(args.data)
    if not Path(args.data).is_file():  # before the output folder is made
        from ..errors import RecordError

        raise RecordError(f"{args.data}: " + ("no such file" if not os.path.exists(args.data) else
                                              "not a regular file (a folder, a named pipe or a device); "
                                              "expected a torque-angle record CSV"))
    # files every run writes; the optional plots are checked when written (nothing replaced then)
    check_output_dir(out, replaces=["stiffness_curve.csv", "stiffness_summary.json", "torque_angle.png"])
    result = analyze_stiffness_curve(
        args.data, rig=rig, method=args.method, order=args.order, cutoff_hz=args.cutoff_hz,
        filter_order=args.filter_order, threshold_nm=args.threshold_nm,
        hold_speed_deg_per_s=args.hold_speed,
    )
    with output_set():
        written = [
            write_csv(out / "stiffness_curve.csv", result.to_frame()),
            write_json(out / "stiffness_summary.json", result.to_dict()),
            save_figure(plot_torque_angle(result), out / "torque_angle.png"),
        ]
        if result.curves:
            written.append(save_figure(plot_stiffness(result), out / "stiffness_torque.png"))
        if result.meshing is not None:
            written.append(save_figure(plot_meshing(result), out / "meshing_pairs.png"))
        if result.source == "camera":
            steps = step_stiffness(args.data)
            written.append(write_csv(out / "stiffness_steps.csv", steps))
            written.append(save_figure(plot_step_stiffness(steps, summarise_steps(steps)),
                                       out / "step_stiffness.png"))
    for c in result.curves:
        print(f"{c.kind}: K {c.stiffness_nm_per_rad.min():.4g} .. "
              f"{c.stiffness_nm_per_rad.max():.4g} N·m/rad over "
              f"{c.torque_nm[0]:.3g} .. {c.torque_nm[-1]:.3g} N·m (mean of {c.n_cycles} cycle(s))")
    for c in result.virgin:
        print(f"virgin loading ({c.kind}, not in the mean): K {c.stiffness_nm_per_rad.min():.4g} .. "
              f"{c.stiffness_nm_per_rad.max():.4g} N·m/rad")
    if result.backlash is not None:
        b = result.backlash
        print(f"dead zone: {b.width_deg:.4g} ± {b.width_std_deg:.2g} deg "
              f"({b.width_arcmin:.3g} arcmin), centre {b.centre_deg:.4g} deg, {b.n_cycles} cycle(s)")
    if result.meshing is not None:
        m = result.meshing
        wrap = ("" if m.max_wrap_angle_per_zone_rad is None
                else f", wrap angle of one zone {m.max_wrap_angle_per_zone_rad / math.pi:.4f}π rad")
        print(f"meshing pairs per zone: max {m.max_pairs_per_zone:.1f} "
              f"({2 * m.max_pairs_per_zone:.1f} in both zones) at {m.torque_at_max_nm:.3g} N·m{wrap}")
    for note in result.notes:
        print(f"note: {note}")
    print(f"wrote {len(written)} files to {out}")
    return 0
