"""Figures of a stiffness result: torque-angle with fit and dead zone, K(T) with its
band, n(T).

Figures are built with :class:`matplotlib.figure.Figure` directly, never
``pyplot``, so no global backend or figure registry is touched (safe in threads, no
``matplotlib.use`` at import). :func:`save_figure` writes PNGs atomically.
"""

from __future__ import annotations

import io

import numpy as np
from matplotlib.figure import Figure

from ..fileio import atomic_write_bytes

__all__ = ["plot_torque_angle", "plot_stiffness", "plot_meshing", "save_figure"]

_COLOURS = {"positive_loading": "tab:red", "negative_loading": "tab:blue"}


def _axes(title: str, xlabel: str, ylabel: str):
    fig = Figure(figsize=(7.0, 4.5), layout="constrained")
    ax = fig.add_subplot()
    ax.set(title=title, xlabel=xlabel, ylabel=ylabel)
    ax.grid(True, alpha=0.3)
    return fig, ax


def plot_torque_angle(result) -> Figure:
    """Torque against output angle: samples, loading-branch fits, the dead zone shaded.

    Parameters
    ----------
    result : StiffnessResult

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, ax = _axes(f"Torque-angle curve: {result.name}", "output angle (deg)", "torque (N·m)")
    ax.plot(result.record.angle_deg, result.record.torque_nm, ".", ms=1.5, color="0.6",
            label="samples", rasterized=True)
    for c in result.curves:
        ax.plot(c.angle_deg, c.torque_nm, "-", lw=2, color=_COLOURS[c.kind], label=f"{c.kind} fit")
    b = result.backlash
    if b is not None:
        ax.axvspan(b.lower_deg, b.upper_deg, color="tab:orange", alpha=0.2,
                   label=f"dead zone {b.width_deg:.4g}° wide at {b.centre_deg:.4g}°")
    ax.legend(loc="best", fontsize="small")
    return fig


def plot_stiffness(result) -> Figure:
    """Stiffness K = dT/dθ against torque with the ±2σ band (≈95 %).

    Parameters
    ----------
    result : StiffnessResult

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, ax = _axes(f"Stiffness curve: {result.name}", "torque (N·m)", "stiffness (N·m/rad)")
    for c in result.curves:
        colour = _COLOURS[c.kind]
        ax.plot(c.torque_nm, c.stiffness_nm_per_rad, color=colour, label=c.kind)
        ax.fill_between(c.torque_nm, c.stiffness_nm_per_rad - 2 * c.stiffness_std_nm_per_rad,
                        c.stiffness_nm_per_rad + 2 * c.stiffness_std_nm_per_rad,
                        color=colour, alpha=0.25, lw=0, label=f"{c.kind} ±2σ")
    ax.legend(loc="best", fontsize="small")
    return fig


def plot_meshing(result) -> Figure:
    """Effective meshing tooth pairs n = K/Ks against torque (needs Ks).

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
    fig, ax = _axes(f"Effective meshing tooth pairs: {result.name}", "torque (N·m)",
                    f"meshing pairs n = K/Ks (Ks = {m.tooth_stiffness_nm_per_rad:.4g} N·m/rad)")
    frame = result.to_frame()
    for kind, part in frame.groupby("branch", sort=False):
        n, n_std = part["meshing_pairs"].to_numpy(), part["meshing_pairs_std"].to_numpy()
        ax.plot(part["torque_nm"], n, color=_COLOURS[kind], label=kind)
        ax.fill_between(part["torque_nm"], n - 2 * n_std, n + 2 * n_std, color=_COLOURS[kind],
                        alpha=0.25, lw=0)
    text = f"max n = {m.max_pairs:.1f} at {m.torque_at_max_nm:.3g} N·m"
    if m.max_wrap_angle_rad is not None:
        text += f"; wrap angle 2πn/z = {m.max_wrap_angle_rad / np.pi:.4f}π"
    ax.set_title(f"{ax.get_title()}\n{text}", fontsize="medium")
    ax.legend(loc="best", fontsize="small")
    return fig


def save_figure(fig: Figure, path, *, dpi: int = 120):
    """Write `fig` as PNG to `path` atomically; return the path."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    return atomic_write_bytes(path, buffer.getvalue())
