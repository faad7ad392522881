"""One self-contained HTML page: inline CSS, images as base64 data URIs, no scripts,
no network access.

The page prints on A4 (``@page``/``@media print`` rules): figures and table rows are
never split across pages, long tables repeat their header row, nothing scrolls or
is clipped (wide tables wrap their cells and shrink their font), and the header
carries the software version, the date and the test's metadata.
"""

from __future__ import annotations

import html

import numpy as np
import pandas as pd

from ..htmlpage import fmt_value, page_html
from ..htmlpage import image_tag as _img
from ..htmlpage import table_html as _table

__all__ = ["render_html", "fmt_value"]

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


def _table1(stiff: pd.DataFrame) -> str:
    """The paper's Table 1, one number per cell: a phase whose straight line fits has
    its stiffness; one whose stiffness switches has its stiffnesses below and above
    the switch and the switch torque instead (the straight line withheld, —)."""
    if stiff.empty:
        return '<p class="muted">No stiffness could be computed.</p>'

    def values(v, u):
        return [fmt_value(a, b) if np.isfinite(a) else "—" for a, b in zip(stiff[v], stiff[u])]

    flags = stiff["flag"] if "flag" in stiff else pd.Series([""] * len(stiff))
    out = pd.DataFrame(
        {
            "orientation": [f"{o:g}°" for o in stiff["orientation_deg"]],
            "phase": [p.replace("_", " ") + ("†" if fl else "") for p, fl in zip(stiff["phase"], flags)],
            "torque range (N·m)": [
                f"{a:+.3g} to {b:+.3g}" if np.isfinite(a) else "—"
                for a, b in zip(stiff["torque_from_nm"], stiff["torque_to_nm"])
            ],
            "k, one line (N·m/rad)": values("stiffness_nm_per_rad", "stiffness_std_nm_per_rad"),
            "k below the switch (N·m/rad)": values("stiffness_below_nm_per_rad", "stiffness_below_std_nm_per_rad"),
            "k above the switch (N·m/rad)": values("stiffness_above_nm_per_rad", "stiffness_above_std_nm_per_rad"),
            "switch at |τ| (N·m)": [f"{abs(v):.3g}" if np.isfinite(v) else "—" for v in stiff["switch_torque_nm"]],
            "secant (N·m/rad)": values("secant_nm_per_rad", "secant_std_nm_per_rad"),
            "hysteresis (deg)": values("hysteresis_deg", "hysteresis_std_deg"),
            "cycles": stiff["n_cycles"].astype(str),
        }
    )
    # † rows shown with a flag: each reason once, with the rows it holds for
    why = {}
    for o, phase, fl in zip(stiff["orientation_deg"], stiff["phase"], flags):
        for text in filter(None, str(fl).split("; ")):
            why.setdefault(text, []).append(f"{o:g}° {phase.replace('_', ' ')}")
    notes = "".join(f"<li>{html.escape(', '.join(at))}: {html.escape(text)}</li>" for text, at in why.items())
    return (_table(out, left=("orientation", "phase"))
            + '<p class="muted">A phase whose stiffness switches is not one straight line: its "one line" '
            "stiffness is withheld (—) and its stiffnesses below and above the switch are given. Stiffness in "
            "N·m/rad throughout (N·m/arcmin in stiffness_table.csv).</p>"
            + ('<p class="note">† A value of the row is shown with a flag:</p><ul class="note">' + notes + "</ul>"
               if notes else ""))


def _metrics(mt: pd.DataFrame, orients, *, one_loop: bool = False) -> str:
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
    if one_loop:
        out = ('<p class="note">One loop per orientation: each orientation mean is that loop\'s value, and its '
               "uncertainty holds the measurement only (the repeatability between loops is not observed; measure "
               "more cycles to observe it). † marks a value whose loop figure is itself flagged.</p>" + out)
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


_IDENTITY_LABELS = (("gear", "Gear"), ("serial", "Serial number"), ("operator", "Operator"), ("date", "Test date"),
                    ("notes", "Notes"))


def _identity(identity) -> str:
    """Who, what, when: the first lines of page 1 (a missing entry says how to give it;
    None, the caller knows no session: nothing)."""
    if identity is None:
        return ""
    rows = []
    for key, label in _IDENTITY_LABELS:
        value = identity.get(key)
        if value:
            rows.append(f"<tr><th>{label}</th><td>{html.escape(str(value))}</td></tr>")
        elif key != "notes":
            rows.append(f'<tr><th>{label}</th><td class="muted">not given (plan --{key}, or session.toml '
                        f'[{"gear" if key in ("gear", "serial") else "test"}])</td></tr>')
    return f'<table class="who">{"".join(rows)}</table>'


_DECISION_WORDS = {"pass": ("PASS", "pass"), "fail": ("FAIL", "fail"),
                   "not_decidable": ("not decidable within U", "undecided"), "no_value": ("no value", "undecided")}


def _verdicts(verdicts) -> str:
    """The conformity table of page 1: one row per catalogue limit (``[spec]``)."""
    from ..analysis.conformity import DECISION_RULE, decision_counts, overall
    from .tables import FIGURE_VOCABULARY

    if verdicts is None:
        return ('<p class="muted">No catalogue limits given, so no verdict: add a <code>[spec]</code> table to '
                "session.toml (k1_min_nm_per_rad, k2_min_nm_per_rad, k3_min_nm_per_rad, lost_motion_max_arcmin, "
                "hysteresis_loss_max_arcmin).</p>")
    rows = []
    for v in verdicts:
        label, unit, scale = FIGURE_VOCABULARY.get(v.limit.figure, (v.limit.figure, "", 1.0))
        if unit == "deg":  # catalogue angles are in arcmin
            unit, scale = "arcmin", 60.0
        word, css = _DECISION_WORDS[v.decision]
        measured = "—" if v.value is None else (
            fmt_value(v.value * scale, (v.u95 or 0) * scale)
            + ("" if v.coverage_factor is None else f" (k = {v.coverage_factor:.2g})"))
        why = v.reason + (f"; {v.flagged}" if v.flagged else "")
        rows.append(
            f'<tr><td class="l">{html.escape(label)}</td><td>{"≥" if v.limit.kind == "min" else "≤"} '
            f"{v.limit.value * scale:.4g} {html.escape(unit)}</td><td>{html.escape(measured)} {html.escape(unit)}"
            f'</td><td class="l {css}">{word}</td><td class="l">{html.escape(why)}</td></tr>'
        )
    verdict = overall(verdicts)
    css = {"fail": "fail", "pass": "pass"}.get(verdict, "undecided")
    return (
        f'<p>Overall: <span class="{css}">{verdict.replace("_", " ").upper()}</span> — '
        f"{html.escape(decision_counts(verdicts))}.</p>"
        '<table><thead><tr><th class="l">figure</th><th>catalogue limit</th><th>measured: session mean ± U95</th>'
        '<th class="l">verdict</th><th class="l">why</th></tr></thead><tbody>' + "".join(rows) + "</tbody></table>"
        f'<p class="muted">Decision rule: {html.escape(DECISION_RULE)}</p>'
    )


def _flag_counts(analysis, issues: pd.DataFrame, n_failed: int) -> str:
    """How many things need a look, each linked to its section further down."""
    n_withheld = int((issues["withheld because"] != _ISSUE_WORDS["flagged"]).sum()) if len(issues) else 0
    n_flagged = int((issues["withheld because"] == _ISSUE_WORDS["flagged"]).sum()) if len(issues) else 0
    items = [f'<a href="#failed-images">{n_failed} image(s) not usable</a>',
             f'<a href="#withheld">{n_withheld} figure(s) withheld</a>',
             f'<a href="#withheld">{n_flagged} flagged</a>']
    css = "ok" if not (n_failed or n_withheld or n_flagged) else "muted"
    return f'<p class="{css}">Flags: {", ".join(items)}; details after the results.</p>'


#: How the report names each kind of issue (:data:`vision_torsion.analysis.session_analysis.ISSUE_KINDS`).
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
    *, title, conditions, analysis, stiffness, metrics, figures, failed, extra_sections=(), metadata=None,
    identity=None, verdicts=None,
) -> str:
    """Assemble the report page.

    Parameters
    ----------
    metadata : dict, optional
        The test's metadata shown under the title (e.g. gear, serial, operator,
        temperature, notes from session.toml's ``[test]``/``[gear]`` tables); None
        or blank values are left out. The software version and date are always shown.
    identity : dict, optional
        ``gear``, ``serial``, ``operator``, ``date``, ``notes``: the first lines of the page.
    verdicts : sequence of Verdict, optional
        The conformity table of page 1 (:mod:`vision_torsion.analysis.conformity`).
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
        _identity(identity),
        _header(metadata),
        (
            '<p class="bad">angle_sign looks inverted; set angle_sign = -1 in session.toml (or 1, if it is -1 now) '
            "and process the images again. Every figure is withheld until then.</p>"
            if (getattr(analysis, "checks", None) or {}).get("angle_sign_inverted")
            else ""
        ),
        "<h2>Verdict against the catalogue</h2>",
        _verdicts(verdicts),
        _flag_counts(analysis, issues, len(failed)),
        '<p class="muted">Torsional stiffness and hysteresis report generated by vision-torsion. '
        "Uncertainties are 1σ standard uncertainties (±) unless marked u95 or U95 (expanded: k = 2, or Student's "
        "t where a part rests on few loops or a flagged fit; the budget table gives each k). Angles are those "
        "of the shaft carrying the torque disk and the target (the input side when a gear ratio is given); "
        "each angle is in one unit throughout: hysteresis in degrees, hysteresis loss and lost motion in "
        "arcmin, stiffness in N·m/rad.</p>",
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
        _metrics(metrics, orients, one_loop=bool(len(analysis.per_orientation))
                 and int(analysis.per_orientation["n_cycles"].max()) == 1),
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
        "<li>Loop energy ∮τ dθ is that of the continuous loop: the polygon through the measured levels, less the "
        "area its chords add (bounded from the neighbouring secants); that bound is in u95 (the sampling term). "
        "Lost motion between levels is corrected the same way for the interpolation, and withheld when the "
        "levels around ±x cannot bound it. K1–K3 and T1/T2 with fitted breaks: a parametric bootstrap that "
        "refits the breaks in every draw.</li>"
        "<li>Fit uncertainties reflect measurement noise only; compare the residual RMS of a model with the "
        "angle uncertainty to judge whether the model describes the data.</li></ul>",
        '<h2 id="failed-images">Failed images</h2>',
        _table(failed_view, left=("image", "phase", "message"))
        if len(failed)
        else '<p class="ok">None: every image was measured.</p>',
        '<h2 id="withheld">Figures withheld or flagged, and why</h2>',
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
    return page_html(title, parts)
