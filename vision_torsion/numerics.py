"""Numerical mechanics shared across the layers: the numerical Jacobian, the
breakpoint (hinge) fit, and a grid search that ranks cheaply and decides exactly.

Both are used by the measurement core and by the analyses beside it, so they live at
the bottom of the layers (numpy only; scipy is imported when a breakpoint fit runs,
so a worker that only measures never loads it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["numeric_jacobian", "BreakpointFit", "fit_breakpoints", "weighted_lstsq", "first_least"]


def numeric_jacobian(fun: Callable[[np.ndarray], np.ndarray], p, steps, *, f0=None) -> np.ndarray:
    """Jacobian of a vector function by finite differences, one column per parameter.

    Parameters
    ----------
    fun : callable
        ``fun(p) -> (m,)`` array.
    p : array_like (n,)
        Where to differentiate.
    steps : array_like (n,)
        Step of each parameter (in its unit).
    f0 : array_like (m,), optional
        ``fun(p)``, when the caller has it: forward differences
        ``(fun(p + h·e_j) − f0) / h`` (n evaluations). Without it, central differences
        ``(fun(p + h·e_j) − fun(p − h·e_j)) / 2h`` (2n evaluations, error O(h²)).

    Returns
    -------
    numpy.ndarray (m, n)

    Examples
    --------
    >>> J = numeric_jacobian(lambda p: np.array([p[0] * p[1], p[1] ** 2]), np.array([2.0, 3.0]), [1e-6, 1e-6])
    >>> np.round(J, 6).tolist()
    [[3.0, 2.0], [0.0, 6.0]]
    """
    p = np.asarray(p, dtype=float)
    cols = []
    for j, h in enumerate(np.asarray(steps, dtype=float)):
        dp = np.zeros_like(p)
        dp[j] = h
        if f0 is None:
            cols.append((fun(p + dp) - fun(p - dp)) / (2.0 * h))
        else:
            cols.append((fun(p + dp) - f0) / h)
    return np.column_stack(cols)


@dataclass(frozen=True)
class BreakpointFit:
    """Result of :func:`fit_breakpoints`.

    Attributes
    ----------
    breakpoints : numpy.ndarray
        The nonlinear parameters (break points, and any shape parameter) at the minimum.
    coef : numpy.ndarray
        The linear coefficients at those break points.
    sse : float
        The (weighted) sum of squared residuals there.
    """

    breakpoints: np.ndarray
    coef: np.ndarray
    sse: float


def fit_breakpoints(design: Callable[[np.ndarray], np.ndarray], y, starts, *, weights=None, feasible=None,
                    xatol: float, fatol_rel: float, maxiter: int | None = None) -> BreakpointFit:
    """Fit a model linear in its coefficients for given break points (a hinge fit).

    The model is ``y ≈ design(t) @ coef``: for fixed break points ``t`` the
    coefficients are the (weighted) linear least-squares solution, so the sum of
    squares is profiled over ``t`` alone ("variable projection"). The best of the
    `starts` (first one on a tie) is refined by Nelder–Mead, which is robust to the
    kinks the break points put in that profile.

    Parameters
    ----------
    design : callable
        ``design(t) -> (m, k)`` design matrix for break points ``t``.
    y : array_like (m,)
        The data.
    starts : iterable of array_like
        Starting break points for the search (a grid).
    weights : array_like (m,), optional
        Least-squares weights (1 by default).
    feasible : callable, optional
        ``feasible(t) -> bool``; infeasible break points have an infinite sum of squares.
    xatol : float
        Nelder–Mead's absolute tolerance on ``t``.
    fatol_rel : float
        Nelder–Mead's tolerance on the sum of squares, relative to the best start's.
    maxiter : int, optional
        Nelder–Mead's iteration limit (scipy's default when None).

    Returns
    -------
    BreakpointFit
        ``breakpoints`` is None when no start was feasible.

    Examples
    --------
    >>> x = np.linspace(0.0, 1.0, 41)
    >>> y = np.maximum(x - 0.3, 0.0) * 2.0                # a hinge at 0.3
    >>> fit = fit_breakpoints(lambda t: np.column_stack([np.ones_like(x), np.maximum(x - t[0], 0.0)]), y,
    ...                       [[v] for v in np.linspace(0.1, 0.9, 9)], xatol=1e-9, fatol_rel=1e-12)
    >>> round(float(fit.breakpoints[0]), 6), round(float(fit.coef[1]), 6)
    (0.3, 2.0)
    """
    from scipy.optimize import minimize  # here: measuring alone never needs scipy

    y = np.asarray(y, dtype=float)

    def solve(t):
        return weighted_lstsq(design(t), y, weights)[0]

    def sse(t):
        if feasible is not None and not feasible(t):
            return np.inf
        return weighted_lstsq(design(t), y, weights)[1]

    best, best_t = np.inf, None
    for t in starts:
        v = sse(t)
        if v < best:
            best, best_t = v, np.asarray(t, dtype=float)
    if best_t is None:
        return BreakpointFit(breakpoints=None, coef=None, sse=np.inf)
    options = {"xatol": xatol, "fatol": fatol_rel * max(best, 1e-300)}
    if maxiter is not None:
        options["maxiter"] = maxiter
    res = minimize(sse, best_t, method="Nelder-Mead", options=options)
    t, value = (np.asarray(res.x, dtype=float), float(res.fun)) if res.fun <= best else (best_t, best)
    return BreakpointFit(breakpoints=t, coef=solve(t), sse=value)


def weighted_lstsq(a, y, weights=None) -> tuple[np.ndarray, float]:
    """Weighted linear least squares ``y ≈ a @ coef``: ``(coef, Σ wᵢ rᵢ²)``.

    ``numpy.linalg.lstsq`` of the rows scaled by ``√w`` (the SVD: no normal equations).

    Examples
    --------
    >>> coef, sse = weighted_lstsq(np.array([[1.0, 0.0], [1.0, 1.0], [1.0, 2.0]]), np.array([1.0, 3.0, 5.0]))
    >>> np.round(coef, 12).tolist(), round(sse, 12)
    ([1.0, 2.0], 0.0)
    """
    a = np.asarray(a, dtype=float)
    y = np.asarray(y, dtype=float)
    if weights is None:
        coef = np.linalg.lstsq(a, y, rcond=None)[0]
        r = y - a @ coef
        return coef, float(r @ r)
    w = np.asarray(weights, dtype=float)
    sw = np.sqrt(w)
    coef = np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)[0]
    r = y - a @ coef
    return coef, float(np.sum(w * r * r))


def first_least(approx, exact: Callable[[int], float], *, rtol: float = 1e-6,
                atol: float = 0.0) -> tuple[float, int | None]:
    """``(value, index)`` of the first candidate with the least `exact` value, evaluating few of them.

    A grid search whose candidates can be ranked by a cheap approximation (e.g. one
    stacked normal-equation solve for all of them) but must be decided by the exact
    criterion (e.g. an ``lstsq`` each): candidates are tried in increasing `approx`
    order until the approximation exceeds the best exact value by more than its error
    bound ``rtol·best + atol``. The answer is that of a plain loop over all candidates
    keeping the first least exact value, provided every ``|approx − exact|`` is within
    ``(rtol·exact + atol)/2``.

    Parameters
    ----------
    approx : array_like (n,)
        Approximate values (``inf``: invalid, tried last).
    exact : callable
        ``exact(i) -> float`` for candidate ``i`` (``inf`` when invalid).
    rtol, atol : float
        The approximation's error bound, relative and absolute.

    Returns
    -------
    (float, int or None)
        ``(inf, None)`` when no candidate has a finite exact value.

    Examples
    --------
    >>> vals = [3.0, 1.0, 2.0, 1.0]
    >>> first_least(np.array(vals) + 1e-9, lambda i: vals[i], rtol=1e-6)
    (1.0, 1)
    """
    approx = np.asarray(approx, dtype=float)
    best, best_i = np.inf, None
    for i in np.argsort(approx, kind="stable"):
        if approx[i] > best * (1.0 + rtol) + atol:  # best = inf: every candidate is tried
            break
        v = exact(int(i))
        if v < best or (v == best and best_i is not None and i < best_i):
            best, best_i = v, int(i)
    return (best, best_i) if best_i is not None else (np.inf, None)
