"""One self-contained HTML page: inline CSS, images as base64 data URIs, no scripts,
no network access.

The page prints on A4 (``@page``/``@media print`` rules): figures and table rows are
never split across pages, long tables repeat their header row, nothing scrolls or
is clipped (wide tables wrap their cells and shrink their font), and the header
carries the software version, the date and the test's metadata.
"""

from __future__ import annotations

import base64
import html
import math

import numpy as np
import pandas as pd

__all__ = ["render_html", "fmt_value"]

_CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:0;color:#1d2430;background:#f6f7f9}
main{max-width:1180px;margin:0 auto;padding:24px 28px 60px;background:#fff}
h1{font-size:26px;margin:0 0 4px}
h2{font-size:19px;margin:34px 0 10px;border-bottom:2px solid #d8dde6;padding-bottom:4px}
h3{font-size:15px;margin:18px 0 6px}p,li{line-height:1.45;font-size:14px}.muted{color:#5b6575;font-size:13px}
table{border-collapse:collapse;font-size:12.5px;margin:8px 0 14px}
th,td{border:1px solid #d8dde6;padding:4px 7px;text-align:right}
th{background:#eef1f6;text-align:center}td.l,th.l{text-align:left}tr:nth-child(even) td{background:#fafbfc}
.grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(360px,1fr));gap:12px}
figure{margin:6px 0}figure img{max-width:100%;border:1px solid #e3e6eb}figcaption{font-size:12.5px;color:#5b6575}
.ok{color:#1a7f37;font-weight:600}.bad{color:#b42318;font-weight:600}
.note{background:#fff8e6;border-left:4px solid #f0b429;padding:8px 12px;font-size:13px}
.scroll{max-height:420px;overflow:auto;border:1px solid #e3e6eb}
.meta{display:flex;flex-wrap:wrap;gap:4px 22px;margin:8px 0 4px;font-size:13px}.meta b{color:#5b6575;font-weight:600}
td{overflow-wrap:break-word}
@page{size:A4;margin:12mm 11mm 14mm}
@media print{
body{background:#fff;font-size:11px}main{max-width:none;padding:0}
h1{font-size:20px}h2{font-size:15px;margin:16px 0 6px;break-after:avoid}h3{break-after:avoid}
p,li{font-size:11px}.muted,figcaption{font-size:10px}
table{font-size:9px;width:100%;table-layout:auto}th,td{padding:2px 3px}
thead{display:table-header-group}tr,figure,img{break-inside:avoid}
.scroll{max-height:none;overflow:visible;border:0}
.grid{grid-template-columns:repeat(2,1fr);gap:6px}
figure img{max-width:100%;max-height:125mm;width:auto;object-fit:contain}
}
"""


def fmt_value(value, std=None, digits=2) -> str:
    """``value ± std`` with the value rounded to the std's precision (2 significant digits)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    if std is None or not math.isfinite(std) or std <= 0:
        return f"{value:.4g}"
    decimals = max(0, digits - 1 - int(math.floor(math.log10(std))))
    if decimals > 10:
        return f"{value:.6g} ± {std:.{digits}g}"
    return f"{value:.{decimals}f} ± {std:.{decimals}f}"


def _img(data: bytes, alt: str, *, mime: str = "image/svg+xml") -> str:
    """A figure embedded in the page (the report's figures are SVG: :mod:`.figures`)."""
    return f'<img alt="{html.escape(alt)}" src="data:{mime};base64,{base64.b64encode(data).decode("ascii")}">'


def _table(frame: pd.DataFrame, left=()) -> str:
    if frame is None or len(frame) == 0:
        return '<p class="muted">None.</p>'
    head = "".join(f'<th class="{"l" if c in left else ""}">{html.escape(str(c))}</th>' for c in frame.columns)
    body = []
    for row in frame.itertuples(index=False):
        cells = []
        for c, v in zip(frame.columns, row):
            text = (
                v
                if isinstance(v, str)
                else (
                    "—"
                    if v is None or (isinstance(v, float) and not math.isfinite(v))
                    else f"{v:.4g}"
                    if isinstance(v, float)
                    else str(v)
                )
            )
            cells.append(f'<td class="{"l" if c in left else ""}">{html.escape(str(text))}</td>')
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _conditions(conditions: dict, analysis, n_failed: int) -> str:
    rows = [(str(k), ", ".join(map(str, v)) if isinstance(v, (list, tuple)) else str(v)) for k, v in conditions.items()]
    rows += [
        ("images in table", str(analysis.n_images)),
        ("failed images", str(n_failed)),
        ("loops (orientation × cycle)", str(len(analysis.loops))),
        ("lost motion at fractions of", f"{analysis.settings['lost_motion_reference_nm']:.4g} N·m "
         f"({analysis.settings['lost_motion_reference']})"),
        ("max torque (secant interval)", f"{analysis.settings['max_torque_nm']:.4g} N·m"),
    ]
    return _table(pd.DataFrame(rows, columns=["condition", "value"]), left=("condition", "value"))


def _stiffness_cell(r) -> str:
    """The phase's straight-line stiffness, or, where that line does not fit, its two
    stiffnesses and the switch torque."""
    if np.isfinite(r.stiffness_nm_per_rad):
        return fmt_value(r.stiffness_nm_per_rad, r.stiffness_std_nm_per_rad)
    if np.isfinite(r.stiffness_below_nm_per_rad) and np.isfinite(r.stiffness_above_nm_per_rad):
        below = fmt_value(r.stiffness_below_nm_per_rad, r.stiffness_below_std_nm_per_rad)
        above = fmt_value(r.stiffness_above_nm_per_rad, r.stiffness_above_std_nm_per_rad)
        switch = abs(r.switch_torque_nm)
        return f"straight line does not fit: {below} below, {above} above the switch at {switch:.3g} N·m"
    return "—"


def _table1(stiff: pd.DataFrame) -> str:
    if stiff.empty:
        return '<p class="muted">No stiffness could be computed.</p>'
    out = pd.DataFrame(
        {
            "orientation": [f"{o:g}°" for o in stiff["orientation_deg"]],
            "phase": stiff["phase"].str.replace("_", " "),
            "torque range (N·m)": [
                f"{a:+.3g} to {b:+.3g}" if np.isfinite(a) else "—"
                for a, b in zip(stiff["torque_from_nm"], stiff["torque_to_nm"])
            ],
            "stiffness k (N·m/rad)": [_stiffness_cell(r) for r in stiff.itertuples(index=False)],
            "k (N·m/arcmin)": [f"{v:.4g}" if np.isfinite(v) else "—" for v in stiff["stiffness_nm_per_arcmin"]],
            "secant (N·m/rad)": [
                fmt_value(v, s) for v, s in zip(stiff["secant_nm_per_rad"], stiff["secant_std_nm_per_rad"])
            ],
            "hysteresis (deg)": [fmt_value(v, s) for v, s in zip(stiff["hysteresis_deg"], stiff["hysteresis_std_deg"])],
            "cycles": stiff["n_cycles"].astype(str),
        }
    )
    return _table(out, left=("orientation", "phase", "stiffness k (N·m/rad)"))


def _metrics(mt: pd.DataFrame, orients) -> str:
    if mt.empty:
        return '<p class="muted">No loop figure could be computed.</p>'
    cols = {"figure": mt["label"], "unit": mt["unit"]}
    flags = mt["flags"] if "flags" in mt else [{}] * len(mt)
    for o in orients:
        cols[f"{o:g}°"] = [fmt_value(m, s) + ("†" if o in fl else "") for (m, s), fl in zip(mt[o], flags)]
    cols["session mean ± std"] = [fmt_value(m, s) for m, s in zip(mt["mean"], mt["mean_std"])]
    cols["sd between loops"] = [f"{v:.3g}" if np.isfinite(v) else "—" for v in mt["sd"]]
    cols["orientation test p"] = ["—" if p is None else f"{p:.3g}" for p in mt["p_value"]]
    # † orientation means shown with a flag: each reason once, with the figures and orientations it holds for
    why = {}
    for label, fl in zip(mt["label"], flags):
        for o, text in fl.items():
            why.setdefault(text, {}).setdefault(label, []).append(f"{o:g}°")
    notes = ""
    for text, by in why.items():
        where = "; ".join(
            label if len(at) == len(orients) else f"{label} ({', '.join(at)})" for label, at in by.items()
        )
        notes += f"<li>{html.escape(where)}: {html.escape(text)}</li>"
    out = _table(pd.DataFrame(cols), left=("figure", "unit"))
    if notes:
        out += '<p class="note">† Orientation means shown with a flag:</p><ul class="note">' + notes + "</ul>"
    return out


_TORQUE_MODELS = {
    "pieces": "every weight piece has its own mass error, drawn once and reused: a pan with n pieces carries "
    "pieces 1..n, so torque errors add up step by step (shared by both phases of a sign), plus the common scale "
    "error of g and r and an independent friction term.",
    "level": "images at the same nominal torque share one error (the same weights).",
    "independent": "every image has its own independent torque error.",
}


def _header(metadata) -> str:
    """Software version, date and the test's metadata (only the entries present)."""
    from datetime import datetime, timezone

    from .. import __version__

    items = [
        ("software", f"vision-torsion {__version__}"),
        ("report date", datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")),
    ]
    for key, value in (metadata or {}).items():
        if value is None or (isinstance(value, str) and not value.strip()):
            continue
        items.append(
            (str(key).replace("_", " "), ", ".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value))
        )
    return (
        '<div class="meta">'
        + "".join(f"<span><b>{html.escape(k)}:</b> {html.escape(v)}</span>" for k, v in items)
        + "</div>"
    )


#: How the report names each kind of issue (:data:`vision_torsion.analysis.session.ISSUE_KINDS`).
_ISSUE_WORDS = {
    "rejected": "does not fit its data",
    "not_applicable": "not applicable to these data",
    "not_computable": "not computable",
    "flagged": "shown, flagged",
}


def _withheld_intro(issues: pd.DataFrame) -> str:
    """What the table below says, in numbers: withheld by kind, and flagged."""
    if not len(issues):
        return ""
    n = issues["withheld because"].value_counts()
    parts = []
    if n.get(_ISSUE_WORDS["rejected"], 0):
        parts.append(f"{n[_ISSUE_WORDS['rejected']]} computed but withheld because they do not fit their data "
                     "(each given another way: a loading phase whose stiffness switches as its stiffness below and "
                     "above the switch and its secant, in the budget and catalogue tables)")
    if n.get(_ISSUE_WORDS["not_applicable"], 0):
        parts.append(f"{n[_ISSUE_WORDS['not_applicable']]} not applicable to these data (one break describes the "
                     "loading branches: two segments K1, K2, so there is no K3 or T2)")
    if n.get(_ISSUE_WORDS["not_computable"], 0):
        parts.append(f"{n[_ISSUE_WORDS['not_computable']]} not computable from these data")
    if n.get(_ISSUE_WORDS["flagged"], 0):
        parts.append(f"{n[_ISSUE_WORDS['flagged']]} shown with a flag")
    return f'<p class="muted">{html.escape("; ".join(parts))}.</p>' if parts else ""


def render_html(
    *, title, conditions, analysis, stiffness, metrics, figures, failed, extra_sections=(), metadata=None
) -> str:
    """Assemble the report page.

    Parameters
    ----------
    metadata : dict, optional
        The test's metadata shown under the title (e.g. gear, serial, operator,
        temperature, notes from session.toml's ``[test]``/``[gear]`` tables); None
        or blank values are left out. The software version and date are always shown.
    figures : dict
        ``{"overlay": svg, "residuals": svg, "stiffness": svg, "orientation": svg}`` (SVG bytes).
    failed : pandas.DataFrame
        ``image, orientation_deg, cycle, phase, step, message`` of failed images.
    extra_sections : sequence of (title, html)
        Extra sections appended as they are (trusted HTML from other modules).
    """
    orients = sorted({lp.orientation_deg for lp in analysis.loop_data})
    issues = pd.DataFrame(
        [
            (
                "session" if i.orientation_deg is None else f"{i.orientation_deg:g}°",
                "" if i.cycle is None else str(i.cycle),
                i.figure,
                _ISSUE_WORDS.get(getattr(i, "kind", ""), "not computable"),
                i.reason,
            )
            for i in analysis.issues
            if i.figure != "*"
        ],
        columns=["orientation", "cycle", "figure", "withheld because", "why"],
    )
    s = analysis.settings
    residuals_html = (
        f"<figure>{_img(figures['residuals'], 'residuals of the bilinear fit')}"
        "<figcaption>Measured minus fitted angle of every image, in the order the loop was photographed; "
        "the grey band is ±2 × the noise the lack-of-fit test expects. The test of each model is in "
        "“Do the models fit?” below.</figcaption></figure>"
    )
    failed_view = failed.rename(columns={"orientation_deg": "orientation"}) if len(failed) else failed
    parts = [
        f"<h1>{html.escape(title)}</h1>",
        _header(metadata),
        (
            '<p class="bad">angle_sign looks inverted; set angle_sign = -1 in session.toml (or 1, if it is -1 now) '
            "and process the images again. Every figure is withheld until then.</p>"
            if (getattr(analysis, "checks", None) or {}).get("angle_sign_inverted")
            else ""
        ),
        '<p class="muted">Torsional stiffness and hysteresis report generated by vision-torsion. '
        "Uncertainties are 1σ standard uncertainties (±) unless marked u95 (expanded: k = 2, or Student's t "
        "where a part rests on few loops or a flagged fit; the budget table gives each k).</p>",
        "<h2>Test conditions</h2>",
        _conditions(conditions, analysis, len(failed)),
        "<h2>Hysteresis loops</h2>",
        f"<figure>{_img(figures['overlay'], 'all loops')}<figcaption>All orientations and cycles overlaid: "
        "measured points, one colour per orientation, and each loop's bilinear fit (thin black line)."
        "</figcaption></figure>",
        "<h3>Does the bilinear fit describe each loop?</h3>",
        residuals_html,
        "<h2>Stiffness per phase and orientation (paper, Table 1)</h2>",
        _table1(stiffness),
        f"<figure>{_img(figures['stiffness'], 'phase stiffness')}</figure>",
        "<h2>Catalogue metrics and model fits per orientation</h2>",
        '<p class="muted">Mean over cycles ± standard uncertainty of that mean. The orientation test is a '
        "one-way ANOVA of the loop values grouped by orientation, against the scatter between cycles of "
        "the same orientation. The figures are tested as one family: p is Holm-adjusted over the figures "
        "tested (fit statistics are not), so the chance that any figure is called significant when no "
        "orientation has an effect stays at 5 %; p &lt; 0.05 means the orientation effect is larger than "
        "that repeatability. "
        "With one cycle per orientation there is no such scatter: the test is not made (—), and the spread "
        "of the orientation means is given instead (sd between loops).</p>",
        _metrics(metrics, orients),
        f"<figure>{_img(figures['orientation'], 'orientation effect')}</figure>",
        "<h2>Uncertainty</h2>",
        "<ul><li>Angles: independent per image (given <code>angle_std_deg</code>); the common reference-image "
        "error cancels in every figure.</li>"
        f"<li>Torques: <code>{html.escape(str(s['torque_correlation']))}</code> model — "
        f"{_TORQUE_MODELS.get(str(s['torque_correlation']), '')} This part is common to all orientations and does "
        "not average down over cycles.</li>"
        "<li>Slopes and model fits: first-order propagation through the least-squares estimate. Hysteresis, "
        f"lost motion, secant stiffness, loop energy, loss factor: Monte Carlo, {s['n_draws']} draws per error "
        f"source, seed {s['seed']}.</li>"
        "<li>Fit uncertainties reflect measurement noise only; compare the residual RMS of a model with the "
        "angle uncertainty to judge whether the model describes the data.</li></ul>",
        "<h2>Failed images</h2>",
        _table(failed_view, left=("image", "phase", "message"))
        if len(failed)
        else '<p class="ok">None: every image was measured.</p>',
        "<h2>Figures withheld or flagged, and why</h2>",
        _withheld_intro(issues),
        (
            f'<div class="scroll">{_table(issues, left=("orientation", "cycle", "figure", "withheld because", "why"))}'
            "</div>"
            if len(issues)
            else '<p class="ok">None: every figure was computed and fits its data.</p>'
        ),
    ]
    for sec_title, sec_html in extra_sections or ():
        parts += [f"<h2>{html.escape(sec_title)}</h2>", sec_html]
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{html.escape(title)}</title><style>{_CSS}</style></head><body><main>"
        + "\n".join(parts)
        + "</main></body></html>\n"
    )
