"""Report figures as SVG bytes, drawn with matplotlib's object API.

``matplotlib.figure.Figure`` with an explicit canvas: no pyplot, no global backend
change, safe to import in any program. SVG rather than PNG: the figures print
sharp on A4, and writing them costs about four fifths of the PNG's time
(:func:`vision_torsion.plotting.svg_bytes`; issue 14, ``analyze`` in <= 3 s).

Every figure takes data of any sign and range: a value axis is logarithmic only
when every value on it is positive and they span at least a decade, and then
carries ticks at 1, 2 and 5 × 10ⁿ, so it never shows a single tick label; else it
is linear (a wrong angle sign gives negative stiffnesses, which must be drawn, not
crash the report). Titles say in words what is plotted, with units.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

from ..htmlpage import unit_words
from ..plotting import fixed_figure, svg_bytes

__all__ = ["svg_bytes", "safe_svg", "loops_overlay", "loop_detail", "fit_residuals", "phase_stiffness_chart",
           "orientation_chart", "value_scale"]

logger = logging.getLogger(__name__)

#: A value axis is logarithmic only when its positive values span at least this ratio.
LOG_AXIS_MIN_RATIO = 10.0

_PHASE_LABELS = {
    "positive_unloading": "positive unloading", "negative_loading": "negative loading",
    "negative_unloading": "negative unloading", "positive_loading": "positive loading",
}


def safe_svg(draw, *args) -> bytes:
    """SVG of ``draw(*args)``; if drawing fails, an SVG saying so, so the report is
    still written (the reason is logged as a warning and printed in the figure).

    Examples
    --------
    >>> def broken():
    ...     raise ValueError("no data")
    >>> b"<svg" in safe_svg(broken)
    True
    """
    try:
        return svg_bytes(draw(*args))
    except (ValueError, TypeError, KeyError, IndexError, ZeroDivisionError, OverflowError) as exc:
        name = getattr(draw, "__name__", "figure")
        logger.warning("report figure %s could not be drawn: %s", name, exc)
        fig = Figure(figsize=(6.0, 1.2))
        fig.text(0.5, 0.5, f"This figure ({name.replace('_', ' ')}) could not be drawn:\n{exc}",
                 ha="center", va="center", wrap=True, fontsize=9)
        return svg_bytes(fig)


def value_scale(values) -> str:
    """``"log"`` when every finite value is > 0 and they span >= LOG_AXIS_MIN_RATIO, else ``"linear"``.

    Examples
    --------
    >>> value_scale([0.3, 4.5]), value_scale([1.0, 2.0]), value_scale([-0.5, 4.0]), value_scale([])
    ('log', 'linear', 'linear', 'linear')
    """
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0 or np.any(v <= 0):
        return "linear"
    return "log" if v.max() / v.min() >= LOG_AXIS_MIN_RATIO else "linear"


def _set_value_axis(ax, values) -> None:
    """y axis per :func:`value_scale`; a log axis gets labels at 1, 2, 5 × 10ⁿ."""
    if value_scale(values) == "log":
        ax.set_yscale("log")
        ax.yaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(ScalarFormatter())
        ax.yaxis.set_minor_formatter(NullFormatter())
    else:
        ax.axhline(0.0, color="0.5", lw=0.6)


def _colours(n: int):
    import matplotlib as mpl

    cmap = mpl.colormaps["viridis"]
    return [cmap(v) for v in np.linspace(0.0, 0.9, max(n, 1))]


def _orientations(analysis) -> list:
    return sorted({lp.orientation_deg for lp in analysis.loop_data})


def _axes_labels(ax, *, x=True, y=True):
    if x:
        ax.set_xlabel("rotation angle (deg)")
    if y:
        ax.set_ylabel("torque (N·m)")
    ax.grid(True, alpha=0.3)
    ax.axhline(0.0, color="0.5", lw=0.6)


def _title(ax, text, **kwargs):
    """Axes title at a fixed height: matplotlib otherwise measures the tick labels to place it."""
    ax.set_title(text, y=1.0, pad=5.0, **kwargs)


def loops_overlay(analysis) -> Figure:
    """All loops of the session overlaid, one colour per orientation, with each loop's
    bilinear fit as a thin black line over its points."""
    fig = fixed_figure(7.5, 5.0, left=0.8, bottom=0.6, top=0.45)
    ax = fig.add_subplot()
    orients = _orientations(analysis)
    colours = dict(zip(orients, _colours(len(orients))))
    seen = set()
    fitted = False
    for lp in analysis.loop_data:
        label = None if lp.orientation_deg in seen else f"{lp.orientation_deg:g}°"
        seen.add(lp.orientation_deg)
        ax.plot(np.degrees(lp.angle_rad), lp.torque_nm, "o", ms=3.0, color=colours[lp.orientation_deg],
                label=label, alpha=0.85)
        fit = analysis.fits.get((lp.orientation_deg, lp.cycle), {}).get("bilinear")
        if fit is not None:
            dense = _dense(lp.torque_nm)
            ax.plot(np.degrees(fit.predict(dense)), dense, "-", lw=0.7, color="k", zorder=3)
            fitted = True
    if fitted:  # last in the legend, after the orientations
        ax.plot([], [], "-", lw=0.7, color="k", label="bilinear fit")
    _axes_labels(ax)
    _title(ax, "Torque (N·m) against rotation angle (deg): every loop, one colour per orientation", fontsize=11)
    if orients:
        ax.legend(title="orientation", fontsize=8, loc="upper left")
    return fig


def _dense(tau: np.ndarray, per_step: int = 12) -> np.ndarray:
    """The torque path with points inserted between samples (weights change monotonically)."""
    if tau.size < 2:
        return tau.copy()
    t = np.linspace(0.0, 1.0, per_step, endpoint=False)
    inner = (tau[:-1, None] + (tau[1:] - tau[:-1])[:, None] * t[None, :]).reshape(-1)
    return np.append(inner, tau[-1])


def _draw_loops(ax, analysis, orientation_deg: float, *, legend: bool) -> None:
    """The loops of one orientation (data ±1σ) with the fits that were made, on `ax`."""
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
    if legend and loops:
        ax.legend(fontsize=8, loc="upper left")


def loop_detail(analysis, orientation_deg: float) -> Figure:
    """Loops of one orientation with the bilinear and Bouc–Wen fits over the data."""
    fig = fixed_figure(6.0, 4.2, left=0.75, bottom=0.55, top=0.6)
    ax = fig.add_subplot()
    _draw_loops(ax, analysis, orientation_deg, legend=True)
    _axes_labels(ax)
    _title(ax, f"Torque (N·m) against rotation angle (deg) at orientation {orientation_deg:g}°,\n"
               "measured and fitted", fontsize=10)
    return fig


def fit_residuals(analysis) -> Figure:
    """Residual of each loop's bilinear fit (deg) along the loop, one colour per
    orientation, against the noise the lack-of-fit test expects.

    The band is ±2 × the RMS noise of the test (angle noise and the torque error
    through the local compliance, :mod:`vision_torsion.analysis.fitcheck`), the
    median over loops: a fit that describes its loop stays inside it.
    """
    fig = fixed_figure(7.5, 3.6, left=0.85, bottom=0.6, top=0.45)
    ax = fig.add_subplot()
    orients = _orientations(analysis)
    colours = dict(zip(orients, _colours(len(orients))))
    seen = set()
    noise = []
    for lp in analysis.loop_data:
        f = analysis.fits.get((lp.orientation_deg, lp.cycle), {})
        fit = f.get("bilinear")
        if fit is None:
            continue
        chk = f.get("checks", {}).get("bilinear")
        if chk is not None and np.isfinite(chk.noise_rms_rad):
            noise.append(chk.noise_rms_rad)
        label = None if lp.orientation_deg in seen else f"{lp.orientation_deg:g}°"
        seen.add(lp.orientation_deg)
        r = np.degrees(lp.angle_rad - fit.predict(lp.torque_nm))
        ax.plot(np.arange(r.size), r, "-o", ms=2.5, lw=0.8, color=colours[lp.orientation_deg], label=label)
    if noise:
        band = 2.0 * math.degrees(float(np.median(noise)))
        ax.axhspan(-band, band, color="0.85", zorder=0, label="±2 × noise RMS")
    if not seen:
        ax.text(0.5, 0.5, "no loop has a bilinear fit (reasons in the table of figures withheld)",
                ha="center", va="center", transform=ax.transAxes, fontsize=9)
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("image number along the loop")
    ax.set_ylabel("residual (deg)")
    _title(ax, "Residual of the bilinear fit (deg) along each loop, one colour per orientation", fontsize=10)
    if seen:
        ax.legend(fontsize=7, loc="upper right", ncol=4)
    return fig


def phase_stiffness_chart(analysis) -> Figure:
    """Stiffness of each phase per orientation (mean over cycles, ±u95); the value
    axis is logarithmic only where that shows more than one tick label."""
    fig = fixed_figure(7.5, 4.7, left=0.8, bottom=1.1, top=0.45)
    ax = fig.add_subplot()
    po = analysis.per_orientation
    orients = _orientations(analysis)
    width = 0.8 / 4
    values = []
    colours = iter(("tab:blue", "tab:orange", "tab:green", "tab:red"))
    for j, (phase, label) in enumerate(_PHASE_LABELS.items()):
        sub = po[po["figure"] == f"k_{phase}"].set_index("orientation_deg").reindex(orients)
        sec = po[po["figure"] == f"k_{phase}_secant"].set_index("orientation_deg").reindex(orients)
        x = np.arange(len(orients)) + (j - 1.5) * width
        k = sub["mean"].to_numpy(dtype=float)
        colour = next(colours)
        yerr = np.nan_to_num(sub["u95"].to_numpy(dtype=float), nan=0.0)
        if np.isfinite(k).any():
            ax.bar(x, k, width, yerr=yerr, label=label, capsize=2, color=colour)
        # where the straight line does not fit (withheld), the phase's secant, hatched
        use = ~np.isfinite(k) & np.isfinite(sec["mean"].to_numpy(dtype=float))
        if use.any():
            ks = np.where(use, sec["mean"].to_numpy(dtype=float), np.nan)
            ax.bar(x, ks, width, label=f"{label}: secant (straight line does not fit)", color="white",
                   edgecolor=colour, hatch="///")
            values.extend(ks)
        values.extend(k)
    ax.set_xticks(np.arange(len(orients)), [f"{o:g}°" for o in orients])
    _set_value_axis(ax, values)
    if not np.isfinite(np.asarray(values, dtype=float)).any():
        ax.text(0.5, 0.5, "no phase stiffness to show (reasons in the table of figures withheld)",
                ha="center", va="center", transform=ax.transAxes, fontsize=9)
    ax.set_ylabel("stiffness (N·m/rad)")
    ax.set_xlabel("flexspline orientation (deg)")
    _title(ax, "Segmental stiffness of each phase (N·m/rad) per orientation, mean over cycles ± u95",
           fontsize=10)
    ax.grid(True, axis="y", which="both", alpha=0.3)
    if ax.get_legend_handles_labels()[0]:  # nothing drawn (e.g. an inverted angle sign): no legend
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(0.0, -0.15), ncol=2, frameon=False)
    return fig


#: The analysis's unit codes as a reader writes them.

_FIGURE_WORDS = {
    "hysteresis": "Hysteresis, largest loop width",
    "loop_energy": "Energy lost per loop",
    "bilinear_k_u": "Bilinear stiffness above the switch",
    "bilinear_k_l": "Bilinear stiffness below the switch",
}


def orientation_chart(analysis, figures=("hysteresis", "loop_energy", "bilinear_k_u", "bilinear_k_l")) -> Figure:
    """Chosen figures per orientation (mean ± u95) as a deviation from their session
    mean (%), in one chart, each with the verdict of its orientation test in the legend."""
    fig = fixed_figure(7.5, 4.9, left=0.85, bottom=1.5, top=0.45, right=0.2)
    ax = fig.add_subplot()
    po = analysis.per_orientation
    orients = _orientations(analysis)
    step = min(np.diff(orients)) if len(orients) > 1 else 1.0
    width = 0.5 * step / max(len(figures), 1)
    for j, name in enumerate(figures):
        sub = po[po["figure"] == name]
        s = analysis.summary.get(name, {})
        words = _FIGURE_WORDS.get(name, name.replace("_", " "))
        unit = unit_words(s.get("unit", ""))
        mean = s.get("mean")
        values = sub["mean"].to_numpy(dtype=float)
        if sub.empty or not np.isfinite(values).any() or mean is None or not mean:
            ax.plot([], [], " ", label=f"{words}: not available")
            continue
        test = s.get("orientation_test", {})
        verdict = ("orientation effect found" if test.get("significant")
                   else "no orientation effect found" if test.get("significant") is False
                   else "orientation effect not tested")
        scale = 100.0 / abs(mean)
        yerr = np.nan_to_num(sub["u95"].to_numpy(dtype=float), nan=0.0) * scale
        x = sub["orientation_deg"].to_numpy(dtype=float) + (j - (len(figures) - 1) / 2) * width
        ax.errorbar(x, (values - mean) * scale, yerr=yerr, fmt="o", ms=4, capsize=2,
                    label=f"{words} (session mean {mean:.4g} {unit}): {verdict}")
    ax.axhline(0.0, color="0.4", lw=0.8)
    if orients:
        ax.set_xticks(orients, [f"{o:g}°" for o in orients])
    ax.set_xlabel("flexspline orientation (deg)")
    ax.set_ylabel("deviation from the session mean (%)")
    ax.grid(True, alpha=0.3)
    _title(ax, "Orientation effect: each figure's orientation mean against its session mean (%), ± u95",
           fontsize=10)
    if figures:  # below the axes: four long entries would hide points inside
        ax.legend(fontsize=7.5, loc="upper left", bbox_to_anchor=(0.0, -0.17), frameon=False)
    return fig
