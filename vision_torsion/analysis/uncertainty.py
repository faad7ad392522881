"""Uncertainty propagation: first-order (analytic) for fits and slopes, seeded Monte
Carlo for the model-free loop figures.

Error model (what the analysis assumes about ``measurements.csv``)
-------------------------------------------------------------------
- **Angles**: the ``angle_std_deg`` of each image is independent between images. All
  angles of an orientation are relative to one reference image, whose error is a
  common offset; every figure computed here is a difference or slope of angles of
  the same orientation, so that offset cancels and is not propagated.
- **Torques**: the torque error comes from the weights. The same weights produce the
  same nominal torque each time it recurs, so images with the **same nominal torque**
  (same signed value, to 1e-9 N·m) in a session share **one** torque error with the
  ``torque_std_nm`` given; different torque levels are independent
  (``torque_correlation="level"``, the default). ``"independent"`` treats every
  image's torque error as its own. A common scale error (arm radius, g) is not
  separable from ``torque_std_nm`` and is not modelled separately.
- The **angle part** of an uncertainty is independent between loops (orientations,
  cycles); the **torque part** is shared by all loops of a session under the level
  model. :mod:`.summary` uses this split.

Every figure therefore carries ``std_angle`` and ``std_torque`` (1σ), and
``std = sqrt(std_angle² + std_torque²)``; expanded uncertainties are
``u95 = 2·std`` (coverage factor k = 2, ≈95 % for a normal distribution).

Monte Carlo
-----------
Model-free figures (hysteresis, lost motion, loop energy, ...) are non-linear in the
data (maxima, interpolation), so they are propagated by drawing ``n_draws`` (default
400: the std is then known to ≈ 1/sqrt(2·400) ≈ 3.5 %) perturbed copies of a loop,
once with angle errors only and once with torque errors only, from
``numpy.random.default_rng(seed)``; every figure is evaluated on all draws at once
(vectorised), so a loop costs milliseconds. The std of a figure is the standard
deviation over draws where it is finite.
"""

from __future__ import annotations

import numpy as np

__all__ = ["COVERAGE_FACTOR", "torque_groups", "monte_carlo_std", "linearised_covariance"]

#: Coverage factor of every ``*_u95`` (normal distribution, ≈95 %).
COVERAGE_FACTOR = 2.0


def torque_groups(torque_nm, *, correlation="level", resolution_nm=1e-9) -> np.ndarray:
    """Index of the shared torque error of each sample.

    Parameters
    ----------
    torque_nm : array_like
        Nominal torques, N·m.
    correlation : {"level", "independent"}
        ``"level"``: samples with the same nominal torque (rounded to
        ``resolution_nm``) share one error; ``"independent"``: one error per sample.

    Returns
    -------
    numpy.ndarray of int
        Group index per sample (0 .. n_groups−1).

    Examples
    --------
    >>> torque_groups([0.1, 0.0, 0.1, -0.1]).tolist()
    [2, 1, 2, 0]
    """
    tau = np.asarray(torque_nm, dtype=float).reshape(-1)
    if correlation == "independent":
        return np.arange(tau.size)
    if correlation != "level":
        from ..errors import AnalysisError

        raise AnalysisError(f"torque_correlation must be 'level' or 'independent', got {correlation!r}")
    keys = np.round(tau / resolution_nm).astype(np.int64)
    _, inverse = np.unique(keys, return_inverse=True)
    return inverse.reshape(-1)


def _group_std(groups: np.ndarray, torque_std_nm: np.ndarray) -> np.ndarray:
    out = np.zeros(int(groups.max()) + 1 if groups.size else 0)
    np.maximum.at(out, groups, np.asarray(torque_std_nm, float))
    return out


def monte_carlo_std(evaluate, torque_nm, angle_rad, *, angle_std_rad, torque_std_nm, groups,
                    n_draws=400, seed=0):
    """Standard deviation of each figure of a loop from angle and from torque errors.

    Parameters
    ----------
    evaluate : callable
        ``evaluate(tau2d, theta2d) -> dict[str, ndarray (D,)]`` evaluating every figure
        on D perturbed copies at once (``tau2d``, ``theta2d`` of shape (D, n)).
    torque_nm, angle_rad : ndarray (n,)
        Nominal data (N·m, rad).
    angle_std_rad, torque_std_nm : ndarray (n,)
        1σ per sample.
    groups : ndarray of int (n,)
        Shared torque error index (:func:`torque_groups`).
    n_draws : int
        Draws per error source.
    seed : int
        Seed of ``numpy.random.default_rng``.

    Returns
    -------
    (dict, dict)
        ``std_angle[name]`` and ``std_torque[name]`` (NaN where fewer than half the
        draws gave a finite value).
    """
    rng = np.random.default_rng(seed)
    tau = np.asarray(torque_nm, float)[None, :]
    th = np.asarray(angle_rad, float)[None, :]
    g_std = _group_std(groups, torque_std_nm)
    d_theta = rng.standard_normal((n_draws, th.shape[1])) * np.asarray(angle_std_rad, float)[None, :]
    d_tau = (rng.standard_normal((n_draws, g_std.size)) * g_std[None, :])[:, groups]
    by_angle = evaluate(np.repeat(tau, n_draws, axis=0), th + d_theta)
    by_torque = evaluate(tau + d_tau, np.repeat(th, n_draws, axis=0))
    return _stds(by_angle), _stds(by_torque)


def _stds(values: dict) -> dict:
    out = {}
    for name, v in values.items():
        v = np.asarray(v, float)
        ok = np.isfinite(v)
        out[name] = float(np.std(v[ok], ddof=1)) if ok.sum() >= max(2, v.size // 2) else float("nan")
    return out


# ---------------------------------------------------------------------------------
# First-order propagation through least-squares estimates
# ---------------------------------------------------------------------------------


def numeric_jacobian(fun, p: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Central-difference Jacobian of a vector function (one column per parameter)."""
    cols = []
    for j, h in enumerate(steps):
        dp = np.zeros_like(p)
        dp[j] = h
        cols.append((fun(p + dp) - fun(p - dp)) / (2.0 * h))
    return np.column_stack(cols)


def torque_jacobian(model, tau: np.ndarray, groups: np.ndarray, h: float = 1e-7) -> np.ndarray:
    """d(model angles)/d(shared error of each torque group), by central differences."""
    n_groups = int(groups.max()) + 1 if groups.size else 0
    cols = []
    for g in range(n_groups):
        d = np.where(groups == g, h, 0.0)
        cols.append((model(tau + d) - model(tau - d)) / (2.0 * h))
    return np.column_stack(cols) if cols else np.zeros((tau.size, 0))


def linearised_covariance(jac_p, weights, angle_var, jac_tau, group_var):
    """Covariance of a weighted least-squares estimate from angle and torque errors.

    Parameters
    ----------
    jac_p : ndarray (n, p)
        d(model)/d(parameters) at the estimate.
    weights : ndarray (n,)
        Weights of the least-squares criterion ``Σ w_i r_i²``.
    angle_var : ndarray (n,)
        Variance of each (independent) angle, rad².
    jac_tau : ndarray (n, g)
        d(model)/d(torque error of each group).
    group_var : ndarray (g,)
        Variance of each group's torque error, (N·m)².

    Returns
    -------
    (ndarray, ndarray)
        Parameter covariance from angle errors and from torque errors.

    Raises
    ------
    numpy.linalg.LinAlgError
        The normal matrix is singular (a parameter is not identified by the data).

    Notes
    -----
    To first order ``δp = G·δθ`` with ``G = (JᵀWJ)⁻¹JᵀW``; a torque error ``δτ`` moves
    the model by ``J_τ·δτ``, which the estimate absorbs like an angle error of opposite
    sign, so ``cov = G·diag(σθ²)·Gᵀ + (G·J_τ)·diag(στ²)·(G·J_τ)ᵀ`` (sandwich form,
    valid also when the weights are not the inverse variances).
    """
    jw = jac_p * weights[:, None]
    normal = jac_p.T @ jw
    # a near-singular normal matrix means a parameter is not identified by the data
    if not np.all(np.isfinite(normal)) or np.linalg.cond(normal) > 1e14:
        raise np.linalg.LinAlgError("normal matrix is singular")
    g = np.linalg.solve(normal, jw.T)
    cov_a = (g * angle_var[None, :]) @ g.T
    gt = g @ jac_tau
    cov_t = (gt * group_var[None, :]) @ gt.T
    return cov_a, cov_t


def parameter_stds(names, cov_a, cov_t):
    """1σ per parameter name from angle and torque covariance matrices."""
    sa = dict(zip(names, (float(v) for v in np.sqrt(np.clip(np.diag(cov_a), 0, None)))))
    st = dict(zip(names, (float(v) for v in np.sqrt(np.clip(np.diag(cov_t), 0, None)))))
    return sa, st


def least_squares_weights(angle_std_rad) -> np.ndarray:
    """Inverse-variance weights; equal weights when no angle uncertainty is given."""
    s = np.asarray(angle_std_rad, dtype=float)
    if np.all(s > 0):
        return 1.0 / s**2
    return np.ones_like(s)
