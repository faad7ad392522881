"""What a user asks of a campaign: add reports, list them, compare gears, follow a
figure over a life test, export the records. Each is one function the command line
calls."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from ..errors import CampaignError
from .folder_record import read_report
from .stats import difference, fit_trend
from .store import AddResult, CampaignDB

__all__ = [
    "AddOutcome",
    "add_reports",
    "list_reports",
    "compare_serials",
    "figure_trend",
    "export_campaign",
    "HEADLINE_FIGURES",
    "EXPORT_FORMATS",
]

log = logging.getLogger(__name__)

#: The figures a campaign shows first (catalogue stiffness, lost motion, hysteresis loss, loop energy).
HEADLINE_FIGURES = ("k1", "k2", "k3", "lost_motion_4pct", "lost_motion_3pct", "hysteresis_loss", "loop_energy")
EXPORT_FORMATS = ("csv", "parquet")


@dataclass(frozen=True)
class AddOutcome:
    """Adding a list of report folders: one :class:`AddResult` per report that was
    read, and ``(folder, message)`` for each that was not (the rest went on)."""

    results: tuple[AddResult, ...]
    failures: tuple[tuple[str, str], ...]

    @property
    def added(self) -> int:
        return sum(r.status == "added" for r in self.results)

    @property
    def present(self) -> int:
        return sum(r.status == "present" for r in self.results)


def add_reports(db_path, folders, *, test_hours=None, progress=None) -> AddOutcome:
    """Add report folders to a campaign database (created when missing).

    Parameters
    ----------
    db_path : str or Path
        The campaign database file.
    folders : iterable of str or Path
        Report folders (each holding ``summary.json``).
    test_hours : float, optional
        Running hours before the test (a life test), for every folder given.
    progress : callable, optional
        Called as ``progress(done, total, folder)`` after each folder.

    Returns
    -------
    AddOutcome
        A folder that is not a usable report is a failure with its message; the other
        folders are added, each in its own transaction.

    Raises
    ------
    CampaignError
        The database cannot be opened or written (nothing half-written).
    """
    folders = [Path(f) for f in folders]
    results, failures = [], []
    with CampaignDB(db_path, write=True) as db:
        for i, folder in enumerate(folders, 1):
            try:
                record = read_report(folder, test_hours=test_hours)
            except CampaignError as exc:
                if exc.reason not in ("not_a_report", "schema_version"):
                    raise
                failures.append((str(folder), str(exc)))
            except OSError as exc:
                failures.append((str(folder), f"{exc.filename or folder}: {exc.strerror or exc}"))
            else:
                results.append(db.add(record))
            if progress is not None:
                progress(i, len(folders), folder)
    return AddOutcome(tuple(results), tuple(failures))


def _wide(db: CampaignDB, reports, figures):
    """One row per report: identity columns, then value/u95/verdict per figure."""
    frame = db.figures(reports["id"].tolist(), figure=list(figures))
    out = reports[["id", "model", "serial", "version", "test_date", "test_hours", "verdict"]].copy()
    for name in figures:
        part = frame[frame["figure"] == name].set_index("report_id")
        out[name] = out["id"].map(part["value"])
        out[f"{name}_u95"] = out["id"].map(part["u95"])
        out[f"{name}_flag"] = out["id"].map(part["flagged"])
    return out


def list_reports(db_path, *, serial=None, model=None, since=None, figures=("k1", "lost_motion_4pct")):
    """Records of a campaign (every version), with the named figures, oldest test first."""
    with CampaignDB(db_path) as db:
        return _wide(db, db.reports(serial=serial, model=model, since=since), figures)


def compare_serials(db_path, serials, *, figures=HEADLINE_FIGURES):
    """Figures of each serial's newest report side by side, each against the first.

    Returns a DataFrame, one row per (figure, serial): ``value, u95, unit``, and for
    every serial after the first its difference from the first with its U95, E_n and
    ``significant`` (E_n > 1; :func:`~vision_torsion.campaign.stats.difference`).

    Raises
    ------
    CampaignError
        A serial with no report in the campaign (``reason="not_found"``).
    """
    import pandas as pd

    serials = [str(s) for s in serials]
    with CampaignDB(db_path) as db:
        reports = db.reports(serial=serials, latest_only=True)
        missing = [s for s in serials if s not in set(reports["serial"])]
        if missing:
            raise CampaignError(f"{db_path}: no report of serial {', '.join(missing)}", reason="not_found")
        # the newest test of each serial
        newest = reports.sort_values(["test_date", "id"]).groupby("serial").tail(1).set_index("serial")
        frame = db.figures(newest["id"].tolist(), figure=list(figures))
    by_id = {rid: s for s, rid in newest["id"].items()}
    frame["serial"] = frame["report_id"].map(by_id)
    rows = []
    for name in figures:
        part = frame[frame["figure"] == name].set_index("serial")
        if part.empty:
            continue
        first = part.loc[serials[0]] if serials[0] in part.index else None
        for s in serials:
            if s not in part.index:
                continue
            r = part.loc[s]
            row = {"figure": name, "serial": s, "unit": r["unit"], "value": r["value"], "u95": r["u95"],
                   "flagged": bool(r["flagged"])}
            if s != serials[0] and first is not None:
                d = difference(r["value"], r["u95"], first["value"], first["u95"])
                row.update(diff=d.value, diff_u95=d.u95, en=d.en, significant=d.significant, note=d.reason)
            rows.append(row)
    return pd.DataFrame(rows)


def figure_trend(db_path, figure, *, by="time", serial=None, model=None):
    """A figure over time or test hours, with its weighted straight-line trend.

    Parameters
    ----------
    by : {"time", "test-hours"}
        The x axis: days since the first test, or the reports' test hours.

    Returns
    -------
    (DataFrame, Trend)
        The points (``test_date, x, value, std, u95, serial``) with the fitted line
        at each (``trend``) and the half-width of its 95 % band (``trend_band95``;
        NaN where the trend is withheld), and the trend of
        :func:`~vision_torsion.campaign.stats.fit_trend` (per day, or per hour).
    """
    import pandas as pd

    if by not in ("time", "test-hours"):
        raise CampaignError(f"--by {by!r}: expected 'time' or 'test-hours'", reason="bad_option")
    with CampaignDB(db_path) as db:
        reports = db.reports(serial=serial, model=model, latest_only=True)
        frame = db.figures(reports["id"].tolist(), figure=figure)
    if frame.empty:
        raise CampaignError(f"{db_path}: no report has the figure {figure!r}", reason="not_found")
    points = reports.set_index("id").loc[frame["report_id"]].reset_index()
    points["value"] = frame["value"].to_numpy()
    points["std"] = frame["std"].to_numpy()
    points["u95"] = frame["u95"].to_numpy()
    if by == "time":
        dates = pd.to_datetime(points["test_date"], errors="coerce")
        points["x"] = (dates - dates.min()).dt.total_seconds() / 86400.0
    else:
        points["x"] = pd.to_numeric(points["test_hours"], errors="coerce")
    points = points.sort_values("x", kind="stable")
    trend = fit_trend(points["x"], points["value"], points["std"])
    points["trend"], points["trend_band95"] = trend.band(points["x"].to_numpy(float))
    return points[["test_date", "test_hours", "x", "value", "std", "u95", "trend", "trend_band95", "serial",
                   "version"]], trend


def export_campaign(db_path, out_path, *, fmt="csv"):
    """Every figure of every record, one row each, with the record's identity.

    Raises
    ------
    CampaignError
        An unknown format, or parquet without its library (pyarrow).
    """
    from ..fileio import atomic_write_bytes

    if fmt not in EXPORT_FORMATS:
        raise CampaignError(f"--format {fmt!r}: expected one of {', '.join(EXPORT_FORMATS)}", reason="bad_option")
    with CampaignDB(db_path) as db:
        reports = db.reports()
        frame = db.figures(reports["id"].tolist())
    reports = reports.drop(columns=["identity"]).rename(columns={"id": "report_id", "verdict": "report_verdict"})
    table = reports.merge(frame.rename(columns={"verdict": "figure_verdict"}), on="report_id")
    if fmt == "csv":
        data = table.to_csv(index=False, lineterminator="\n").encode("utf-8")
    else:
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise CampaignError("--format parquet needs pyarrow: pip install 'vision-torsion[parquet]'",
                                reason="missing_library") from None
        import io

        buffer = io.BytesIO()
        table.to_parquet(buffer, index=False)
        data = buffer.getvalue()
    atomic_write_bytes(out_path, data)
    return len(table)
