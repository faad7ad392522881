"""One rule for a mean over cycles (or loops) and its standard uncertainty.

Each cycle gives a value with its own propagated standard uncertainty. The mean
over n cycles carries both the scatter between them (Type A, sd/sqrt(n)) and the
propagated part (Type B, sqrt(sum sigma_i^2)/n, the cycles' errors independent):

    u = sqrt(sd^2/n + sum(sigma_i^2)/n^2)

With one cycle there is no scatter to see and u is that cycle's sigma. This is
conservative where the scatter already contains the propagated noise (then the
Type B term counts part of it twice, at most a factor sqrt(2)); the conventions
ask for both parts.
"""

from __future__ import annotations

import numpy as np

__all__ = ["mean_over_cycles"]


def mean_over_cycles(values, stds, *, axis: int = 0):
    """Mean over cycles and its standard uncertainty (module docstring).

    Parameters
    ----------
    values, stds : array_like
        Per-cycle values and their standard uncertainties (same shape), cycles
        along `axis`.
    axis : int
        The cycle axis.

    Returns
    -------
    mean, u : ndarray or float

    Examples
    --------
    >>> mean_over_cycles([100.0, 102.0], [1.0, 1.0])
    (np.float64(101.0), np.float64(1.224744871391589))
    >>> mean_over_cycles([5.0], [0.5])
    (np.float64(5.0), np.float64(0.5))
    """
    v = np.asarray(values, dtype=float)
    s = np.asarray(stds, dtype=float)
    n = v.shape[axis]
    u_b2 = np.sum(s**2, axis=axis) / n**2
    u_a2 = np.var(v, axis=axis, ddof=1) / n if n > 1 else 0.0
    return np.mean(v, axis=axis), np.sqrt(u_a2 + u_b2)
