"""Summaries across loops: per orientation, across the session, and a test of whether
the orientation effect is larger than the measurement uncertainty.

Input is the long *figures* table of :func:`.session.analyze_session` (one row per
orientation, cycle and figure with ``value``, ``std_angle``, ``std_torque``).

Notes
-----
- **Across all loops**: mean, sample standard deviation (ddof=1), min, max, range.
  The standard uncertainty of the mean combines the angle part, independent between
  loops (``sqrt(Σσ_a²)/n``), with the torque part, which the torque error models
  (:mod:`.uncertainty`: the same weight pieces, or the same levels, in every loop)
  make common to all loops and so does not average down (mean of ``σ_t``).
- **Per orientation**: the same over that orientation's cycles.
- **Orientation test** (a chi-square test of equal means): with orientation means
  ``x_o`` and their uncertainties ``s_o``,
  ``χ² = Σ (x_o − x̄_w)² / s_o²`` about the weighted mean ``x̄_w``, ``dof = n_o − 1``,
  ``p = P(χ²_dof ≥ χ²)``. ``s_o`` is the *angle* part only (the torque part is the
  same for every orientation and cancels in their differences), or, when an
  orientation has several cycles, the larger of that and the observed cycle-to-cycle
  scatter ``sd/sqrt(n_c)``, so that unmodelled repeatability does not pass for an
  orientation effect. The orientation effect is called larger than the measurement
  uncertainty when ``p < 0.05``.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from .uncertainty import COVERAGE_FACTOR

__all__ = ["ALPHA", "summarise_figures", "orientation_test"]

#: Significance level of the orientation test.
ALPHA = 0.05


def _describe(v: np.ndarray) -> dict:
    n = int(v.size)
    return {
        "n": n,
        "mean": float(np.mean(v)) if n else None,
        "sd": float(np.std(v, ddof=1)) if n >= 2 else None,
        "min": float(np.min(v)) if n else None,
        "max": float(np.max(v)) if n else None,
        "range": float(np.ptp(v)) if n else None,
    }


def orientation_test(means, stds) -> dict:
    """Chi-square test of equal orientation means given their standard uncertainties.

    Parameters
    ----------
    means, stds : array_like
        Orientation means and their 1σ (independent between orientations).

    Returns
    -------
    dict
        ``chi2``, ``dof``, ``p_value``, ``significant`` (p < :data:`ALPHA`), or those
        as None with a ``reason`` when the test cannot be made.

    Examples
    --------
    >>> r = orientation_test([1.0, 1.1, 0.9], [0.1, 0.1, 0.1])
    >>> round(r["chi2"], 6), r["dof"], r["significant"]
    (2.0, 2, False)
    """
    x = np.asarray(means, float)
    s = np.asarray(stds, float)
    none = {"chi2": None, "dof": None, "p_value": None, "significant": None}
    if x.size < 2:
        return {**none, "reason": "fewer than two orientations with a value"}
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        return {**none, "reason": "an orientation mean has no positive finite uncertainty"}
    w = 1.0 / s**2
    xw = float(np.sum(w * x) / np.sum(w))
    chi2 = float(np.sum(w * (x - xw) ** 2))
    dof = int(x.size - 1)
    p = float(stats.chi2.sf(chi2, dof))
    return {"chi2": chi2, "dof": dof, "p_value": p, "significant": bool(p < ALPHA), "reason": None}


def _mean_std(std_angle: np.ndarray, std_torque: np.ndarray) -> tuple[float, float]:
    n = std_angle.size
    return float(np.sqrt(np.sum(std_angle**2)) / n), float(np.mean(std_torque))


def summarise_figures(figures: pd.DataFrame) -> tuple[dict, pd.DataFrame]:
    """Summary per figure across loops and per orientation.

    Parameters
    ----------
    figures : pandas.DataFrame
        Columns ``orientation_deg, cycle, figure, unit, value, std_angle, std_torque``.

    Returns
    -------
    summary : dict
        ``{figure: {unit, n, mean, sd, min, max, range, mean_std, mean_u95,
        orientation_test}}`` over finite values.
    per_orientation : pandas.DataFrame
        ``orientation_deg, figure, unit, n_cycles, mean, sd, std, std_angle,
        std_torque`` (``std``: 1σ of the orientation mean).
    """
    rows = []
    summary = {}
    ok = figures[np.isfinite(figures["value"].to_numpy(float))]
    for fig, sub in figures.groupby("figure", sort=False):
        unit = str(sub["unit"].iloc[0])
        good = ok[ok["figure"] == fig]
        entry = {"unit": unit, **_describe(good["value"].to_numpy(float))}
        if entry["n"]:
            sa, st = _mean_std(good["std_angle"].to_numpy(float), good["std_torque"].to_numpy(float))
            entry["mean_std"] = float(np.hypot(sa, st))
            entry["mean_u95"] = COVERAGE_FACTOR * entry["mean_std"]
        else:
            entry["mean_std"] = entry["mean_u95"] = None
        o_means, o_stds = [], []
        for orient, og in good.groupby("orientation_deg", sort=True):
            v = og["value"].to_numpy(float)
            sa, st = _mean_std(og["std_angle"].to_numpy(float), og["std_torque"].to_numpy(float))
            sd = float(np.std(v, ddof=1)) if v.size >= 2 else np.nan
            rows.append({"orientation_deg": float(orient), "figure": fig, "unit": unit, "n_cycles": int(v.size),
                         "mean": float(np.mean(v)), "sd": sd, "std": float(np.hypot(sa, st)),
                         "std_angle": sa, "std_torque": st})
            o_means.append(float(np.mean(v)))
            o_stds.append(max(sa, sd / np.sqrt(v.size)) if v.size >= 2 else sa)
        entry["orientation_test"] = orientation_test(o_means, o_stds)
        summary[fig] = entry
    cols = ["orientation_deg", "figure", "unit", "n_cycles", "mean", "sd", "std", "std_angle", "std_torque"]
    return summary, pd.DataFrame(rows, columns=cols)
