"""Report figures as PNG bytes, drawn with matplotlib's object API.

``matplotlib.figure.Figure`` with an explicit Agg canvas: no pyplot, no global
backend change, safe to import in any program.
"""

from __future__ import annotations

import io
import math

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter, ScalarFormatter

__all__ = ["png_bytes", "loops_overlay", "loop_detail", "phase_stiffness_chart", "orientation_chart"]

_PHASE_LABELS = {
    "positive_unloading": "positive unloading", "negative_loading": "negative loading",
    "negative_unloading": "negative unloading", "positive_loading": "positive loading",
}


def png_bytes(fig: Figure, *, dpi: int = 110) -> bytes:
    """Render a figure to PNG bytes."""
    FigureCanvasAgg(fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return buf.getvalue()


def _colours(n: int):
    import matplotlib as mpl

    cmap = mpl.colormaps["viridis"]
    return [cmap(v) for v in np.linspace(0.0, 0.9, max(n, 1))]


def _orientations(analysis) -> list:
    return sorted({lp.orientation_deg for lp in analysis.loop_data})


def _axes_labels(ax):
    ax.set_xlabel("rotation angle (deg)")
    ax.set_ylabel("torque (N·m)")
    ax.grid(True, alpha=0.3)
    ax.axhline(0.0, color="0.5", lw=0.6)


def loops_overlay(analysis) -> Figure:
    """All loops of the session overlaid, one colour per orientation."""
    fig = Figure(figsize=(7.5, 5.0), layout="constrained")
    ax = fig.add_subplot()
    orients = _orientations(analysis)
    colours = dict(zip(orients, _colours(len(orients))))
    seen = set()
    for lp in analysis.loop_data:
        label = None if lp.orientation_deg in seen else f"{lp.orientation_deg:g}°"
        seen.add(lp.orientation_deg)
        ax.plot(np.degrees(lp.angle_rad), lp.torque_nm, "-o", ms=2.5, lw=1.0, color=colours[lp.orientation_deg],
                label=label, alpha=0.85)
    _axes_labels(ax)
    ax.set_title("Torque–angle loops, all orientations and cycles")
    if orients:
        ax.legend(title="orientation", fontsize=8)
    return fig


def _dense(tau: np.ndarray, per_step: int = 12) -> np.ndarray:
    """The torque path with points inserted between samples (weights change monotonically)."""
    if tau.size < 2:
        return tau.copy()
    t = np.linspace(0.0, 1.0, per_step, endpoint=False)
    inner = (tau[:-1, None] + (tau[1:] - tau[:-1])[:, None] * t[None, :]).reshape(-1)
    return np.append(inner, tau[-1])


def loop_detail(analysis, orientation_deg: float) -> Figure:
    """Loops of one orientation with the bilinear and Bouc–Wen fits over the data."""
    fig = Figure(figsize=(6.0, 4.2), layout="constrained")
    ax = fig.add_subplot()
    loops = [lp for lp in analysis.loop_data if lp.orientation_deg == orientation_deg]
    for k, lp in enumerate(loops):
        ax.errorbar(np.degrees(lp.angle_rad), lp.torque_nm, xerr=np.degrees(lp.angle_std_rad), yerr=lp.torque_std_nm,
                    fmt="o", ms=3, color="0.15", ecolor="0.6", label="data" if k == 0 else None, zorder=3)
        fits = analysis.fits.get((lp.orientation_deg, lp.cycle), {})
        dense = _dense(lp.torque_nm)
        for key, style, label in (("bilinear", "-", "bilinear fit"), ("bouc_wen", "--", "Bouc–Wen fit")):
            fit = fits.get(key)
            if fit is not None:
                ax.plot(np.degrees(fit.predict(dense)), dense, style, lw=1.3,
                        color="tab:red" if key == "bilinear" else "tab:blue", label=label if k == 0 else None)
    _axes_labels(ax)
    ax.set_title(f"Orientation {orientation_deg:g}°")
    ax.legend(fontsize=8)
    return fig


def phase_stiffness_chart(analysis) -> Figure:
    """Stiffness of each phase per orientation (mean over cycles, ±u95), log scale."""
    fig = Figure(figsize=(7.5, 4.2), layout="constrained")
    ax = fig.add_subplot()
    po = analysis.per_orientation
    orients = _orientations(analysis)
    width = 0.8 / 4
    for j, (phase, label) in enumerate(_PHASE_LABELS.items()):
        sub = po[po["figure"] == f"k_{phase}"].set_index("orientation_deg").reindex(orients)
        x = np.arange(len(orients)) + (j - 1.5) * width
        ax.bar(x, sub["mean"], width, yerr=2 * sub["std"], label=label, capsize=2)
    ax.set_xticks(np.arange(len(orients)), [f"{o:g}°" for o in orients])
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(ScalarFormatter())
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set_ylabel("stiffness (N·m/rad)")
    ax.set_xlabel("orientation")
    ax.set_title("Segmental stiffness per phase (error bars: u95, k = 2)")
    ax.grid(True, axis="y", which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def orientation_chart(analysis, figures=("hysteresis", "loop_energy", "bilinear_k_u", "bilinear_k_l")) -> Figure:
    """Chosen figures per orientation (mean ± u95) against the session mean."""
    n = len(figures)
    cols = 2
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(8.0, 2.8 * rows), layout="constrained")
    po = analysis.per_orientation
    for i, name in enumerate(figures):
        ax = fig.add_subplot(rows, cols, i + 1)
        sub = po[po["figure"] == name]
        s = analysis.summary.get(name, {})
        if sub.empty:
            ax.text(0.5, 0.5, f"{name}: not available", ha="center", va="center", transform=ax.transAxes)
            ax.set_axis_off()
            continue
        ax.errorbar(sub["orientation_deg"], sub["mean"], yerr=2 * sub["std"], fmt="o", capsize=3)
        if s.get("mean") is not None:
            ax.axhline(s["mean"], color="tab:red", lw=0.8, ls="--", label="session mean")
        test = s.get("orientation_test", {})
        verdict = ("orientation effect > uncertainty" if test.get("significant")
                   else "no orientation effect beyond uncertainty" if test.get("significant") is False else "not tested")
        ax.set_title(f"{name} ({s.get('unit', '')})\n{verdict}", fontsize=9)
        ax.set_xticks(sub["orientation_deg"])
        ax.set_xlabel("orientation (deg)")
        ax.grid(True, alpha=0.3)
        ax.ticklabel_format(axis="y", useOffset=False)
    return fig
