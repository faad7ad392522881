"""The test report: summary.json, stiffness_table.csv, PNG figures and one
self-contained report.html (issue 5).

:func:`write_report` is the one entry point; the ``report`` and ``demo`` commands
call it after :func:`vision_torsion.analysis.analyze_session`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from .. import __version__
from ..errors import AnalysisError
from ..fileio import atomic_write_bytes, atomic_write_text, write_csv, write_json
from . import figures as _fig
from .html import render_html
from .tables import STIFFNESS_TABLE_COLUMNS, metrics_table, stiffness_table

__all__ = ["ReportFiles", "write_report", "stiffness_table", "STIFFNESS_TABLE_COLUMNS", "export_name"]

_FAILED_COLUMNS = ["image", "orientation_deg", "cycle", "phase", "step", "message"]


@dataclass(frozen=True)
class ReportFiles:
    """Paths written by :func:`write_report`."""

    out_dir: Path
    summary_json: Path
    stiffness_table_csv: Path
    report_html: Path
    figures: tuple
    export_html: Path | None = None


def export_name(identity: dict | None) -> str | None:
    """The file name of the report to send out, from the test's identity:
    ``<gear>_<serial>_<date>_report.html`` with the entries given (None without
    any), each reduced to letters, digits, ``-`` and ``.`` so it is a safe file name
    on every system.

    Examples
    --------
    >>> export_name({"gear": "HFUC-20-100", "serial": "SN 123/45", "date": "2026-11-27"})
    'HFUC-20-100_SN-123-45_2026-11-27_report.html'
    >>> export_name({}) is None
    True
    """
    import re

    parts = []
    for key in ("gear", "serial", "date"):
        text = re.sub(r"[^A-Za-z0-9.-]+", "-", str((identity or {}).get(key) or "")).strip("-.")
        if text:
            parts.append(text[:60])
    return "_".join(parts) + "_report.html" if parts else None


def _failures(analysis, failures) -> pd.DataFrame:
    frames = [analysis.failed_images.reindex(columns=_FAILED_COLUMNS)]
    if failures is not None:
        extra = pd.DataFrame(failures)
        if "image" not in extra.columns or "message" not in extra.columns:
            raise AnalysisError("failures must have 'image' and 'message' for every failed image")
        frames.append(extra.reindex(columns=_FAILED_COLUMNS))
    frames = [f for f in frames if len(f)]
    if not frames:
        return pd.DataFrame(columns=_FAILED_COLUMNS)
    return pd.concat(frames, ignore_index=True).drop_duplicates(subset=["image"], keep="first")


def write_report(measurements_df, analysis, *, conditions: dict, out_dir, failures=None, extra_sections=None,
                 title="Torsional stiffness and hysteresis report", metadata=None, identity=None,
                 verdicts=None) -> ReportFiles:
    """Write summary.json, stiffness_table.csv, figures/*.svg and report.html.

    Parameters
    ----------
    measurements_df : pandas.DataFrame
        The measurements table the analysis came from (its row count is reported).
    analysis : vision_torsion.analysis.SessionAnalysis
        Result of :func:`vision_torsion.analysis.analyze_session`.
    conditions : dict
        Test conditions shown first in the report and stored under ``conditions`` in
        summary.json, e.g. ``{"rig": ..., "masses_kg": ..., "arm_radius_m": 0.05,
        "g_m_per_s2": 9.81}``; values must be JSON-serialisable.
    out_dir : path-like
        Output folder (created). Every file is written atomically.
    failures : pandas.DataFrame or list of dict, optional
        Further failed images (``image``, ``message``, optionally ``orientation_deg``,
        ``cycle``, ``phase``, ``step``), e.g. images that never reached the table.
    extra_sections : sequence of (title, html), optional
        Extra HTML sections appended to the page (trusted HTML).
    title : str
        Page title.
    metadata : dict, optional
        The test's metadata (gear, serial, operator, temperature, notes, ...) shown
        at the top of the page with the software version and date, and stored
        under ``metadata`` in summary.json.
    identity : dict, optional
        Who, what, when (keys ``gear``, ``serial``, ``operator``, ``date``,
        ``notes``; :func:`~vision_torsion.report.analyze.identity`): the first lines of
        page 1, ``identity`` in summary.json, and the name of a copy of the page to
        send out (:func:`export_name`).
    verdicts : sequence of vision_torsion.analysis.conformity.Verdict, optional
        The conformity verdicts against the catalogue (``[spec]``): the table on
        page 1 and ``conformity`` in summary.json with the decision rule. None: no
        specification was given.

    Returns
    -------
    ReportFiles

    Raises
    ------
    AnalysisError
        ``conditions`` not a dict, or failures without ``image``/``message``.
    """
    if not isinstance(conditions, dict):
        raise AnalysisError(f"conditions must be a dict of test conditions, got {type(conditions).__name__}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    failed = _failures(analysis, failures)
    stiff = stiffness_table(analysis)
    metrics = metrics_table(analysis)

    svgs = {
        "loops_overlay.svg": _fig.safe_svg(_fig.loops_overlay, analysis),
        "fit_residuals.svg": _fig.safe_svg(_fig.fit_residuals, analysis),
        "phase_stiffness.svg": _fig.safe_svg(_fig.phase_stiffness_chart, analysis),
        "orientation_effect.svg": _fig.safe_svg(_fig.orientation_chart, analysis),
    }
    fig_paths = tuple(atomic_write_bytes(out / "figures" / name, data) for name, data in svgs.items())

    summary = analysis.to_dict()
    summary["software"] = {"name": "vision-torsion", "version": __version__}
    summary["conditions"] = dict(conditions)
    summary["metadata"] = {k: v for k, v in (metadata or {}).items() if v is not None}
    summary["identity"] = dict(identity or {})
    if verdicts is not None:
        from ..analysis.conformity import DECISION_RULE

        summary["conformity"] = {"rule": DECISION_RULE, "verdicts": [v.to_dict() for v in verdicts]}
    export = export_name(identity)
    summary["counts"]["images"] = int(len(measurements_df))
    summary["counts"]["images_failed"] = int(len(failed))
    summary["failed_images"] = failed.to_dict(orient="records")
    summary["files"] = {"stiffness_table": "stiffness_table.csv", "report": "report.html",
                        "figures": [f"figures/{p.name}" for p in fig_paths]}
    if export:
        summary["files"]["export"] = export
    summary_path = write_json(out / "summary.json", summary)
    table_path = write_csv(out / "stiffness_table.csv", stiff)
    page = render_html(
        title=title, conditions=conditions, analysis=analysis, stiffness=stiff, metrics=metrics,
        figures={"overlay": svgs["loops_overlay.svg"], "stiffness": svgs["phase_stiffness.svg"],
                 "orientation": svgs["orientation_effect.svg"], "residuals": svgs["fit_residuals.svg"]},
        failed=failed, extra_sections=extra_sections or (), metadata=metadata, identity=identity,
        verdicts=verdicts,
    )
    html_path = atomic_write_text(out / "report.html", page)
    # the same page under the gear's name, to send out: report.html stays the name links use
    export_path = atomic_write_text(out / export, page) if export else None
    return ReportFiles(out_dir=out, summary_json=summary_path, stiffness_table_csv=table_path,
                       report_html=html_path, figures=fig_paths, export_html=export_path)
