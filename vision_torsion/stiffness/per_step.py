"""Stiffness per load step of camera-rig data: Δτ/Δθ between consecutive images.

A camera session measures a few load steps per phase, each loop (orientation ×
cycle) against its own reference image, so each loop has its own zero offset. The
stiffness of a step does not depend on that offset: for consecutive steps i, i+1
of one phase of one loop,

    k = (τ[i+1] − τ[i]) / (θ[i+1] − θ[i])        [N·m/rad]

at the mid torque (τ[i] + τ[i+1]) / 2. Loops are never pooled: each step's k is
computed within its loop, and only then are the loops compared at equal step
(:func:`summarise_steps`).

Uncertainty (first-order): the angle difference has variance σθ[i]² + σθ[i+1]²
(each image measured independently, ``angle_std_deg``), the torque difference
σ_Δτ² = σ_τ[i]² + σ_τ[i+1]² from ``torque_std_nm``, an upper bound when the two
torques share weight pieces (their common error then cancels in Δτ); so
σ_k = |k|·sqrt((σ_Δτ/Δτ)² + (σ_Δθ/Δθ)²).

A step is flagged (value kept, ``flag`` says why) when

- it starts or ends at zero torque: the output may cross the backlash dead zone
  (or sit in it), so Δθ holds more than the elastic twist;
- |Δθ| < 3·σ_Δθ: the angle did not move measurably, k is not determined;
- k ≤ 0 on a loading or unloading step: the angle moved against the load (a
  forgotten weight, a swapped image, or the angle sign).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..measurements import CYCLE_PHASES, read_measurements
from .combine import mean_over_cycles
from .records import record_from_measurements

__all__ = ["STEP_COLUMNS", "step_stiffness", "summarise_steps"]

#: Columns of :func:`step_stiffness`.
STEP_COLUMNS = (
    "orientation_deg", "cycle", "phase", "step_from", "step_to", "image_from", "image_to",
    "torque_from_nm", "torque_to_nm", "torque_mid_nm", "delta_torque_nm", "delta_angle_deg",
    "delta_angle_std_deg", "stiffness_nm_per_rad", "stiffness_std_nm_per_rad", "flag",
)
_PHASE_ORDER = CYCLE_PHASES
_NEEDED = ("orientation_deg", "cycle", "phase", "step", "torque_nm", "angle_deg", "status")
#: |Δθ| below this many of its standard uncertainties is not a measured twist.
MIN_TWIST_SIGMAS = 3.0


def _column(frame, name, default=0.0):
    if name not in frame.columns:
        return np.full(len(frame), default)
    return pd.to_numeric(frame[name], errors="coerce").fillna(default).to_numpy(dtype=float)


def step_stiffness(measurements, *, name: str = "measurements table") -> pd.DataFrame:
    """Stiffness Δτ/Δθ of every load step of every loop of a camera session.

    Parameters
    ----------
    measurements : pandas.DataFrame or str or Path
        The session's ``measurements.csv`` (columns ``orientation_deg, cycle, phase,
        step, torque_nm, angle_deg, status``; ``image``, ``torque_std_nm`` and
        ``angle_std_deg`` used when present). Only ``status == "ok"`` rows count;
        a step next to a failed image is not bridged (the pair is skipped).
    name : str
        Name for messages.

    Returns
    -------
    pandas.DataFrame
        One row per pair of consecutive steps, columns :data:`STEP_COLUMNS`,
        ordered by orientation, cycle, phase (in the order of the loop) and step.

    Raises
    ------
    RecordError
        The table is invalid (read by
        :func:`vision_torsion.measurements.read_measurements`, whose errors name
        the CSV line and column, and checked as by
        :func:`~.records.record_from_measurements`).

    Examples
    --------
    >>> from vision_torsion.synthetic.encoder import synthetic_measurements
    >>> steps = step_stiffness(synthetic_measurements(steps=4))
    >>> len(steps), sorted(set(steps["phase"]))[0]
    (16, 'negative_loading')
    """
    table = read_measurements(measurements, columns=_NEEDED)
    record_from_measurements(table, name=name)  # no ok row, an ok row without torque or angle
    ok = table[(table["status"] == "ok") & table["phase"].isin(_PHASE_ORDER)].copy()
    ok["_step"] = pd.to_numeric(ok["step"], errors="coerce")
    ok["_torque"] = _column(ok, "torque_nm", np.nan)
    ok["_angle"] = _column(ok, "angle_deg", np.nan)
    ok["_torque_std"] = _column(ok, "torque_std_nm")
    ok["_angle_std"] = _column(ok, "angle_std_deg")
    ok["_image"] = ok["image"] if "image" in ok.columns else ""
    rows = []
    for (orient, cycle, phase), part in ok.groupby(["orientation_deg", "cycle", "phase"], sort=False):
        part = part.sort_values("_step")
        s, t, a = part["_step"].to_numpy(), part["_torque"].to_numpy(), part["_angle"].to_numpy()
        ts, as_, img = part["_torque_std"].to_numpy(), part["_angle_std"].to_numpy(), part["_image"].to_numpy()
        for i in range(len(part) - 1):
            if s[i + 1] - s[i] != 1:
                continue  # a failed image in between: never bridged
            dt, da = t[i + 1] - t[i], a[i + 1] - a[i]
            da_std = float(np.hypot(as_[i], as_[i + 1]))
            dt_std = float(np.hypot(ts[i], ts[i + 1]))
            if da == 0 or dt == 0:
                k, k_std = np.nan, np.nan
            else:
                k = dt / np.deg2rad(da)
                k_std = abs(k) * float(np.hypot(dt_std / dt, da_std / da))
            flags = []
            if t[i] == 0 or t[i + 1] == 0:
                flags.append("from or to zero torque: may include the backlash dead zone")
            if abs(da) < MIN_TWIST_SIGMAS * da_std or da == 0:
                flags.append(f"angle change {da:.2g}° is below {MIN_TWIST_SIGMAS:g}σ ({da_std:.2g}°): "
                             "stiffness not determined")
            elif dt != 0 and k <= 0:
                flags.append("the angle moved against the load (negative stiffness): check the images, "
                             "the weights and angle_sign")
            rows.append({
                "orientation_deg": orient, "cycle": cycle, "phase": phase,
                "step_from": int(s[i]), "step_to": int(s[i + 1]), "image_from": img[i], "image_to": img[i + 1],
                "torque_from_nm": t[i], "torque_to_nm": t[i + 1], "torque_mid_nm": 0.5 * (t[i] + t[i + 1]),
                "delta_torque_nm": dt, "delta_angle_deg": da, "delta_angle_std_deg": da_std,
                "stiffness_nm_per_rad": k, "stiffness_std_nm_per_rad": k_std, "flag": "; ".join(flags),
            })
    frame = pd.DataFrame(rows, columns=list(STEP_COLUMNS))
    if len(frame):
        order = {p: i for i, p in enumerate(_PHASE_ORDER)}
        frame = (frame.assign(_p=frame["phase"].map(order))
                 .sort_values(["orientation_deg", "cycle", "_p", "step_from"], kind="stable")
                 .drop(columns="_p").reset_index(drop=True))
    return frame


def summarise_steps(steps: pd.DataFrame) -> pd.DataFrame:
    """Step stiffness compared over loops at equal phase and step.

    Parameters
    ----------
    steps : pandas.DataFrame
        From :func:`step_stiffness`.

    Returns
    -------
    pandas.DataFrame
        Columns ``phase, step_from, step_to, torque_mid_nm, n_loops,
        stiffness_nm_per_rad, stiffness_std_nm_per_rad, sd_between_loops_nm_per_rad,
        flag``: the mean over the loops whose step is not flagged; its standard
        uncertainty combines the scatter between loops (Type A, sd/sqrt(n)) with the
        propagated part (Type B, sqrt(sum σ²)/n). A step flagged in every loop keeps
        its flag and has no value. (:func:`~.combine.mean_over_cycles`.)

    Examples
    --------
    >>> from vision_torsion.synthetic.encoder import synthetic_measurements
    >>> table = synthetic_measurements(steps=4, cycles=2, angle_noise_deg=1e-4, seed=1)
    >>> summary = summarise_steps(step_stiffness(table))
    >>> int(summary["n_loops"].max())
    2
    """
    out = []
    for (phase, a, b), part in steps.groupby(["phase", "step_from", "step_to"], sort=False):
        good = part[(part["flag"] == "") & np.isfinite(part["stiffness_nm_per_rad"])]
        n = len(good)
        k = good["stiffness_nm_per_rad"].to_numpy()
        mean, u = (mean_over_cycles(k, good["stiffness_std_nm_per_rad"].to_numpy()) if n
                   else (np.nan, np.nan))
        sd = float(np.std(k, ddof=1)) if n > 1 else np.nan
        flags = sorted({f for f in part["flag"] if f})
        out.append({
            "phase": phase, "step_from": a, "step_to": b, "torque_mid_nm": float(part["torque_mid_nm"].median()),
            "n_loops": n, "stiffness_nm_per_rad": float(mean),
            "stiffness_std_nm_per_rad": float(u), "sd_between_loops_nm_per_rad": sd,
            "flag": "" if n else "; ".join(flags),
        })
    return pd.DataFrame(out, columns=["phase", "step_from", "step_to", "torque_mid_nm", "n_loops",
                                      "stiffness_nm_per_rad", "stiffness_std_nm_per_rad",
                                      "sd_between_loops_nm_per_rad", "flag"])
