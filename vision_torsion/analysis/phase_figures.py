"""Figure family: the stiffness of each phase of a loop — a straight line (gated), its two
stiffnesses below and above a switch when the line does not fit, and its secant over the phase.

Every phase range starts at the phase's **starting image** (the last image of the phase
before: the paper's "0 to −0.36" for negative loading). A straight-line slope is
withheld rather than inflated when it does not fit, because it has no meaning when the
stiffness switches inside the phase; the phase is then described by its two stiffnesses
and its secant. The phase secants' torque part is later replaced by the loop's Monte
Carlo (:func:`.loop_figures.loop_figures`), which carries the torque errors as the loop
shows them.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from ..errors import AnalysisError
from . import checks, metrics
from .fitcheck import fit_switch, lack_of_fit, secant
from .loops import LOOP_PHASES, Loop
from .rows import LEVEL_TOL_NM as _TOL
from .rows import FigureRows
from .uncertainty import compact_sources, std_by_kind

__all__ = ["phase_figures"]

_RAD_TO_ARCMIN = 180.0 * 60.0 / math.pi


def _expected_start_end(phase, tmax, tmin):
    return {
        "positive_unloading": (tmax, 0.0),
        "negative_loading": (0.0, tmin),
        "negative_unloading": (tmin, 0.0),
        "positive_loading": (0.0, tmax),
    }[phase]


_PREVIOUS = {
    "negative_loading": "positive_unloading",
    "negative_unloading": "negative_loading",
    "positive_loading": "negative_unloading",
    "positive_unloading": "positive_loading",
}


def _phase_samples(seq: pd.DataFrame, loop: Loop, phase: str, tmax: float, tmin: float):
    """Indices (into ``seq``) of a phase's samples, its starting image first when it was measured."""
    pos = np.flatnonzero(((seq["cycle"] == loop.cycle) & (seq["phase"] == phase)).to_numpy())
    if pos.size == 0:
        return pos
    start, _ = _expected_start_end(phase, tmax, tmin)
    first = seq.iloc[pos[0]]
    if abs(float(first["torque_nm"]) - start) > _TOL and pos[0] > 0:
        prev = seq.iloc[pos[0] - 1]
        if prev["phase"] == _PREVIOUS[phase] and abs(float(prev["torque_nm"]) - start) <= _TOL:
            pos = np.concatenate([[pos[0] - 1], pos])
    return pos


def phase_figures(loop: Loop, seq: pd.DataFrame, *, local_std: np.ndarray, sources: np.ndarray,
                  kinds: np.ndarray, levels: np.ndarray) -> tuple[FigureRows, list]:
    """The stiffness figures of each phase of `loop`, and its rows of the phases table.

    Parameters
    ----------
    loop : Loop
        The loop (its orientation and cycle).
    seq : pandas.DataFrame
        The usable rows of the loop's orientation, in acquisition order (a phase's starting
        image may be the last image of the phase before).
    local_std : numpy.ndarray
        Image-to-image part of each row's torque 1σ (N·m), aligned with the rows of `seq`.
    sources, kinds : numpy.ndarray
        The rows' torque-error loading matrix (N·m per unit source) and each source's kind
        (:func:`.uncertainty.torque_sources`).
    levels : numpy.ndarray
        The session's nominal torque levels (N·m), to tell a missing image.

    Returns
    -------
    rows : FigureRows
        ``k_<phase>`` (withheld when a straight line does not fit), ``k_<phase>_below``,
        ``_above``, ``switch_<phase>`` (when it does not), ``k_<phase>_secant``, and their issues.
    phase_rows : list of dict
        One row of :attr:`.session.SessionAnalysis.phases` per phase.
    """
    col, phase_rows = FigureRows(loop), []
    tau_all = seq["torque_nm"].to_numpy(float)
    tmax, tmin = float(tau_all.max()), float(tau_all.min())
    for phase in LOOP_PHASES:
        pos = _phase_samples(seq, loop, phase, tmax, tmin)
        row = _phase_row(loop, phase, tau_all[pos])
        if pos.size == 0:
            col.fail(f"k_{phase}", "nm_per_rad", f"phase {phase} is missing (no usable image)")
        else:
            _one_phase(col, row, seq.iloc[pos], local_std[pos], sources[pos], kinds, levels, (tmax, tmin))
        _finish_phase_row(row, phase_rows)
    return col, phase_rows


def _phase_row(loop: Loop, phase: str, tau: np.ndarray) -> dict:
    """A phase's row of the phases table, its figures not yet filled in."""
    return {
        "orientation_deg": loop.orientation_deg,
        "cycle": loop.cycle,
        "phase": phase,
        "torque_from_nm": float(tau[0]) if tau.size else np.nan,
        "torque_to_nm": float(tau[-1]) if tau.size else np.nan,
        "n_points": int(tau.size),
        "stiffness_nm_per_rad": np.nan,
        "stiffness_std_nm_per_rad": np.nan,
        "residual_rms_deg": np.nan,
        "reduced_chi2": np.nan,
        "stiffness_below_nm_per_rad": np.nan,
        "stiffness_above_nm_per_rad": np.nan,
        "switch_torque_nm": np.nan,
        "secant_nm_per_rad": np.nan,
        "secant_std_nm_per_rad": np.nan,
        "note": "",
    }


def _one_phase(col, row, rows, st, sources, kinds, levels, tips):
    """The figures of one measured phase (`rows` of the table; `st`, `sources` aligned with them)."""
    phase = row["phase"]
    tau = rows["torque_nm"].to_numpy(float)
    th = np.radians(rows["angle_deg"].to_numpy(float))
    sa = np.radians(rows["angle_std_deg"].to_numpy(float))
    src, knd = compact_sources(sources, kinds)
    src_local = src[:, np.asarray(knd) != "g_r"]
    start, end = _expected_start_end(phase, *tips)
    lo, hi = sorted((start, end))
    expected = levels[(levels >= lo - _TOL) & (levels <= hi + _TOL)]
    missing = checks.missing_levels(tau, expected)
    if _straight_line(col, row, tau, th, sa, st, src, knd, src_local):
        _switch_figures(col, row, phase, tau, th, sa, st, src_local, src)
    _phase_secant(col, row, phase, tau, th, sa, rows["torque_std_nm"].to_numpy(float), start, end, missing)


def _straight_line(col, row, tau, th, sa, st, src, knd, src_local) -> bool:
    """The phase's straight-line stiffness, gated; True when the line is rejected (the phase switches)."""
    phase = row["phase"]
    name = f"k_{phase}"
    try:
        res = metrics.phase_stiffness(tau, th, angle_std_rad=sa, torque_std_nm=st, torque_sources=src)
    except AnalysisError as exc:
        col.fail(name, "nm_per_rad", f"phase {phase}: {exc}")
        return False
    b = res["compliance_rad_per_nm"]
    chk = lack_of_fit(
        res["residual_rad"],
        angle_std_rad=sa,
        torque_std_nm=st,
        compliance_rad_per_nm=b,
        n_params=2,
        torque_sources=src_local,
        jacobian=np.column_stack([np.ones_like(tau), tau]),
        weights=1.0 / np.maximum(sa**2 + (b * st) ** 2, 1e-300),
    )
    row.update(residual_rms_deg=math.degrees(res["residual_rms_rad"]), reduced_chi2=chk.reduced_chi2)
    if chk.rejected:
        col.fail(
            name,
            "nm_per_rad",
            f"phase {phase}: a straight line does not fit, withheld ({chk.describe()}); "
            "the phase is given as its stiffness below and above the switch, and its secant",
            kind="rejected",
        )
        row["note"] = "straight line rejected (lack of fit)"
        return True
    col.add(
        name,
        "nm_per_rad",
        res["value"],
        res["std_angle"],
        res["std_torque"],
        "first-order",
        parts=_slope_parts(tau, th, sa, st, src, knd, res["value"]),
        check=chk,
    )
    row.update(
        stiffness_nm_per_rad=res["value"],
        stiffness_std_nm_per_rad=math.hypot(res["std_angle"], res["std_torque"]),
    )
    return False


def _slope_parts(tau, th, sa, st, src, knd, k):
    """Torque part of a phase slope by kind of source (first order)."""
    b = 1.0 / k
    x = np.column_stack([np.ones_like(tau), tau])
    w = 1.0 / np.maximum(sa**2 + (b * st) ** 2, 1e-300)
    g = np.linalg.solve(x.T @ (x * w[:, None]), (x * w[:, None]).T)
    gt = g @ (b * src)
    parts = std_by_kind(gt, knd)
    return {kk: float(v[1]) * k * k for kk, v in parts.items()}


def _switch_figures(col, row, phase, tau, th, sa, st, src_local, src):
    names = (f"k_{phase}_below", f"k_{phase}_above", f"switch_{phase}")
    try:
        sw = fit_switch(tau, th, angle_std_rad=sa, torque_std_nm=st, torque_sources=src)
    except AnalysisError as exc:
        for n, u in zip(names, ("nm_per_rad", "nm_per_rad", "nm")):
            col.fail(n, u, f"phase {phase}: {exc}")
        return
    chk = lack_of_fit(
        th - sw["model"],
        angle_std_rad=sa,
        torque_std_nm=st,
        compliance_rad_per_nm=sw["compliance"],
        n_params=sw["n_params"],
        torque_sources=src_local,
        jacobian=sw["design"],
        weights=sw["weights"],
    )
    if chk.rejected:
        for n, u in zip(names, ("nm_per_rad", "nm_per_rad", "nm")):
            col.fail(
                n,
                u,
                f"phase {phase}: two stiffnesses with one switch do not fit either, withheld "
                f"({chk.describe()}); see the secant and the model fits",
                kind="rejected",
            )
        return
    for n, key in zip(names[:2], ("k_below", "k_above")):
        col.add(n, "nm_per_rad", sw[key], sw["std_angle"][key], sw["std_torque"][key], "first-order", check=chk)
    col.add(
        names[2],
        "nm",
        sw["switch_nm"],
        sw["std_angle"]["switch_nm"],
        sw["std_torque"]["switch_nm"],
        "first-order (switch torque from the phase start)",
        check=chk,
    )
    row.update(
        stiffness_below_nm_per_rad=sw["k_below"],
        stiffness_above_nm_per_rad=sw["k_above"],
        switch_torque_nm=sw["switch_nm"],
    )


def _phase_secant(col, row, phase, tau, th, sa, st, start, end, missing):
    name = f"k_{phase}_secant"
    if abs(tau[0] - start) > _TOL or abs(tau[-1] - end) > _TOL:
        which = "starting" if abs(tau[0] - start) > _TOL else "last"
        col.fail(
            name,
            "nm_per_rad",
            f"phase {phase}: its {which} image ({start if which == 'starting' else end:+.4g} "
            "N·m) is missing, so the secant over the phase cannot be formed",
        )
        return
    try:
        k, s_a, s_t = secant(tau, th, angle_std_rad=sa, torque_std_nm=st)
    except AnalysisError as exc:
        col.fail(name, "nm_per_rad", f"phase {phase}: {exc}")
        return
    col.add(name, "nm_per_rad", k, s_a, s_t, "first-order (two ends)")
    row.update(secant_nm_per_rad=k, secant_std_nm_per_rad=math.hypot(s_a, s_t))


def _finish_phase_row(row, phase_rows):
    row["stiffness_nm_per_arcmin"] = row["stiffness_nm_per_rad"] / _RAD_TO_ARCMIN
    row["stiffness_std_nm_per_arcmin"] = row["stiffness_std_nm_per_rad"] / _RAD_TO_ARCMIN
    phase_rows.append(row)
