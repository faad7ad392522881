"""Report sections on whether the figures can be signed: the uncertainty budget of the
headline figures, the lack-of-fit test of every model, the checks on the data, and
the Preisach model's element distribution.

Each function returns ``(title, html)`` for :func:`vision_torsion.report.write_report`'s
``extra_sections``; values are rounded to two significant digits of their
uncertainty (:func:`.html.fmt_value`, GUM 7.2.6).
"""

from __future__ import annotations

import html
import math

import numpy as np
import pandas as pd

from .html import _img, _table, fmt_value
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
        from ..analysis.session import OUTPUT_SIDE_CAVEAT

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
    from ..plotting import fixed_figure
    from .figures import svg_bytes

    fits = [(k, f["preisach"]) for k, f in sorted(analysis.fits.items()) if f.get("preisach") is not None]
    if not fits:
        return (
            "Preisach model: element distribution",
            '<p class="muted">No loop could be fitted (reasons in the table of figures withheld).</p>',
        )
    (o, c), pre = fits[0]
    fig = fixed_figure(6.0, 4.6, left=0.8, bottom=0.6, top=0.4)
    ax = fig.add_subplot()
    w = pre.weight_rad
    m = w > 0
    hyst = m & pre.hysteretic
    rev = m & ~pre.hysteretic
    scale = 400.0 / max(float(w.max()), 1e-300)
    for a_, b_, sel, colour, label in (
        (pre.alpha_nm, pre.beta_nm, hyst, "tab:red", "hysteretic (α > β)"),
        (pre.alpha_nm, pre.beta_nm, rev, "tab:blue", "reversible (α = β)"),
    ):
        if sel.any():
            ax.scatter(b_[sel], a_[sel], s=w[sel] * scale, color=colour, alpha=0.6, label=label)
            ax.scatter(-a_[sel], -b_[sel], s=w[sel] * scale, color=colour, alpha=0.25)
    lim = float(np.max(np.abs(np.concatenate([pre.alpha_nm, pre.beta_nm])))) * 1.05
    ax.plot([-lim, lim], [-lim, lim], color="0.6", lw=0.8)
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_xlabel("switch-down torque β (N·m)")
    ax.set_ylabel("switch-up torque α (N·m)")
    ax.set_title(f"Preisach elements, orientation {o:g}°, cycle {c} (area ∝ weight, rad)", fontsize=10, y=1.0,
                 pad=5.0)
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(True, alpha=0.3)
    verdict = "fits" if not pre.check.rejected else "REJECTED (" + pre.check.describe() + ")"
    text = (
        f"<p>Relays that switch up at α and down at β, with weights ≥ 0 fitted by non-negative least squares "
        f"(no starting values); each with its mirror (−β, −α). The paper's bilinear loop is a uniform square "
        f"0 < α < τ_c, −τ_c < β < 0. This loop: {html.escape(verdict)}; "
        f"{int(np.sum(m))} elements in use.</p>"
    )
    return "Preisach model: element distribution", text + _img(svg_bytes(fig), "Preisach element distribution")


def analysis_sections(analysis) -> list:
    """The four sections, in report order."""
    return [budget_section(analysis), model_section(analysis), checks_section(analysis), preisach_section(analysis)]
