"""The campaign report: one HTML page over every gear of a campaign — the batch
table, control charts of the headline figures, conformity and capability."""

from __future__ import annotations

import html
from dataclasses import dataclass
from pathlib import Path

from ..analysis.conformity import DECISION_RULE, DECISIONS
from ..errors import CampaignError
from ..htmlpage import fmt_value, image_tag, page_html, table_html, unit_words
from .stats import capability, control_limits
from .store import CampaignDB
from .views import HEADLINE_FIGURES

__all__ = ["CampaignReport", "write_campaign_report", "catalogue_limits", "REPORT_NAME"]

REPORT_NAME = "campaign_report.html"
# the figures of the batch table (all of them are charted)
_BATCH_COLUMNS = ("k1", "k2", "lost_motion_4pct", "hysteresis_loss")


@dataclass(frozen=True)
class CampaignReport:
    """The written page and what it holds."""

    path: Path
    n_reports: int
    figures: tuple[str, ...]


def _limits_by_figure(limits, long) -> dict:
    """figure -> (lower, upper): from ``limits`` (conformity Limits) when given, else
    the limit the newest report judged each figure against."""
    out = {}
    if limits is not None:
        for limit in limits:
            lower, upper = out.get(limit.figure, (None, None))
            out[limit.figure] = (limit.value, upper) if limit.kind == "min" else (lower, limit.value)
        return out
    stored = long.dropna(subset=["limit_kind"])
    for name, part in stored.groupby("figure", sort=False):
        last = part.iloc[-1]
        out[name] = (last["limit_value"], None) if last["limit_kind"] == "min" else (None, last["limit_value"])
    return out


def catalogue_limits(path, *, figures=HEADLINE_FIGURES):
    """The conformity limits of a gear type's catalogue file (``[gear]`` and
    ``[spec]``, as ``plan --catalogue`` takes it), in the figures' units.

    Raises
    ------
    SessionError
        The file is missing, not TOML, or has invalid keys (named).
    """
    from ..report.analyze import spec_limits
    from ..session.config import load_catalogue

    _, spec = load_catalogue(path)
    return spec_limits(spec, figures)


def _chart_html(usable, *, name: str, unit: str, spec_limits) -> str:
    """A figure's control chart with its caption (or why there is none)."""
    if usable.empty:
        return f'<p class="muted">{html.escape(name)}: withheld in every report, nothing to chart.</p>'
    limits = control_limits(usable["value"].tolist())
    caption = f"{name}: {len(usable)} report(s)"
    if limits.centre is None:
        caption += f" — control limits withheld: {limits.reason}"
    elif limits.out_of_control:
        caption += f"; {len(limits.out_of_control)} beyond the control limits"
    img = image_tag(_chart(usable, limits, spec_limits, name=name, unit=unit), name, mime="image/png")
    return f"<figure>{img}<figcaption>{html.escape(caption)}</figcaption></figure>"


def _capability_row(usable, *, name: str, unit: str, lower, upper) -> dict:
    """A figure's row of the capability table."""
    cap = capability(usable["value"].tolist(), lower=lower, upper=upper)
    return {
        "figure": name, "unit": unit_words(unit), "n": cap.n,
        "limit": _limit_text(lower, upper),
        "mean": cap.mean if cap.mean is not None else float(usable["value"].mean()) if len(usable) else None,
        "sd": cap.sd, "Ppk": cap.ppk, "Ppk 95 % lower bound": cap.ppk_lower95,
        "within limits": "—" if cap.conforming is None else f"{100 * cap.conforming:.1f} %",
        "note": cap.reason,
    }


def _limit_text(lower, upper) -> str:
    parts = ([f"≥ {lower:g}"] if lower is not None else []) + ([f"≤ {upper:g}"] if upper is not None else [])
    return ", ".join(parts) or "—"


def _chart(points, limits, spec_limits, *, name: str, unit: str) -> bytes:
    from ..plotting import fixed_figure, png_bytes

    fig = fixed_figure(5.0, 2.4, left=0.8, bottom=0.45, top=0.15)
    ax = fig.add_subplot()
    x = list(range(1, len(points) + 1))
    ax.errorbar(x, points["value"], yerr=points["u95"].fillna(0.0), fmt="o", ms=3, lw=0.8, color="#1f4e79",
                ecolor="#9db4cc", label="report (± U95)")
    if limits.centre is not None:
        ax.axhline(limits.centre, color="#444", lw=0.9, label="centre")
        for level in (limits.lower, limits.upper):
            ax.axhline(level, color="#b42318", lw=0.9, ls="--")
        out = [i for i in limits.out_of_control]
        if out:
            ax.plot([x[i] for i in out], points["value"].to_numpy()[out], "s", mfc="none", mec="#b42318", ms=8,
                    label="beyond the control limits")
    for level in spec_limits:
        if level is not None:
            ax.axhline(level, color="#1a7f37", lw=1.2, ls=":", label="specification")
    ax.set_xlabel("report, in test order")
    ax.set_ylabel(f"{name} ({unit_words(unit)})")
    ax.legend(loc="best", fontsize=7, frameon=False)
    # raster: a campaign's thousand points draw in half the time of SVG, and print sharp at 150 dpi
    return png_bytes(fig, dpi=150)


def write_campaign_report(db_path, out_dir, *, model=None, limits=None, figures=HEADLINE_FIGURES) -> CampaignReport:
    """Write ``campaign_report.html`` for the newest version of every report.

    Parameters
    ----------
    db_path : str or Path
        The campaign database.
    out_dir : str or Path
        Output folder (created).
    model : str, optional
        Only this gear model.
    limits : sequence of vision_torsion.analysis.conformity.Limit, optional
        Catalogue limits in the figures' units (N·m/rad, degrees), e.g. from a
        catalogue file (:func:`catalogue_limits`); default: the limits the newest
        report judged each figure against (its ``[spec]``).

    Notes
    -----
    Control charts are Shewhart individuals charts in test order (ISO 7870-2:
    centre ± 3 σ̂, σ̂ = mean moving range / 1.128), withheld below
    :data:`~vision_torsion.campaign.stats.MIN_CONTROL_POINTS` reports; capability is
    Ppk against the specification with its 95 % lower bound
    (:func:`~vision_torsion.campaign.stats.capability`).
    """
    import pandas as pd

    from ..fileio import atomic_write_text, check_output_dir

    out_dir = check_output_dir(out_dir)
    with CampaignDB(db_path) as db:
        reports = db.reports(model=model, latest_only=True)
        if reports.empty:
            raise CampaignError(f"{db_path}: no report{' of model ' + model if model else ''} in the campaign",
                                reason="not_found")
        long = db.figures(reports["id"].tolist(), figure=list(figures))
    order = {rid: i for i, rid in enumerate(reports["id"])}
    long = long.assign(order=long["report_id"].map(order)).sort_values("order")
    limits_by_figure = _limits_by_figure(limits, long)

    batch = reports[["serial", "test_date", "version", "verdict"]].copy()
    charts, capability_rows, conformity_rows = [], [], []
    present = [f for f in figures if (long["figure"] == f).any()]
    for name in present:
        part = long[long["figure"] == name]
        values = part.set_index("report_id")
        if name in _BATCH_COLUMNS:
            batch[f"{name} ({unit_words(part['unit'].iloc[0])})"] = [
                fmt_value(values["value"].get(r), values["u95"].get(r)) for r in reports["id"]]
        unit = str(part["unit"].iloc[0])
        usable = part[~part["withheld"]]
        lower, upper = limits_by_figure.get(name, (None, None))
        charts.append(_chart_html(usable, name=name, unit=unit, spec_limits=(lower, upper)))
        capability_rows.append(_capability_row(usable, name=name, unit=unit, lower=lower, upper=upper))
        verdicts = part["verdict"].dropna()
        if len(verdicts):
            counts = verdicts.value_counts()
            conformity_rows.append({"figure": name, "reports judged": int(len(verdicts)),
                                    **{k.replace("_", " "): int(counts.get(k, 0)) for k in DECISIONS}})
    verdict_counts = reports["verdict"].fillna("no [spec]").str.replace("_", " ").value_counts()
    n = len(reports)
    parts = [
        f"<h1>Campaign{' — ' + html.escape(model) if model else ''}</h1>",
        f'<p class="muted">{html.escape(str(Path(db_path).name))}: {n} report(s) (newest version of each test), '
        f"{reports['serial'].nunique()} serial(s), tests {html.escape(str(reports['test_date'].min()))} to "
        f"{html.escape(str(reports['test_date'].max()))}.</p>",
        "<h2>Verdicts</h2>",
        table_html(pd.DataFrame({"verdict": verdict_counts.index, "reports": verdict_counts.to_numpy()}),
                   left=("verdict",)),
        "<h2>Conformity per figure</h2>",
        table_html(pd.DataFrame(conformity_rows), left=("figure",)) if conformity_rows
        else '<p class="muted">No report carries a conformity verdict (no [spec] in their session.toml).</p>',
        f'<p class="muted">{html.escape(DECISION_RULE)}</p>' if conformity_rows else "",
        "<h2>Capability</h2>",
        '<p class="muted">Ppk = min(USL − mean, mean − LSL) / 3s over the newest report of each test, with its '
        "one-sided 95 % lower bound; withheld with the reason when there are too few reports or no limit.</p>",
        table_html(pd.DataFrame(capability_rows), left=("figure", "unit", "limit", "note")),
        "<h2>Control charts</h2>",
        '<p class="muted">Individuals charts in test order: centre line and ±3σ̂ limits (σ̂ from the mean '
        "moving range); bars are each report's U95; dotted: the specification.</p>",
        f'<div class="grid">{"".join(charts)}</div>',
        "<h2>Batch</h2>",
        '<p class="muted">One row per test (its newest version): each figure ± its U95.</p>',
        table_html(batch.rename(columns={"test_date": "test date"}), left=("serial", "test date", "verdict")),
    ]
    path = out_dir / REPORT_NAME
    atomic_write_text(path, page_html("Campaign report", parts))
    return CampaignReport(path, n, tuple(present))
