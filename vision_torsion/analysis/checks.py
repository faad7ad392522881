"""Checks on the data itself, before and beside the figures: the angle sign, gaps in
the torque levels, loop closure and creep, and points far off their loop's model.

Each check returns plain values (and :class:`.session.Issue` rows are made from
them by :mod:`.session_analysis`); none of them changes the data.

- **Angle sign** (:func:`angle_sign_inverted`, :func:`angle_sign_by_run`): the
  angle must rise with the torque. The least-squares slope of angle on torque is
  negative, beyond its own scatter, only when ``angle_sign`` is set the wrong way
  round. It is judged per orientation and per run (descending: positive unloading
  and negative loading; ascending: the other two), so that one orientation whose
  sign is inverted (a mis-set orientation, a camera flipped between orientations)
  is named, not averaged away by the others.
- **Loop direction** (:func:`loop_direction`): a passive gear dissipates, so its
  loop runs anticlockwise in (τ, θ): the descending run lies above the ascending
  one and the loop's area (energy) is positive. An area negative beyond its
  uncertainty is a loop running the other way round (phases or torque signs
  labelled the wrong way); an area within its uncertainty of zero resolves no
  dissipation.
- **Gaps** (:func:`gap_between`): a run of a loop is expected to hold every torque
  level the session uses between its ends. A figure evaluated between two measured
  neighbours with an expected level missing between them (a failed image) would be
  interpolated across the kink a missing level can hide, so it is withheld.
- **Closure and creep** (:func:`closure_checks`): the same load state photographed
  twice must give the same angle within the noise. Two pairs are compared per
  orientation: +Tmax at the start of the first cycle and +Tmax at the end of the
  last (the same weights: the torque error cancels), and the ``closing`` zero-torque
  image against the end of cycle 1's positive unloading (both reached by unloading
  from +Tmax, no weights on the pans). ``|Δθ| > CLOSURE_K·σ_Δ`` is creep (or a
  disturbed rig), with ``σ_Δ`` from the two images' angle uncertainties.
- **Flat top** (:func:`flat_top`): the paper's hysteresis is the *largest* loop width.
  When several torque levels share that width within the noise (a flat-topped loop,
  e.g. a play that stays open over most of the cycle), the largest of several noisy
  widths is biased upward by the noise (by about σ_w·E[max of m normals]) and its
  Monte Carlo spread does not show it; the figure is then flagged with the expected
  bias, and the width at zero (``hysteresis_loss``) is the unbiased one.
- **Outliers** (:func:`backward_outliers`): a point is judged by a fit that cannot
  absorb it: its score is that of a lone spike at the point
  (:func:`.fitcheck.spike_scores`: the generalised-least-squares estimate of an extra
  offset at that point alone over its standard error, with the fit's projection and
  the correlated noise), so a flexible model cannot bend to it and noise shared by
  many points neither hides it nor makes its neighbours look like one. The worst
  point beyond :data:`OUTLIER_K` is listed, the fit is made again without it and the
  next worst is judged on that fit (a backward, one-at-a-time search). Only the
  offending image is listed; a point the fit follows exactly (its own model term)
  cannot be judged.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from ..errors import AnalysisError

__all__ = [
    "CLOSURE_K",
    "OUTLIER_K",
    "FLAT_TOP_K",
    "FLAT_TOP_LEVELS",
    "angle_sign_inverted",
    "gap_between",
    "closure_checks",
    "flat_top",
    "SIGN_T",
    "angle_sign_by_run",
    "loop_direction",
    "backward_outliers",
]

#: Closure differences beyond this many σ are reported as creep.
CLOSURE_K = 4.0
#: Standardised residuals beyond this are listed as outliers.
OUTLIER_K = 4.0
#: A level's loop width within this many σ of the largest one shares the maximum (:func:`flat_top`).
FLAT_TOP_K = 2.0
#: This many levels sharing the largest width make it a maximum of noise (:func:`flat_top`).
FLAT_TOP_LEVELS = 3


def angle_sign_inverted(torque_nm, angle_deg) -> bool:
    """True when the angle clearly falls as the torque rises (``angle_sign`` set the wrong way).

    The least-squares slope of angle on torque over all given samples is compared with
    the scatter about that line: inverted when its t-value is below ``−SIGN_T``.

    Examples
    --------
    >>> angle_sign_inverted([0.0, 0.1, 0.2, 0.3], [0.0, -1.0, -2.1, -2.9])
    True
    """
    return bool(_slope_t(torque_nm, angle_deg) < -SIGN_T)


#: |t| of the angle-on-torque slope beyond which a run's sign is decided (:func:`angle_sign_by_run`).
SIGN_T = 5.0
#: Phases of the descending run (torque falling) and of the ascending run.
RUNS = {"descending": ("positive_unloading", "negative_loading"),
        "ascending": ("negative_unloading", "positive_loading")}


def _slope_t(tau, th) -> float:
    """t-value of the least-squares slope of ``th`` on ``tau`` (±inf for an exact line; NaN if undefined)."""
    tau = np.asarray(tau, float)
    th = np.asarray(th, float)
    ok = np.isfinite(tau) & np.isfinite(th)
    tau, th = tau[ok], th[ok]
    if tau.size < 3 or np.ptp(tau) <= 0:
        return math.nan
    x = tau - tau.mean()
    b = float(np.sum(x * (th - th.mean())) / np.sum(x * x))
    r = th - th.mean() - b * x
    s = math.sqrt(max(float(np.sum(r * r)) / (tau.size - 2), 0.0))
    se = s / math.sqrt(float(np.sum(x * x)))
    if se == 0:
        return math.copysign(math.inf, b) if b != 0 else math.nan
    return b / se


def angle_sign_by_run(usable: pd.DataFrame) -> list:
    """The angle's sign against the torque per orientation and run (see the module notes).

    Parameters
    ----------
    usable : pandas.DataFrame
        Usable loop rows (``orientation_deg, phase, torque_nm, angle_deg``).

    Returns
    -------
    list of dict
        One per orientation: ``orientation_deg``, ``t`` (``{run: t-value of the
        slope}``), ``falls`` (the runs whose angle falls as the torque rises,
        ``t < −SIGN_T``) and ``rises`` (``t > SIGN_T``).

    Examples
    --------
    >>> import pandas as pd
    >>> t = [0.3, 0.1, -0.1, -0.3]
    >>> d = pd.DataFrame({"orientation_deg": 0.0, "phase": ["positive_unloading"] * 4 + ["positive_loading"] * 4,
    ...                   "torque_nm": t + t[::-1], "angle_deg": [-3.0, -1.1, 0.9, 3.0, 3.1, 1.0, -1.0, -2.9]})
    >>> r = angle_sign_by_run(d)[0]
    >>> r["falls"], r["rises"]
    (['descending', 'ascending'], [])
    """
    out = []
    for orient, sub in usable.groupby("orientation_deg", sort=True):
        t = {}
        for run, phases in RUNS.items():
            part = sub[sub["phase"].isin(phases)]
            t[run] = _slope_t(part["torque_nm"], part["angle_deg"])
        out.append({
            "orientation_deg": float(orient),
            "t": t,
            "falls": [r for r, v in t.items() if v < -SIGN_T],
            "rises": [r for r, v in t.items() if v > SIGN_T],
        })
    return out


def loop_direction(energy_j: float, u95_j: float) -> str:
    """``"anticlockwise"`` (dissipating), ``"clockwise"`` (area negative beyond u95) or
    ``"unresolved"`` (area within its u95 of zero, or not finite).

    Examples
    --------
    >>> loop_direction(0.07, 0.001), loop_direction(-0.07, 0.001), loop_direction(-1e-5, 1e-4)
    ('anticlockwise', 'clockwise', 'unresolved')
    """
    if not (np.isfinite(energy_j) and np.isfinite(u95_j)):
        return "unresolved"
    if energy_j > u95_j:
        return "anticlockwise"
    if energy_j < -u95_j:
        return "clockwise"
    return "unresolved"


def gap_between(run_levels, expected_levels, at_nm, *, resolution_nm=1e-9):
    """The expected torque levels missing between the measured neighbours of ``at_nm``.

    Parameters
    ----------
    run_levels : array_like
        Torque levels measured in a run (N·m).
    expected_levels : array_like
        Every level the session uses (N·m).
    at_nm : float
        Where a figure is evaluated (N·m).

    Returns
    -------
    list of float
        Missing levels strictly between the neighbours (empty: bracketed without a
        gap); None when ``at_nm`` is outside the run.

    Examples
    --------
    >>> gap_between([0.0, 0.2, 0.3], [0.0, 0.1, 0.2, 0.3], 0.05)
    [0.1]
    >>> gap_between([0.0, 0.1], [0.0, 0.1], 0.05)
    []
    """
    lv = np.unique(np.asarray(run_levels, float))
    ex = np.unique(np.asarray(expected_levels, float))
    if lv.size == 0 or at_nm < lv[0] - resolution_nm or at_nm > lv[-1] + resolution_nm:
        return None
    lo = lv[lv <= at_nm + resolution_nm].max()
    hi = lv[lv >= at_nm - resolution_nm].min()
    miss = ex[(ex > lo + resolution_nm) & (ex < hi - resolution_nm)]
    return [float(v) for v in miss]


def missing_levels(run_levels, expected_levels, *, resolution_nm=1e-9):
    """Expected levels inside a run's torque range that the run lacks (N·m)."""
    lv = np.unique(np.asarray(run_levels, float))
    ex = np.unique(np.asarray(expected_levels, float))
    if lv.size == 0:
        return []
    inside = ex[(ex > lv[0] + resolution_nm) & (ex < lv[-1] - resolution_nm)]
    have = np.min(np.abs(inside[:, None] - lv[None, :]), axis=1) <= resolution_nm if inside.size else np.zeros(0, bool)
    return [float(v) for v in inside[~have]]


def _pair(a, b, label):
    d = float(b["angle_deg"] - a["angle_deg"])
    s = math.hypot(float(a["angle_std_deg"]), float(b["angle_std_deg"]))
    return {
        "check": label,
        "image_first": str(a["image"]),
        "image_last": str(b["image"]),
        "difference_deg": d,
        "std_deg": s,
        "z": d / s if s > 0 else (math.inf if d else 0.0),
        "creep": bool(abs(d) > CLOSURE_K * s) if s > 0 else bool(d != 0),
    }


def closure_checks(usable: pd.DataFrame, closing: pd.DataFrame) -> list:
    """Loop-closure and creep checks per orientation (see the module notes).

    Parameters
    ----------
    usable : pandas.DataFrame
        Usable loop rows in acquisition order (``image, orientation_deg, cycle, phase,
        step, torque_nm, angle_deg, angle_std_deg``).
    closing : pandas.DataFrame
        Usable rows of phase ``closing`` (same columns).

    Returns
    -------
    list of dict
        ``orientation_deg, check, image_first, image_last, difference_deg, std_deg,
        z, creep`` per comparison that could be made.
    """
    out = []
    for orient, sub in usable.groupby("orientation_deg", sort=True):
        tmax = sub["torque_nm"].max()
        top = sub[np.isclose(sub["torque_nm"], tmax, rtol=0, atol=1e-9 * max(abs(tmax), 1.0))]
        if len(top) >= 2:
            out.append(
                {
                    "orientation_deg": float(orient),
                    **_pair(top.iloc[0], top.iloc[-1], "+Tmax at the start and at the end of the run"),
                }
            )
        c = closing[closing["orientation_deg"] == orient]
        first = sub[(sub["phase"] == "positive_unloading") & (sub["cycle"] == sub["cycle"].min())]
        if len(c) and len(first):
            end = first.iloc[-1]
            if abs(float(end["torque_nm"])) <= 1e-9:
                out.append(
                    {
                        "orientation_deg": float(orient),
                        **_pair(end, c.iloc[-1], "zero torque after unloading: cycle 1 and the closing image"),
                    }
                )
    return out


def flat_top(tau_desc, th_desc, std_desc, tau_asc, th_asc, std_asc, *, resolution_nm=1e-9):
    """Whether the largest loop width is a maximum of noise over a flat top.

    Parameters
    ----------
    tau_desc, th_desc, std_desc, tau_asc, th_asc, std_asc : array_like
        The descending and ascending runs: torques (N·m), angles and their 1σ (rad).

    Returns
    -------
    dict or None
        None when fewer than :data:`FLAT_TOP_LEVELS` levels (measured in both runs)
        have a width within :data:`FLAT_TOP_K`·σ_w of the largest; else ``levels``
        (their count), ``sigma_rad`` (median σ_w of them) and ``bias_rad``: the
        expected excess of the largest of ``levels`` noisy widths over the true
        one, ``σ_w·Φ⁻¹((m − 0.375)/(m + 0.25))`` (Blom's approximation of the
        expected maximum of m standard normal values).

    Examples
    --------
    >>> t = [1.0, 0.5, 0.0, -0.5, -1.0]
    >>> r = flat_top(t, [0.1] * 5, [1e-3] * 5, t[::-1], [0.0] * 5, [1e-3] * 5)
    >>> r["levels"], round(r["bias_rad"] / r["sigma_rad"], 2)
    (5, 1.18)
    >>> flat_top(t, [0.1, 0.2, 0.3, 0.2, 0.1], [1e-3] * 5, t[::-1], [0.0] * 5, [1e-3] * 5) is None
    True
    """
    from scipy import special  # ndtri is scipy.stats.norm.ppf

    key = lambda t: np.round(np.asarray(t, float) / resolution_nm).astype(np.int64)  # noqa: E731
    kd, ka = key(tau_desc), key(tau_asc)
    common, i_d, i_a = np.intersect1d(kd, ka, return_indices=True)
    if common.size < FLAT_TOP_LEVELS:
        return None
    w = np.abs(np.asarray(th_desc, float)[i_d] - np.asarray(th_asc, float)[i_a])
    s = np.hypot(np.asarray(std_desc, float)[i_d], np.asarray(std_asc, float)[i_a])
    near = w >= w.max() - FLAT_TOP_K * s
    m = int(near.sum())
    if m < FLAT_TOP_LEVELS:
        return None
    sigma = float(np.median(s[near]))
    return {"levels": m, "sigma_rad": sigma, "bias_rad": sigma * float(special.ndtri((m - 0.375) / (m + 0.25)))}


def backward_outliers(images, scores, *, k=OUTLIER_K, max_listed=3):
    """Outliers by a backward search on a score that already accounts for the point itself.

    Parameters
    ----------
    images : sequence of str
        Image names, one per sample.
    scores : callable
        ``scores(keep)`` with a boolean mask (n,) returns each kept sample's score
        as a lone outlier of the fit to the kept samples (e.g.
        :func:`.fitcheck.spike_scores`; NaN where it cannot be judged); it may raise
        :class:`vision_torsion.errors.AnalysisError` (the search then stops).
    k : float
        Score beyond which a sample is an outlier.
    max_listed : int
        Most samples listed (a loop with more is not an outlier problem).

    Returns
    -------
    list of (str, float)
        ``(image, score)`` worst first; after each, the fit is made again without it.

    Examples
    --------
    >>> import numpy as np
    >>> z = np.array([0.5, 12.0, 6.0, -1.0])  # a spike at 1 whose neighbour 2 shares part of it
    >>> def scores(keep):
    ...     return np.where(keep, z if keep[1] else np.array([0.5, 0.0, 1.0, -1.0]), np.nan)
    >>> backward_outliers(["a", "b", "c", "d"], scores)
    [('b', 12.0)]
    """
    keep = np.ones(len(images), bool)
    found = []
    while len(found) < max_listed and keep.any():
        try:
            z = np.where(keep, np.asarray(scores(keep), float), np.nan)
        except AnalysisError:
            break
        if not np.any(np.isfinite(z)):
            break
        i = int(np.nanargmax(np.abs(z)))
        if abs(z[i]) <= k:
            break
        found.append((str(np.asarray(images)[i]), float(z[i])))
        keep[i] = False
    return found
