"""``vision-torsion campaign add|list|compare|trend|report|export DB ...``."""

from __future__ import annotations

import sys

from . import add_common_options
from .options import add_output_option


def register(sub) -> None:
    p = sub.add_parser(
        "campaign",
        help="keep every tested gear's reports in one database: add, list, compare, trend, report, export",
        description=(
            "A campaign database (one SQLite file) holds one immutable record per report: the gear's identity, "
            "the test's metadata, every figure with its uncertainty, flags and verdict, and the hashes of the "
            "inputs. Re-adding a report is a no-op; a changed report is stored as a new version."
        ),
    )
    kinds = p.add_subparsers(dest="kind", metavar="ACTION")
    kinds.required = True

    add = kinds.add_parser("add", help="add report folders (results folders holding summary.json)")
    add.add_argument("db", metavar="DB")
    add.add_argument("folders", metavar="RESULTS_DIR", nargs="+")
    add.add_argument("--test-hours", type=float, metavar="H", help="running hours before these tests (life test)")
    add_common_options(add)
    add.set_defaults(func=run_add)

    lst = kinds.add_parser("list", help="list the records, oldest test first")
    lst.add_argument("db", metavar="DB")
    lst.add_argument("--serial", action="append", help="only this serial (repeatable)")
    lst.add_argument("--model", help="only this gear model")
    lst.add_argument("--since", metavar="YYYY-MM-DD", help="only tests on or after this date")
    add_common_options(lst)
    lst.set_defaults(func=run_list)

    cmp_ = kinds.add_parser("compare", help="figures of gears side by side, each against the first")
    cmp_.add_argument("db", metavar="DB")
    cmp_.add_argument("serials", metavar="SERIAL", nargs="+")
    add_common_options(cmp_)
    cmp_.set_defaults(func=run_compare)

    trend = kinds.add_parser("trend", help="a figure over time or test hours, with its trend")
    trend.add_argument("db", metavar="DB")
    trend.add_argument("--figure", required=True, help="e.g. k1, lost_motion_4pct, hysteresis_loss")
    trend.add_argument("--by", choices=("time", "test-hours"), default="time")
    trend.add_argument("--serial", help="only this serial (a life test)")
    trend.add_argument("--model", help="only this gear model")
    add_common_options(trend)
    trend.set_defaults(func=run_trend)

    rep = kinds.add_parser("report", help="the campaign's HTML page: batch table, control charts, capability")
    rep.add_argument("db", metavar="DB")
    add_output_option(rep, "the current folder")
    rep.add_argument("--model", help="only this gear model")
    rep.add_argument("--catalogue", metavar="FILE.toml",
                     help="the gear type's catalogue file ([gear] and [spec], as plan --catalogue takes it); "
                          "default: the limits each report was judged against")
    add_common_options(rep)
    rep.set_defaults(func=run_report)

    exp = kinds.add_parser("export", help="every figure of every record as CSV or Parquet")
    exp.add_argument("db", metavar="DB")
    exp.add_argument("out", metavar="OUT_FILE")
    exp.add_argument("--format", choices=("csv", "parquet"), default="csv")
    add_common_options(exp)
    exp.set_defaults(func=run_export)


def run_add(args) -> int:
    from ..campaign import add_reports

    def progress(done, total, folder):
        if total >= 20 and (done % 100 == 0 or done == total):
            print(f"{done}/{total} report folders read", file=sys.stderr, flush=True)

    outcome = add_reports(args.db, args.folders, test_hours=args.test_hours, progress=progress)
    if len(outcome.results) <= 20:
        for result in outcome.results:
            print(f"{result.source}: {describe_added(result)}")
    for folder, message in outcome.failures:
        print(f"failed: {message}", file=sys.stderr)
    print(f"{outcome.added} added, {outcome.present} already there, {len(outcome.failures)} not a usable report")
    return 1 if outcome.failures else 0


def describe_added(result) -> str:
    """What adding a report did, in words."""
    what = f"added as version {result.version}" if result.status == "added" else "already there"
    return f"{what} (record {result.report_id})"


def _print_frame(frame) -> None:
    if frame.empty:
        print("no records")
        return
    shown = frame.copy()
    for column in [c for c in shown.columns if shown[c].dtype.kind == "O"]:
        shown[column] = shown[column].map(lambda v: "—" if v is None else v)
    print(shown.to_string(index=False, na_rep="—", float_format=lambda v: f"{v:.6g}"))


def run_list(args) -> int:
    from ..campaign import list_reports

    frame = list_reports(args.db, serial=args.serial, model=args.model, since=args.since)
    _print_frame(frame.drop(columns=["id"]))
    return 0


def run_compare(args) -> int:
    from ..campaign import compare_serials

    _print_frame(compare_serials(args.db, args.serials))
    print("E_n = |difference| / sqrt(U95_a² + U95_b²); significant when E_n > 1 (ISO 13528). "
          "Gears tested on one rig share the weights' errors, so E_n is conservative there.")
    return 0


def run_trend(args) -> int:
    from ..campaign import figure_trend

    points, trend = figure_trend(args.db, args.figure, by=args.by, serial=args.serial, model=args.model)
    _print_frame(points)
    per = "day" if args.by == "time" else "hour"
    if trend.slope is None:
        print(f"trend withheld: {trend.reason}")
    else:
        print(f"trend: {trend.slope:.4g} ± {2 * trend.slope_std:.2g} per {per} (±2σ; n = {trend.n}, "
              f"p = {trend.p_value:.3g}, χ²_red = {trend.chi2_red:.3g})")
    return 0


def run_report(args) -> int:
    from ..campaign import catalogue_limits, write_campaign_report

    limits = catalogue_limits(args.catalogue) if args.catalogue else None
    rep = write_campaign_report(args.db, args.out_dir or ".", model=args.model, limits=limits)
    print(f"{rep.n_reports} report(s); campaign report: {rep.path}")
    return 0


def run_export(args) -> int:
    from ..campaign import export_campaign

    n = export_campaign(args.db, args.out, fmt=args.format)
    print(f"{n} rows written to {args.out}")
    return 0
