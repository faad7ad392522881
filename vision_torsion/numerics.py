"""Numerical mechanics shared across the layers: the numerical Jacobian and the
breakpoint (hinge) fit.

Both are used by the measurement core and by the analyses beside it, so they live at
the bottom of the layers (numpy only; scipy is imported when a breakpoint fit runs,
so a worker that only measures never loads it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["numeric_jacobian", "BreakpointFit", "fit_breakpoints"]


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
    w = np.ones_like(y) if weights is None else np.asarray(weights, dtype=float)
    sw = np.sqrt(w)

    def solve(t):
        a = design(t)
        return a, np.linalg.lstsq(a * sw[:, None], y * sw, rcond=None)[0]

    def sse(t):
        if feasible is not None and not feasible(t):
            return np.inf
        a, coef = solve(t)
        r = y - a @ coef
        return float(r @ r) if weights is None else float(np.sum(w * r * r))

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
    return BreakpointFit(breakpoints=t, coef=solve(t)[1], sse=value)
