"""Summaries across loops: per orientation, across the session, the uncertainty budget
of each mean, and a test of the orientation effect against the cycle-to-cycle scatter.

Input is the long *figures* table of :func:`.session.analyze_session` (one row per
orientation, cycle and figure with ``value``, ``std_angle``, ``std_torque`` and the
torque parts ``std_weights``, ``std_g_r``, ``std_friction``, ``std_torque`` (level
model), ``std_lack_of_fit``).

Notes
-----
- **Mean across loops** and its standard uncertainty (GUM):
  the part that differs from loop to loop is known twice, propagated
  (``u_prop = sqrt(Σσ_a,i²)/n``: angle noise, independent between loops) and observed
  (**Type A**, ``u_A = sd/√n``, which also holds the cycle-to-cycle repeatability of
  the gear); it is the larger of the two (the observed scatter already contains the
  propagated noise, adding both would count it twice). The torque parts (weights,
  g and r, friction) and the lack of fit are common to all loops and do not average
  down: the mean of each over loops. All in quadrature give ``u_c``.
  The expanded uncertainty is that of Type A, its Student t at ``n − 1`` degrees of
  freedom convolved with the normal rest (:func:`.uncertainty.coverage_factor_t_normal`,
  JCGM 101, k never below 2), or k = 2 on the propagated part, whichever is larger;
  ``coverage_factor`` is their ratio to ``std``. (Taking k = 2 on the propagated part
  whenever the observed scatter came out below it covered only 87–93 % of two-loop
  means whose angle noise is 0.1–0.5 of the repeatability: a small scatter of two
  values is a chance low that the t already allows for.) The
  Welch–Satterthwaite ``t`` at ``ν_eff = u_c⁴/(u_A⁴/(n−1))`` (GUM G.4) covered only
  87–92 % of the benchmark's two-loop session means (``benchmarks/bench_figures.py``):
  with ``n = 2`` it is known to under-cover when the other parts are about a third
  of ``u_A``. ``dof`` reports ``ν_eff`` for information.
- The same rules give each **orientation's mean** over its cycles (``per_orientation``).
- A **mean of one loop** is flagged: its uncertainty holds the measurement only, the
  repeatability between loops cannot be observed from one loop (the benchmark's 2 %
  cycle-to-cycle scatter put such means 20–500 u off the gear's value). A mean that
  includes flagged loop figures is flagged too (``flag`` says which and why).
- **Orientation effect**: a one-way ANOVA of the loop values grouped by orientation
  (:func:`orientation_anova`): the orientation effect is tested against the
  cycle-to-cycle scatter, never against the measurement noise alone (which leaves
  out the gear's own repeatability and so calls every difference "significant").
  With one cycle per orientation there is no replicate scatter: the effect size
  (sd of the orientation values over their mean) is reported and the test is not
  made.
- **One test family**: the figures of a session are tested together, so the
  family-wise error rate (the chance that any figure comes out "significant" when no
  orientation has an effect) is held at :data:`ALPHA` by Holm's step-down procedure
  over the tested figures (:func:`holm_adjust`; Holm 1979, valid for any dependence
  between the tests, as these ~27 figures of the same loops are). A figure is
  ``significant`` when its Holm-adjusted p (``p_value_holm``) is below ``ALPHA``;
  its own ANOVA p stays in ``p_value``. Fit statistics (a model's residual RMS,
  ``method == "fit statistic"``) describe a fit, not the gear: they are not tested
  and not in the family.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

# scipy.special, not scipy.stats: the same functions (scipy.stats.chi2/f/t call them), a
# ~0.5 s less to import (`analyze` must run in <= 3 s: benchmarks/bench_analyze.py)
from scipy import special

from .uncertainty import COVERAGE_FACTOR, coverage_factor_t_normal

__all__ = ["ALPHA", "FAMILY_METHOD", "summarise_figures", "orientation_test", "orientation_anova", "holm_adjust",
           "mean_uncertainty", "BUDGET_LABELS"]

#: Significance level of the orientation test (family-wise, over the figures of a session).
ALPHA = 0.05
#: How the orientation tests of a session's figures are combined (for the report text).
FAMILY_METHOD = (
    "one-way ANOVA per figure against the cycle-to-cycle scatter; Holm's step-down correction over the "
    "{m} figures tested holds the family-wise error (any figure called significant when there is no "
    "orientation effect) at {alpha:g}; fit statistics are not tested"
)


def holm_adjust(p_values) -> np.ndarray:
    """Holm's step-down adjusted p-values (Holm 1979), NaN entries left out of the family.

    ``p_adj(i) = max_{j ≤ i} min(1, (m − j)·p(j))`` over the ``m`` finite p-values in
    ascending order (j from 0); rejecting ``p_adj < α`` holds the family-wise error at
    α whatever the dependence between the tests.

    Examples
    --------
    >>> holm_adjust([0.01, 0.04, float("nan"), 0.03]).round(3).tolist()
    [0.03, 0.06, nan, 0.06]
    """
    p = np.asarray(p_values, float)
    out = np.full(p.shape, np.nan)
    idx = np.flatnonzero(np.isfinite(p))
    m = idx.size
    if m == 0:
        return out
    order = idx[np.argsort(p[idx], kind="stable")]
    adj = np.minimum(1.0, (m - np.arange(m)) * p[order])
    out[order] = np.maximum.accumulate(adj)
    return out


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

    Kept for means whose uncertainties include the replicate scatter; the session
    summary uses :func:`orientation_anova` (the noise alone is not the right yardstick).

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
    p = float(special.chdtrc(dof, chi2))
    return {"chi2": chi2, "dof": dof, "p_value": p, "significant": bool(p < ALPHA), "reason": None}


def orientation_anova(groups) -> dict:
    """One-way ANOVA of a figure's loop values grouped by orientation.

    Parameters
    ----------
    groups : sequence of array_like
        Values of each orientation (one per cycle).

    Returns
    -------
    dict
        ``test`` ("one-way ANOVA"), ``f``, ``dof`` ([between, within]), ``p_value``,
        ``significant`` (p < :data:`ALPHA`), ``effect_size`` (sd of the orientation
        means / |grand mean|), ``range`` (of the orientation means), ``reason``
        (why not tested, else None).

    Examples
    --------
    >>> r = orientation_anova([[1.0, 1.1], [1.0, 1.1], [1.0, 1.1]])
    >>> r["significant"], r["dof"]
    (False, [2, 3])
    >>> orientation_anova([[1.0], [1.2]])["reason"].startswith("one cycle per orientation: no cycle-to-cycle scatter")
    True
    """
    g = [np.asarray(v, float)[np.isfinite(np.asarray(v, float))] for v in groups]
    g = [v for v in g if v.size]
    means = np.array([v.mean() for v in g]) if g else np.zeros(0)
    grand = float(np.mean(np.concatenate(g))) if g else float("nan")
    out = {
        "test": "one-way ANOVA",
        "f": None,
        "dof": None,
        "p_value": None,
        "significant": None,
        "effect_size": (float(np.std(means, ddof=1) / abs(grand)) if means.size >= 2 and grand != 0 else None),
        "range": float(np.ptp(means)) if means.size >= 2 else None,
        "reason": None,
    }
    if len(g) < 2:
        out["reason"] = "fewer than two orientations with a value"
        return out
    n = sum(v.size for v in g)
    if n - len(g) < 1:
        out["reason"] = (
            "one cycle per orientation: no cycle-to-cycle scatter to test the orientation effect "
            "against (effect size reported, not tested)"
        )
        return out
    within = sum(float(np.sum((v - v.mean()) ** 2)) for v in g)
    between = sum(v.size * (v.mean() - grand) ** 2 for v in g)
    d1, d2 = len(g) - 1, n - len(g)
    if within <= 0:
        out["reason"] = "no scatter at all between cycles: the test is undefined"
        return out
    f = (between / d1) / (within / d2)
    p = float(special.fdtrc(d1, d2, f))
    out.update(f=float(f), dof=[d1, d2], p_value=p, significant=bool(p < ALPHA))
    return out


_KINDS = ("weights", "g_r", "friction", "level")
BUDGET_LABELS = {
    "angle_noise": "angle noise (propagated)",
    "repeatability": "repeatability between loops (Type A)",
    "between_orientations": "spread between orientations, one cycle each (Type A: orientation effect and "
    "repeatability together)",
    "weights": "weights",
    "g_r": "g and r (scale)",
    "friction": "pulley friction",
    "level": "torque (per level)",
    "torque_total": "torque (all sources)",
    "lack_of_fit": "lack of fit",
}


def _finite_mean(x) -> float:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.mean(x)) if x.size else 0.0


def _col(sub, name) -> np.ndarray:
    return np.asarray(sub[name], dtype=float)


def _one_cycle_each(sub) -> bool:
    """Whether the loops of ``sub`` are one per orientation, from two or more orientations."""
    if "orientation_deg" not in sub:
        return False
    o = np.asarray(sub["orientation_deg"], float)
    _, counts = np.unique(o, return_counts=True)
    return counts.size >= 2 and bool(np.all(counts == 1))


def mean_uncertainty(sub) -> dict:
    """Uncertainty budget of the mean of ``sub["value"]`` (module notes).

    ``sub`` is a DataFrame, or a dict of equal-length arrays with the same column names
    (what :func:`summarise_figures` passes: pandas filtering per figure and orientation
    cost a fifth of the analysis).

    Returns ``{"mean", "n", "sd", "std", "coverage_factor", "u95", "dof", "budget": {...}}``.
    """
    v = _col(sub, "value")
    n = v.size
    sa = _col(sub, "std_angle")
    if not (np.any(np.isfinite(sa)) or np.any(np.isfinite(_col(sub, "std_torque")))):
        # a fit statistic or a profiled value: no uncertainty to summarise
        return {
            "mean": float(np.mean(v)) if n else None,
            "n": n,
            "sd": float(np.std(v, ddof=1)) if n >= 2 else None,
            "std": float("nan"),
            "coverage_factor": None,
            "u95": float("nan"),
            "dof": None,
            "budget": {"angle_noise": float("nan")},
        }
    st = _col(sub, "std_torque")
    if "std_lack_of_fit" in sub:
        # a flagged fit's angle and torque parts come inflated by √χ²_red and its lack of fit is a budget
        # line of its own (std² = std₀² + lof²): take the parts back to std₀ so the lack of fit counts once
        lof = np.nan_to_num(_col(sub, "std_lack_of_fit"), nan=0.0)
        tot = np.hypot(np.nan_to_num(sa, nan=0.0), np.nan_to_num(st, nan=0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            deflate = np.where((lof > 0) & (tot > lof), np.sqrt(np.clip(tot**2 - lof**2, 0.0, None)) / tot, 1.0)
        sa, st = sa * deflate, st * deflate
    u_prop = float(np.sqrt(np.nansum(sa**2)) / n) if n else float("nan")
    sd = float(np.std(v, ddof=1)) if n >= 2 else float("nan")
    u_a = sd / math.sqrt(n) if n >= 2 else float("nan")
    budget = {"angle_noise": u_prop, "repeatability": u_a if n >= 2 else None}
    if n >= 2 and _one_cycle_each(sub):
        # one loop per orientation: the scatter is between orientations (an orientation effect and the
        # repeatability together), not a repeatability observed on replicates
        budget["between_orientations"] = budget.pop("repeatability")
    rand = max(u_prop, u_a) if n >= 2 else u_prop
    total = rand**2 if np.isfinite(rand) else 0.0
    have_parts = all(f"std_{k}" in sub for k in _KINDS)
    if have_parts and all(np.all(np.isfinite(_col(sub, f"std_{k}"))) for k in _KINDS):
        for k in _KINDS:
            u = float(np.mean(_col(sub, f"std_{k}")))
            budget[k] = u
            total += u * u
    else:
        u = _finite_mean(st)
        budget["torque_total"] = u
        total += u * u
    if "std_lack_of_fit" in sub:
        lof = _col(sub, "std_lack_of_fit")
        u = _finite_mean(lof)
        budget["lack_of_fit"] = u
        total += u * u
    if "std_sampling" in sub:  # the loop sampled by its levels: the same bias in every loop, not averaged down
        u = _finite_mean(_col(sub, "std_sampling"))
        if u > 0:
            budget["sampling"] = u
            total += u * u
    std = math.sqrt(total)
    dof = math.inf
    k = COVERAGE_FACTOR
    if n >= 2 and u_a > 0:
        u_rest = math.sqrt(max(total - rand * rand, 0.0))  # the parts common to all loops
        u_c = math.hypot(u_a, u_rest)
        # the Type A interval (t ⊗ normal), never shorter than the propagated one (k = 2 on the propagated
        # random part): a scatter that happens to come out below the propagated noise is a chance low of an
        # estimate whose t already allows for it, not a smaller repeatability
        expanded = max(max(COVERAGE_FACTOR, coverage_factor_t_normal(u_a, n - 1, u_rest)) * u_c,
                       COVERAGE_FACTOR * math.hypot(u_prop, u_rest))
        k = expanded / std
        if u_a >= u_prop:
            dof = std**4 / (u_a**4 / (n - 1))  # Welch–Satterthwaite, for information
    return {
        "mean": float(np.mean(v)) if n else None,
        "n": n,
        "sd": sd if n >= 2 else None,
        "std": std,
        "coverage_factor": k,
        "u95": k * std,
        "dof": dof if np.isfinite(dof) else None,
        "budget": budget,
    }


def _flagged(rows: dict) -> int:
    """How many of the loop values in ``rows`` (column arrays) carry a flag."""
    return int(np.sum(rows["flag"].astype(str) != "")) if "flag" in rows else 0


def _mean_flag(entry: dict) -> str:
    """Why a mean across loops (of the session or of one orientation) cannot be taken at its
    u95 (module notes), or "": ``entry`` holds ``n``, ``mean_u95`` and ``flagged``."""
    why = []
    if entry["n"] == 1 and entry.get("mean_u95") is not None:
        why.append(
            "mean of one loop: its uncertainty holds the measurement only, the repeatability between loops "
            "is not observed (measure more loops or cycles)"
        )
    if entry["flagged"]:
        why.append(f"{entry['flagged']} of its {entry['n']} loop values are flagged (see the issues)")
    return "flagged: " + "; ".join(why) if why else ""


def _fit_statistic(data: dict, rows: np.ndarray) -> bool:
    """Whether a figure's rows are a fit statistic (its ``method``), not a figure of the gear."""
    return "method" in data and rows.size > 0 and bool(np.all(data["method"][rows] == "fit statistic"))


def _holm(summary: dict) -> None:
    """Holm over the orientation tests of ``summary`` (module notes): ``p_value_holm``, ``significant``, ``family``."""
    names = [f for f, e in summary.items() if e["orientation_test"].get("p_value") is not None]
    adj = holm_adjust([summary[f]["orientation_test"]["p_value"] for f in names])
    family = FAMILY_METHOD.format(m=len(names), alpha=ALPHA)
    for f, e in summary.items():
        t = e["orientation_test"]
        t["family"] = family
        t["p_value_holm"] = None
    for f, pa in zip(names, adj):
        t = summary[f]["orientation_test"]
        t.update(p_value_holm=float(pa), significant=bool(pa < ALPHA))


def summarise_figures(figures: pd.DataFrame) -> tuple[dict, pd.DataFrame]:
    """Summary per figure across loops and per orientation.

    Parameters
    ----------
    figures : pandas.DataFrame
        Columns ``orientation_deg, cycle, figure, unit, value, std_angle, std_torque``
        (and the budget parts when present).

    Returns
    -------
    summary : dict
        ``{figure: {unit, n, mean, sd, min, max, range, mean_std, mean_u95,
        coverage_factor, dof, budget, flagged, withheld, flag, orientation_test}}`` over
        finite values (``flagged``: how many loop values are flagged; ``flag``: why the
        mean itself is flagged, or "").
    per_orientation : pandas.DataFrame
        ``orientation_deg, figure, unit, n_cycles, mean, sd, std, std_angle,
        std_torque, coverage_factor, u95, flag``: the mean over the orientation's
        cycles by the same rules as the session mean (:func:`mean_uncertainty`: 1σ
        ``std``, ``u95 = coverage_factor·std``; ``flag`` as the session mean's, so a
        mean of one cycle is flagged).
    """
    rows = []
    summary = {}
    # the columns once, as arrays; each figure's and orientation's rows by index (the same rows, in
    # the same order, as the boolean filters and groupby of the frame)
    data = {c: figures[c].to_numpy() for c in figures.columns}
    value = np.asarray(data["value"], dtype=float)
    finite = np.isfinite(value)
    names = data["figure"]
    orient_all = np.asarray(data["orientation_deg"], dtype=float)
    for fig in pd.unique(names):
        rows_all = np.flatnonzero(names == fig)
        unit = str(data["unit"][rows_all[0]])
        idx = rows_all[finite[rows_all]]
        good = {c: a[idx] for c, a in data.items()}
        entry = {"unit": unit, **_describe(value[idx])}
        if entry["n"]:
            mu = mean_uncertainty(good)
            entry.update(
                mean_std=mu["std"] if np.isfinite(mu["std"]) else None,
                mean_u95=mu["u95"] if np.isfinite(mu["u95"]) else None,
                coverage_factor=mu["coverage_factor"],
                dof=mu["dof"],
                budget=mu["budget"],
            )
        else:
            entry.update(mean_std=None, mean_u95=None, coverage_factor=None, dof=None, budget=None)
        entry["flagged"] = _flagged(good)
        entry["withheld"] = int(rows_all.size - idx.size)
        entry["flag"] = _mean_flag(entry)
        groups = []
        orient = orient_all[idx]
        for o in np.unique(orient[np.isfinite(orient)]):
            og = {c: a[orient == o] for c, a in good.items()}
            v = value[idx][orient == o]
            mu = mean_uncertainty(og)
            u95 = mu["u95"] if np.isfinite(mu["u95"]) else None
            rows.append(
                {
                    "orientation_deg": float(o),
                    "figure": fig,
                    "unit": unit,
                    "n_cycles": int(v.size),
                    "mean": float(np.mean(v)),
                    "sd": mu["sd"] if mu["sd"] is not None else np.nan,
                    "std": mu["std"],
                    "std_angle": mu["budget"]["angle_noise"],
                    "std_torque": _finite_mean(_col(og, "std_torque")),
                    "coverage_factor": mu["coverage_factor"] if mu["coverage_factor"] is not None else np.nan,
                    "u95": mu["u95"],
                    "flag": _mean_flag({"n": int(v.size), "mean_u95": u95, "flagged": _flagged(og)}),
                }
            )
            groups.append(v)
        if _fit_statistic(data, rows_all):
            entry["orientation_test"] = {**orientation_anova([]), "reason": "a fit statistic, not a figure: not tested"}
        else:
            entry["orientation_test"] = orientation_anova(groups)
        summary[fig] = entry
    _holm(summary)
    cols = ["orientation_deg", "figure", "unit", "n_cycles", "mean", "sd", "std", "std_angle", "std_torque",
            "coverage_factor", "u95", "flag"]
    return summary, pd.DataFrame(rows, columns=cols)
