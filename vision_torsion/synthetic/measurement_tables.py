"""Synthetic ``measurements.csv`` tables from the bilinear model with known truth.

The torque schedule follows the paper's protocol: per orientation a reference image
at zero torque, then cycles of positive unloading (+Tmax → 0), negative loading
(0 → −Tmax), negative unloading (−Tmax → 0) and positive loading (0 → +Tmax) in
weight steps. Each phase includes both its end points, so the zero and ±Tmax states
are imaged twice per cycle (as when a phase is photographed from start to end).

Noise model: every image gets an independent angle error of ``angle_std_deg``; the
torque error follows one of two models (``torque_model``, see :mod:`.uncertainty`):

- ``"level"``: a torque level made of ``n`` pieces on each of the two pans has the
  torque error ``g·r·Σδm`` (σ = ``g·r·mass_std_kg·sqrt(2n)``), drawn independently
  per signed level and the same every time that level recurs in the session;
- ``"pieces"`` (how a real rig and :func:`vision_torsion.synthetic.session.session_truth`
  work): each of the four pans (+A, +B, −A, −B) has its own pieces, each with a mass
  error drawn once per session; a pan with ``n`` pieces carries pieces ``1..n``, so
  ``τ_true = s·g·r·Σ_{k≤n}(m_A,k + m_B,k)`` — a random walk in the step number,
  shared by the two phases of one sign and by every orientation and cycle. Same
  marginal σ as ``"level"``, but correlated between levels. Only whole pieces are
  used: the amplitude is snapped down to a whole number of steps (as the session
  planner does).

The table holds the *nominal* torque and its σ; the angles come from the *true* torque.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from ..analysis.loops import LOOP_PHASES
from ..analysis.models import bilinear_response
from ..errors import AnalysisError
from ..measurements import couple_torque_nm

__all__ = ["torque_levels", "cycle_schedule", "simulate_measurements"]


def torque_levels(max_torque_nm: float, step_nm: float) -> np.ndarray:
    """Torque levels 0, step, 2·step, …, ending exactly at ``max_torque_nm``.

    A last partial step is added when ``max_torque_nm`` is not a multiple of the step.

    Examples
    --------
    >>> torque_levels(0.05, 0.02).round(3).tolist()
    [0.0, 0.02, 0.04, 0.05]
    """
    if not (max_torque_nm > 0 and step_nm > 0):
        raise AnalysisError(f"max torque and step must be positive, got {max_torque_nm!r}, {step_nm!r}")
    n = int(math.floor(max_torque_nm / step_nm + 1e-9))
    lv = np.arange(n + 1) * step_nm
    if max_torque_nm - lv[-1] > 1e-9 * max_torque_nm:
        lv = np.append(lv, max_torque_nm)
    return lv


def cycle_schedule(levels: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """The four phases of one cycle as ``(phase, torques)`` for given levels ``0..Tmax``."""
    lv = np.asarray(levels, float)
    return [(LOOP_PHASES[0], lv[::-1]), (LOOP_PHASES[1], -lv), (LOOP_PHASES[2], -lv[::-1]), (LOOP_PHASES[3], lv)]


def simulate_measurements(*, k_u, k_l, tau_c, max_torque_nm=0.36, step_mass_kg=0.02, arm_radius_m=0.05,
                          g_m_per_s2=9.81, orientations_deg=(0, 60, 120, 180, 240, 300), n_cycles=1,
                          angle_std_deg=0.001, mass_std_kg=1e-4, rng=None, orientation_k_u=None,
                          torque_model="level", mass_distribution="normal") -> pd.DataFrame:
    """A noisy measurements table of a session of the bilinear model.

    Parameters
    ----------
    k_u, k_l, tau_c : float
        True model parameters (N·m/rad, N·m/rad, N·m).
    max_torque_nm : float
        Cycle amplitude, N·m (``"pieces"``: snapped down to whole steps).
    step_mass_kg, arm_radius_m, g_m_per_s2 : float
        Weight step per pan, arm radius and gravity; the torque step is
        ``2·m·g·r`` (force couple, paper).
    orientations_deg : sequence of float
    n_cycles : int
    angle_std_deg : float
        1σ angle noise per image (0 for exact data).
    mass_std_kg : float
        1σ mass error of each weight piece (0 for exact torques).
    rng : numpy.random.Generator, optional
        Needed when any noise is non-zero.
    orientation_k_u : dict, optional
        ``{orientation: k_u}`` overriding ``k_u`` (an orientation effect for tests).
    torque_model : {"level", "pieces"}
        How torque errors are drawn (module notes).
    mass_distribution : {"normal", "uniform"}
        Distribution of each piece's mass error in the ``"pieces"`` model; uniform
        has half-width ``sqrt(3)·mass_std_kg`` (a ± tolerance, as the synthetic
        sessions draw it).

    Returns
    -------
    pandas.DataFrame
        Columns of ``measurements.csv``; all rows ``status == "ok"``.

    Raises
    ------
    AnalysisError
        Noise without ``rng``, an unknown ``torque_model`` or ``mass_distribution``,
        or a non-positive amplitude or step.

    Examples
    --------
    >>> import numpy as np
    >>> df = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0,), torque_model="pieces",
    ...                            rng=np.random.default_rng(0))
    >>> len(df), round(float(df["torque_nm"].max()), 4)  # 18 whole steps of 0.01962 N·m, 4 phases of 19 + reference
    (77, 0.3532)
    """
    if torque_model not in ("level", "pieces"):
        raise AnalysisError(f"torque_model must be 'level' or 'pieces', got {torque_model!r}")
    if mass_distribution not in ("normal", "uniform"):
        raise AnalysisError(f"mass_distribution must be 'normal' or 'uniform', got {mass_distribution!r}")
    if (angle_std_deg > 0 or mass_std_kg > 0) and rng is None:
        raise AnalysisError("simulate_measurements needs rng=numpy.random.default_rng(seed) when noise is on")
    step = couple_torque_nm(step_mass_kg, gravity_m_per_s2=g_m_per_s2, arm_radius_m=arm_radius_m)
    per_kg = couple_torque_nm(1.0, gravity_m_per_s2=g_m_per_s2, arm_radius_m=arm_radius_m)  # N·m per kg a pan
    if torque_model == "pieces":
        if not (max_torque_nm > 0 and step > 0):
            raise AnalysisError(f"max torque and step must be positive, got {max_torque_nm!r}, {step!r}")
        n_steps = int(math.floor(max_torque_nm / step + 1e-9))
        if n_steps < 1:
            raise AnalysisError(f"max torque {max_torque_nm!r} N·m is less than one weight step ({step:.4g} N·m)")
        levels = np.arange(n_steps + 1) * step
    else:
        levels = torque_levels(max_torque_nm, step)
    pieces = np.ceil(levels / step - 1e-9)  # pieces per pan at each level
    g_r = g_m_per_s2 * arm_radius_m
    tau_std = g_r * mass_std_kg * np.sqrt(2.0 * pieces)
    if torque_model == "level":
        # one torque error per signed level (the same weights each time the level recurs)
        err_pos = rng.standard_normal(levels.size) * tau_std if mass_std_kg > 0 else np.zeros(levels.size)
        err_neg = rng.standard_normal(levels.size) * tau_std if mass_std_kg > 0 else np.zeros(levels.size)
        err_neg[0] = err_pos[0] = 0.0  # no weights at zero torque
    else:
        n_max = levels.size - 1
        if mass_std_kg == 0:
            dm = np.zeros((4, n_max))
        elif mass_distribution == "normal":
            dm = rng.standard_normal((4, n_max)) * mass_std_kg
        else:
            dm = rng.uniform(-1.0, 1.0, size=(4, n_max)) * math.sqrt(3.0) * mass_std_kg
        # pans +A, +B, −A, −B; a pan with n pieces carries pieces 1..n
        cum = np.concatenate([np.zeros((4, 1)), np.cumsum(dm, axis=1)], axis=1)
        err_pos = g_r * (cum[0] + cum[1])
        err_neg = -g_r * (cum[2] + cum[3])
    sched = cycle_schedule(levels)
    rows = []
    for orient in orientations_deg:
        ku = (orientation_k_u or {}).get(orient, k_u)
        phases, steps, nominal, true, std = ["reference"], [0], [0.0], [0.0], [0.0]
        for cycle in range(1, n_cycles + 1):
            for phase, torques in sched:
                idx = np.rint(np.abs(torques) / step).astype(int).clip(max=levels.size - 1)
                idx = np.where(np.isclose(np.abs(torques), levels[-1]), levels.size - 1, idx)
                err = np.where(torques < 0, err_neg[idx], err_pos[idx])
                for s, (t, e, sd) in enumerate(zip(torques, err, tau_std[idx])):
                    phases.append(phase)
                    steps.append(s)
                    nominal.append(float(t))
                    true.append(float(t + e))
                    std.append(float(sd))
        # reference: zero torque reached by loading upward, i.e. on the ascending branch
        theta = bilinear_response(np.asarray(true), k_u=ku, k_l=k_l, tau_c=tau_c)
        noise = rng.standard_normal(theta.size) * angle_std_deg if angle_std_deg > 0 else np.zeros(theta.size)
        angle = np.degrees(theta - theta[0]) + noise - noise[0]
        cycle_of = [0] + [c for c in range(1, n_cycles + 1) for _ in range(4 * levels.size)]
        for i, (ph, st_, tn, sd, an) in enumerate(zip(phases, steps, nominal, std, angle)):
            rows.append({
                "image": f"o{int(orient):03d}_{i:04d}.png", "orientation_deg": float(orient), "cycle": cycle_of[i],
                "phase": ph, "step": st_, "mass_kg": abs(tn) / per_kg,
                "torque_nm": tn, "torque_std_nm": sd, "angle_deg": float(an),
                "angle_std_deg": float(angle_std_deg), "status": "ok", "message": "",
            })
    return pd.DataFrame(rows)
