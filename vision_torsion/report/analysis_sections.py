"""Report sections on whether the figures can be signed: the uncertainty budget of the
headline figures, the lack-of-fit test of every model, the checks on the data, and
the Preisach model as a description of the loop (its loop, its residuals and the
numbers one loop identifies).

Each function returns ``(title, html)`` for :func:`vision_torsion.report.write_report`'s
``extra_sections``; values are rounded to two significant digits of their
uncertainty (:func:`.html.fmt_value`, GUM 7.2.6).
"""

from __future__ import annotations

import html
import math

import numpy as np
import pandas as pd

from ..htmlpage import fmt_value
from ..htmlpage import image_tag as _img
from ..htmlpage import table_html as _table
from .tables import figure_rows

__all__ = ["analysis_sections", "HEADLINE_FIGURES"]

#: Figures given a budget table: (figure, label, unit shown, scale from the analysis unit),
#: from the report's one figure vocabulary (two labels worded for this table).
HEADLINE_FIGURES = figure_rows(
    [
        "hysteresis", "hysteresis_loss", "lost_motion_3pct", "lost_motion_4pct", "k1", "k2", "k3",
        "k_positive_unloading", "k_negative_loading_below", "k_negative_loading_above",
        "k_negative_loading_secant", "secant_stiffness", "loop_energy", "bilinear_k_u", "bilinear_k_l",
    ],
    labels={"hysteresis": "Hysteresis (largest loop width)", "loop_energy": "Loop energy"},
)
_PARTS = [
    ("angle_noise", "angle noise"),
    ("repeatability", "repeatability (Type A)"),
    ("between_orientations", "spread between orientations (one cycle each)"),
    ("weights", "weights"),
    ("g_r", "g and r"),
    ("friction", "friction"),
    ("level", "torque (per level)"),
    ("torque_total", "torque (all)"),
    ("lack_of_fit", "lack of fit"),
]


def _g2(v, scale):
    return "—" if v is None or not math.isfinite(v) else f"{v * scale:.2g}"


def budget_section(analysis):
    rows, flags = [], []
    for fig, label, unit, scale in HEADLINE_FIGURES:
        s = analysis.summary.get(fig)
        if not s or not s.get("n") or s.get("budget") is None or s.get("mean_std") is None:
            continue
        if s.get("flag"):
            flags.append(f"<li>{html.escape(label)}: {html.escape(s['flag'])}</li>")
        b = s["budget"]
        row = {"figure": label, "unit": unit, "mean ± u": fmt_value(s["mean"] * scale, s["mean_std"] * scale)}
        for key, name in _PARTS:
            row[name] = _g2(b.get(key), scale)
        row["k"] = f"{s['coverage_factor']:.2g}"
        row["U95"] = _g2(s["mean_u95"], scale)
        row["flagged / withheld"] = f"{s.get('flagged', 0)} / {s.get('withheld', 0)}"
        if s.get("output_side"):
            o = s["output_side"]
            row["output side (i²·K)"] = fmt_value(o["mean_nm_per_rad"], o["mean_std_nm_per_rad"])
        rows.append(row)
    frame = pd.DataFrame(rows).fillna("")
    text = (
        '<p class="muted">Standard uncertainty of each session mean and its parts (1σ, in the unit shown). '
        "Repeatability is the observed scatter between loops (sd/√n); the propagated angle noise is inside it, "
        "the larger of the two is used. Weights, g and r, friction and lack of fit are common to all loops and "
        "do not average down. U95 = k·u with k from the repeatability's Student t (n − 1 degrees of freedom) "
        "combined with the other parts (JCGM 101), at least 2.</p>"
    )
    if flags:
        text += '<p class="note">Session means shown with a flag:</p><ul class="note">' + "".join(flags) + "</ul>"
    if any(s.get("output_side") for s in analysis.summary.values()):
        from ..analysis.session_analysis import OUTPUT_SIDE_CAVEAT

        text += f'<p class="note">{html.escape(OUTPUT_SIDE_CAVEAT)}</p>'
    return "Uncertainty budget of the headline figures", text + _table(frame, left=("figure", "unit"))


def model_section(analysis):
    rows = []
    for (o, c), f in sorted(analysis.fits.items()):
        for model, chk in f.get("checks", {}).items():
            rows.append(
                {
                    "orientation": f"{o:g}°",
                    "cycle": str(c),
                    "model": model,
                    "residual RMS (deg)": f"{math.degrees(chk.residual_rms_rad):.3g}",
                    "noise RMS (deg)": f"{math.degrees(chk.noise_rms_rad):.3g}",
                    "χ²_red": "—" if not chk.testable else f"{chk.reduced_chi2:.3g}",
                    "dof": str(chk.dof),
                    "p": "—" if not chk.testable else f"{chk.p_value:.2g}",
                    "verdict": ("not testable: " + chk.reason)
                    if not chk.testable
                    else ("REJECTED: flagged, u × √χ²_red" if chk.rejected else "fits"),
                }
            )
    text = (
        '<p class="muted">Each model\'s residuals against the noise the table implies (angle noise and the '
        "torque error through the local compliance); rejected at p &lt; 0.001. A rejected model's parameters "
        "are flagged and their uncertainty multiplied by √χ²_red; a straight-line phase stiffness that does "
        "not fit is withheld and replaced by the stiffnesses below and above the switch.</p>"
    )
    return "Do the models fit? (lack-of-fit test)", text + _table(pd.DataFrame(rows), left=("model", "verdict"))


def checks_section(analysis):
    ch = analysis.checks or {}
    parts = []
    if ch.get("angle_sign_inverted"):
        parts.append(
            '<p class="bad">angle_sign looks inverted; set angle_sign = -1 in session.toml. Every figure '
            "is withheld until then.</p>"
        )
    wrong = ch.get("angle_sign_inverted_orientations") or []
    if wrong:
        parts.append(
            '<p class="bad">The angle falls as the torque rises in orientation(s) '
            + ", ".join(f"{o:g}°" for o in wrong)
            + " only (a mis-set orientation, or the camera flipped): their figures are withheld.</p>"
        )
    clo = pd.DataFrame(
        [
            {
                "orientation": f"{c['orientation_deg']:g}°",
                "comparison": c["check"],
                "images": f"{c['image_first']} → {c['image_last']}",
                "Δθ (deg)": fmt_value(c["difference_deg"], c["std_deg"]),
                "z": f"{c['z']:+.1f}",
                "verdict": "CREEP / DRIFT (figures flagged)" if c["creep"] else "closes within the noise",
            }
            for c in ch.get("closure", [])
        ]
    )
    parts.append(
        "<h3>Loop closure and creep (the same load state twice)</h3>"
        + (
            _table(clo, left=("comparison", "images", "verdict"))
            if len(clo)
            else '<p class="muted">No load state was photographed twice (a plan with a closing image gives one '
            "per orientation).</p>"
        )
    )
    out = pd.DataFrame(
        [
            {
                "orientation": f"{r['orientation_deg']:g}°",
                "cycle": str(r["cycle"]),
                "image": r["image"],
                "off by (σ)": f"{r['z']:+.1f}",
            }
            for r in ch.get("outliers", [])
        ]
    )
    parts.append(
        "<h3>Images more than 4σ off their loop's model</h3>"
        + (_table(out, left=("image",)) if len(out) else '<p class="ok">None.</p>')
    )
    return "Checks on the data", "\n".join(parts)


def preisach_section(analysis):
    """The Preisach model as a description of the first fitted loop: its loop over the data and its
    residuals. Its relay weights are not shown as numbers: a single major loop does not identify them
    (another layout, or the elastic compliance traded for reversible relays, fits as well)."""
    from ..plotting import fixed_figure
    from .figures import svg_bytes

    title = "Preisach model: a description of the loop"
    fits = [(k, f["preisach"]) for k, f in sorted(analysis.fits.items()) if f.get("preisach") is not None]
    loops = {(lp.orientation_deg, lp.cycle): lp for lp in analysis.loop_data}
    fits = [(k, pre) for k, pre in fits if k in loops]
    if not fits:
        return title, '<p class="muted">No loop could be fitted (reasons in the table of figures withheld).</p>'
    (o, c), pre = fits[0]
    lp = loops[(o, c)]
    fig = fixed_figure(9.0, 4.0, left=0.8, bottom=0.6, top=0.4, wspace=0.35)
    ax, axr = fig.subplots(1, 2)
    model = lp.angle_rad - pre.residual_rad
    ax.plot(lp.torque_nm, np.degrees(lp.angle_rad), "o", ms=3, color="0.3", label="measured")
    ax.plot(lp.torque_nm, np.degrees(model), "-", lw=1.0, color="tab:red", label="Preisach model")
    ax.set_xlabel("torque (N·m)")
    ax.set_ylabel("angle (deg)")
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(True, alpha=0.3)
    ax.set_title(f"orientation {o:g}°, cycle {c}", fontsize=10)
    res_arcmin = np.degrees(pre.residual_rad) * 60.0
    axr.plot(np.arange(res_arcmin.size), res_arcmin, "o-", ms=3, lw=0.6, color="tab:red")
    if pre.weights is not None and len(pre.weights) == res_arcmin.size:
        # each point's own σ: its angle noise and its torque error through the local compliance, which
        # is large where the loop switches, so the band widens there and the residuals there are judged fairly
        band = 2.0 * np.degrees(1.0 / np.sqrt(pre.weights)) * 60.0
        axr.fill_between(np.arange(res_arcmin.size), -band, band, color="0.85", step="mid",
                         label="±2σ of each point (angle and torque)")
    else:
        noise = 2.0 * np.degrees(pre.check.noise_rms_rad) * 60.0
        axr.axhspan(-noise, noise, color="0.85", label="±2σ of the noise (RMS)")
    axr.set_xlabel("image (acquisition order)")
    axr.set_ylabel("residual (arcmin)")
    axr.legend(fontsize=8, loc="upper left")
    axr.grid(True, alpha=0.3)
    axr.set_title("residuals", fontsize=10)
    verdict = "fits" if not pre.check.rejected else "REJECTED (" + pre.check.describe() + ")"
    text = (
        "<p>Relays that switch up at α and down at β (each with its mirror), weights ≥ 0 fitted by "
        "non-negative least squares: a description of the loop's shape, not a measurement of parameters. "
        "The relay layout and the elastic compliance are not identified by one loop (other layouts fit as "
        "well, and the elastic compliance often comes out 0), so they are not reported. What one loop does "
        "identify is below, for the loops the model describes (its gate passes): the model's stiffness over "
        "the first level step after a reversal (± u95, k = 2, the fit's active set held fixed) and the "
        "integral of its dissipation distribution, the model's ∮τ dθ, beside the loop energy measured from "
        "the levels (± u95; the model's ∮τ dθ has no ± of its own: its scatter comes from which relays the fit "
        f"leaves active, so it is a check on the measured one). The loop plotted: {html.escape(verdict)}.</p>"
    )
    return title, text + _img(svg_bytes(fig), "Preisach model loop and residuals") + _table(
        _preisach_numbers(analysis, fits, loops), left=("orientation", "cycle", "model"))


def _preisach_numbers(analysis, fits, loops) -> pd.DataFrame:
    """The identifiable numbers of each loop's Preisach fit (:func:`vision_torsion.analysis.preisach.loop_description`),
    a row per fitted loop; none for a loop whose gate rejects the model."""
    from ..analysis.preisach import loop_description

    energy = {(float(r.orientation_deg), int(r.cycle)): (r.value, r.u95)
              for r in analysis.figures[analysis.figures["figure"] == "loop_energy"].itertuples(index=False)}
    rows = []
    for (o, c), pre in fits:
        lp = loops[(o, c)]
        row = {"orientation": f"{o:g}°", "cycle": str(c), "model": "fits" if not pre.check.rejected else "rejected",
               "stiffness after a reversal (N·m/rad)": "—", "model's ∮τ dθ (J)": "—"}
        if not pre.check.rejected:
            d = loop_description(pre, lp.torque_nm, angle_std_rad=lp.angle_std_rad, torque_sources=lp.local_sources())
            key = "reversal_stiffness_nm_per_rad"
            std = math.hypot(d[f"{key}_std_angle"], d[f"{key}_std_torque"])
            row["stiffness after a reversal (N·m/rad)"] = fmt_value(d[key], 2.0 * std)
            row["model's ∮τ dθ (J)"] = f"{d['loop_energy_j']:.4g}"
        row["loop energy measured (J)"] = fmt_value(*energy.get((float(o), int(c)), (math.nan, math.nan)))
        row["residual RMS (arcmin)"] = f"{math.degrees(pre.residual_rms_rad) * 60.0:.2g}"
        rows.append(row)
    return pd.DataFrame(rows)


def analysis_sections(analysis) -> list:
    """The four sections, in report order."""
    return [budget_section(analysis), model_section(analysis), checks_section(analysis), preisach_section(analysis)]
