"""``vision-torsion analyze TABLE.csv [--session FILE.toml] [-o OUT_DIR]``."""

from __future__ import annotations

from . import add_common_options
from .options import add_output_option


def register(sub) -> None:
    p = sub.add_parser(
        "analyze",
        help="analyse a torque-angle table (measurements.csv or another rig's) and write its report",
        description=(
            "Analyse TABLE.csv (a measurements.csv, or a table from elsewhere: see the options below) and write "
            "summary.json, stiffness_table.csv, figures and report.html. With --session, the rig's weight pieces "
            "carry the torque uncertainty and the optional [gear]/[test] tables (rated torque, catalogue T1/T2, "
            "gear ratio, secant interval, operator, ...) are used. A figure that does not fit or would be "
            "interpolated across a gap is withheld or flagged with its reason. Exit status 0, 1 if an image of "
            "the table failed, 2 unusable input."
        ),
    )
    p.add_argument("table", metavar="TABLE.csv")
    p.add_argument("--session", metavar="FILE.toml", help="session.toml with the rig and the optional [gear]/[test]")
    p.add_argument("--catalogue", metavar="FILE.toml",
                   help="catalogue values of the gear type ([gear] and [spec]): K1-K3 at its T1/T2, lost motion "
                        "at its T_R, and the conformity verdict against its [spec] limits")
    t = p.add_argument_group("a table from elsewhere (comma, semicolon with decimal comma, or tab; units from the "
                             "headers; without a phase column, phases and cycles from the torque reversals)")
    t.add_argument("--columns", metavar="MAP", help="which header is which: torque=Torque [N m],angle=Angle [arcmin] "
                   "(also torque_std, angle_std, orientation, image, status, message)")
    t.add_argument("--units", metavar="MAP", help="units of headers that carry none: torque=N m,angle=arcmin")
    t.add_argument("--angle-std", type=float, metavar="DEG", help="1σ of every angle, deg, when the table has none")
    t.add_argument("--torque-std", type=float, metavar="NM", help="1σ of every torque, N·m, when the table has none")
    rig = p.add_argument_group(
        "rig without a session.toml (all four together; without them or --session the figures are flagged "
        "'torque uncertainty not modelled')")
    rig.add_argument("--piece-tolerance", type=float, metavar="KG", help="tolerance of one weight piece, ±kg")
    rig.add_argument("--pieces-per-step", type=int, metavar="N", help="pieces added to each pan per step")
    rig.add_argument("--gravity", type=float, metavar="M/S2", help="local g, m/s²")
    rig.add_argument("--arm-radius", type=float, metavar="M", help="arm radius r, m")
    add_output_option(p, "TABLE's folder/<TABLE stem>_analysis")
    p.add_argument("--campaign", metavar="DB", help="also add the report to this campaign database")
    add_common_options(p)
    # a short batch job: its own process runs it with the cyclic GC off (cli._ends_process)
    p.set_defaults(func=run, gc_off=True)


def run(args) -> int:
    from ..report.analyze import analyze_table, describe_withheld
    from ..table_import import parse_column_map

    units = parse_column_map(args.units, what="--units") if args.units else None
    given = {"piece_tolerance_kg": args.piece_tolerance, "pieces_per_step": args.pieces_per_step,
             "gravity_m_per_s2": args.gravity, "arm_radius_m": args.arm_radius}
    rig_options = given if any(v is not None for v in given.values()) else None
    res = analyze_table(args.table, session=args.session, out_dir=args.out_dir,
                        columns=parse_column_map(args.columns) if args.columns else None, units=units,
                        angle_std_deg=args.angle_std, torque_std_nm=args.torque_std, catalogue=args.catalogue,
                        rig_options=rig_options)
    for note in res.import_notes:
        print(f"table: {note}")
    if not res.analysis.settings.get("torque_uncertainty_modelled", True):
        print("torque uncertainty not modelled (no --session and no --piece-tolerance/--pieces-per-step/--gravity/"
              "--arm-radius): every figure is flagged")
    withheld = ("every figure withheld until the angle sign is right" if res.angle_sign_advice
                else describe_withheld(res.withheld_by_kind, res.n_flagged))
    print(f"{res.n_rows} rows, {res.n_failed} image(s) not usable; {withheld}")
    if res.angle_sign_advice:
        print(res.angle_sign_advice)
    from .report import print_verdict

    print_verdict(res)
    print(f"report: {res.files.report_html}")
    if args.campaign:
        from .report import add_to_campaign

        add_to_campaign(args.campaign, res.files.out_dir)
    return 1 if res.n_failed else 0

