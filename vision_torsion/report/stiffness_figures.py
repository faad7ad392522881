"""Figures of a stiffness result (:mod:`vision_torsion.stiffness`): torque-angle with
fit and dead zone, K(T) with its band, n(T), and the camera rig's step stiffness.

The stiffness layer computes; this module of the report layer draws (the session
report's stiffness section, :func:`section_figures`, and ``vision-torsion stiffness``).

Figures are built with :class:`matplotlib.figure.Figure` directly, never
``pyplot``, so no global backend or figure registry is touched (safe in threads, no
``matplotlib.use`` at import). :func:`~vision_torsion.plotting.save_figure` writes
PNGs atomically (at the figures' 120 dpi).
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

__all__ = ["plot_torque_angle", "plot_stiffness", "plot_meshing", "plot_step_stiffness", "section_figures"]

#: Resolution of the saved figures (dots per inch).
_DPI = 120
_COLOURS = {"positive_loading": "tab:red", "negative_loading": "tab:blue",
            "positive_unloading": "tab:orange", "negative_unloading": "tab:cyan"}


def _words(kind: str) -> str:
    return kind.replace("_", " ")


def _axes(title: str, xlabel: str, ylabel: str):
    fig = Figure(figsize=(7.0, 4.5), layout="constrained", dpi=_DPI)
    ax = fig.add_subplot()
    ax.set(title=title, xlabel=xlabel, ylabel=ylabel)
    ax.grid(True, alpha=0.3)
    return fig, ax


def plot_torque_angle(result) -> Figure:
    """Torque against output angle: samples, loading-branch fits, the dead zone shaded.

    Parameters
    ----------
    result : StiffnessResult
        A record's analysis (:func:`~vision_torsion.stiffness.analyze_stiffness_curve`).

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, ax = _axes(f"Torque against output angle, with each cycle's loading fit ({result.name})",
                    "output angle (deg)", "torque (N·m)")
    ax.plot(result.record.angle_deg, result.record.torque_nm, ".", ms=1.5, color="0.6",
            label="samples", rasterized=True)
    labelled = set()
    for c in result.cycle_curves:
        virgin = result.is_virgin(c)
        key = (c.kind, virgin)
        label = None if key in labelled else (f"{_words(c.kind)} fit, virgin loading" if virgin
                                              else f"{_words(c.kind)} fits, one per cycle")
        labelled.add(key)
        ax.plot(c.angle_deg, c.torque_nm, ":" if virgin else "-", lw=1.5,
                color="0.2" if virgin else _COLOURS[c.kind], label=label)
    b = result.backlash
    if b is not None:
        ax.axvspan(b.lower_deg, b.upper_deg, color="tab:orange", alpha=0.2,
                   label=f"dead zone {b.width_deg:.4g}° wide at {b.centre_deg:.4g}°")
    ax.legend(loc="best", fontsize="small")
    return fig


def plot_stiffness(result) -> Figure:
    """Stiffness K = dT/dθ against torque: each cycle's curve, the virgin loading
    dotted, and the mean over cycles with its ±2σ band (≈95 %).

    Parameters
    ----------
    result : StiffnessResult
        With at least one fitted branch (``result.curves``).

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, ax = _axes(f"Stiffness K = dT/dθ against torque, per cycle and mean ({result.name})",
                    "torque (N·m)", "stiffness K (N·m/rad)")
    for c in result.cycle_curves:
        virgin = result.is_virgin(c)
        ax.plot(c.torque_nm, c.stiffness_nm_per_rad, ":" if virgin else "-", lw=0.8,
                color="0.2" if virgin else _COLOURS[c.kind], alpha=0.9 if virgin else 0.45,
                label=f"{_words(c.kind)}, virgin loading (not in the mean)" if virgin else None)
    for c in result.curves:
        colour = _COLOURS[c.kind]
        ax.plot(c.torque_nm, c.stiffness_nm_per_rad, color=colour, lw=2,
                label=f"{_words(c.kind)}: mean of {c.n_cycles} cycle(s)")
        ax.fill_between(c.torque_nm, c.stiffness_nm_per_rad - 2 * c.stiffness_std_nm_per_rad,
                        c.stiffness_nm_per_rad + 2 * c.stiffness_std_nm_per_rad,
                        color=colour, alpha=0.25, lw=0, label=f"{_words(c.kind)} ±2σ")
    ax.legend(loc="best", fontsize="small")
    return fig


def plot_meshing(result) -> Figure:
    """Effective meshing tooth pairs per meshing zone, n = K/Ks, against torque (needs Ks).

    Parameters
    ----------
    result : StiffnessResult
        With ``result.meshing`` set.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        The result has no meshing figures (no Ks in the rig).
    """
    if result.meshing is None:
        raise ValueError("the result has no meshing pairs (no Ks given)")
    m = result.meshing
    fig, ax = _axes(f"Effective meshing tooth pairs per meshing zone against torque ({result.name})",
                    "torque (N·m)",
                    f"pairs per zone n = K/Ks (Ks = {m.tooth_stiffness_nm_per_rad:.4g} N·m/rad)")
    frame = result.to_frame()
    frame = frame[frame["curve"] == "summary"]
    for kind, part in frame.groupby("branch", sort=False):
        n, n_std = part["meshing_pairs_per_zone"].to_numpy(), part["meshing_pairs_per_zone_std"].to_numpy()
        ax.plot(part["torque_nm"], n, color=_COLOURS[kind], label=_words(kind))
        ax.fill_between(part["torque_nm"], n - 2 * n_std, n + 2 * n_std, color=_COLOURS[kind],
                        alpha=0.25, lw=0)
    text = (f"max n = {m.max_pairs_per_zone:.1f} per zone ({2 * m.max_pairs_per_zone:.1f} in both zones) "
            f"at {m.torque_at_max_nm:.3g} N·m")
    if m.max_wrap_angle_per_zone_rad is not None:
        text += f"; wrap angle of one zone 2πn/z = {m.max_wrap_angle_per_zone_rad / np.pi:.4f}π rad"
    ax.set_title(f"{ax.get_title()}\n{text}", fontsize="medium")
    ax.legend(loc="best", fontsize="small")
    return fig


def plot_step_stiffness(steps, summary) -> Figure:
    """Camera-rig stiffness per load step, Δτ/Δθ, against the step's mid torque.

    Parameters
    ----------
    steps : pandas.DataFrame
        :func:`~vision_torsion.stiffness.per_step.step_stiffness` (every loop: small grey-edged points; flagged
        steps as crosses).
    summary : pandas.DataFrame
        :func:`~vision_torsion.stiffness.per_step.summarise_steps` (mean over loops with ±2σ error bars).

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, ax = _axes("Stiffness of each load step Δτ/Δθ against torque (all loops; mean ± 2σ)",
                    "mid-step torque (N·m)", "step stiffness Δτ/Δθ (N·m/rad)")
    for phase, part in steps.groupby("phase", sort=False):
        colour = _COLOURS.get(phase, "0.3")
        good = part["flag"] == ""
        ax.plot(part.loc[good, "torque_mid_nm"], part.loc[good, "stiffness_nm_per_rad"], ".", ms=3,
                color=colour, alpha=0.35)
        if (~good).any():
            ax.plot(part.loc[~good, "torque_mid_nm"], part.loc[~good, "stiffness_nm_per_rad"], "x", ms=4,
                    color=colour, alpha=0.6)
    for phase, part in summary.groupby("phase", sort=False):
        ok = part["n_loops"] > 0
        ax.errorbar(part.loc[ok, "torque_mid_nm"], part.loc[ok, "stiffness_nm_per_rad"],
                    yerr=2 * part.loc[ok, "stiffness_std_nm_per_rad"], fmt="-o", ms=3, lw=1, capsize=2,
                    color=_COLOURS.get(phase, "0.3"), label=_words(phase))
    ax.axvline(0.0, color="0.5", lw=0.6)
    ax.legend(loc="best", fontsize="small", title="crosses: flagged steps")
    return fig


def section_figures(section) -> dict:
    """The figures of a session report's stiffness section, by name.

    Parameters
    ----------
    section : vision_torsion.stiffness.section.StiffnessSection

    Returns
    -------
    dict of str to matplotlib.figure.Figure
        ``step_stiffness``; with a smooth fit also ``torque_angle``, ``stiffness``
        (when a branch was fitted) and ``meshing_pairs`` (with Ks).

    Examples
    --------
    >>> from vision_torsion.stiffness import stiffness_section
    >>> from vision_torsion.synthetic.encoder import synthetic_measurements
    >>> sorted(section_figures(stiffness_section(synthetic_measurements(steps=10))))
    ['step_stiffness']
    """
    figures = {"step_stiffness": plot_step_stiffness(section.steps, section.summary)}
    result = section.result
    if result is not None:
        figures["torque_angle"] = plot_torque_angle(result)
        if result.curves:
            figures["stiffness"] = plot_stiffness(result)
        if result.meshing is not None:
            figures["meshing_pairs"] = plot_meshing(result)
    return figures
