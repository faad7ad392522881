"""Catalogue stiffness K1, K2, K3 the catalogue way: break torques T1, T2 given
(from the gear's catalogue), the three stiffnesses a **linear** least-squares fit.

Model of the two loading branches (0 → +T and 0 → −T), as
:func:`.metrics.fit_three_segment`: ``θ = θ₀± ± h(|τ|)``, ``h`` continuous and
piecewise linear with slopes ``1/K1`` below T1, ``1/K2`` between, ``1/K3`` above.
With T1, T2 fixed the model is linear in ``(θ₀₊, θ₀₋, 1/K1, 1/K2, 1/K3)``: no
starting value, no search, a unique answer, and first-order uncertainties that are
exact for the linear fit (angle and torque parts, the torque errors with all their
correlations, :mod:`.uncertainty`).

Without catalogue breaks, :func:`fit_catalogue_breaks` fits them, choosing between
**one break (two segments)** and **two breaks (three segments)** by a stated
criterion: two breaks are kept only when they lower the effective-variance ``χ²`` by
more than the 99 % point of ``χ²`` with 2 degrees of freedom (the extra slope and
break), i.e. when the third segment is supported by the data at 1 %. One break is a
valid answer ("two segments"), not a failure.

Every fit goes through the lack-of-fit gate (:mod:`.fitcheck`); a rejected fit is
**flagged** and its uncertainties multiplied by ``√χ²_red``.

With fitted breaks the break torques are estimated from the same data as the
stiffnesses, and the two are strongly correlated (a break placed later makes the
segment below it softer). Their uncertainties are then those of
:func:`break_bootstrap`: every draw refits the breaks too, so K1–K3 carry the
break's uncertainty and T1/T2 get their own.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import optimize, special

from ..errors import AnalysisError
from ..numerics import first_least
from .fitcheck import lack_of_fit
from .uncertainty import linearised_covariance, torque_source_jacobian

__all__ = [
    "fit_fixed_breaks",
    "fit_catalogue_breaks",
    "break_bootstrap",
    "BreakChi2",
    "first_best_placement",
    "TWO_BREAK_ALPHA",
    "BREAK_SLOPE_ALPHA",
]

#: Significance of the third segment when the breaks are fitted.
TWO_BREAK_ALPHA = 0.01
#: Two-sided significance at which a fitted break's neighbouring compliances must differ, before the
#: Bonferroni correction over the two-break placements searched (:func:`fit_catalogue_breaks`).
BREAK_SLOPE_ALPHA = 0.05


def _columns(x, breaks):
    edges = [0.0, *breaks, np.inf]
    return np.column_stack([np.clip(x - lo, 0.0, hi - lo) for lo, hi in zip(edges[:-1], edges[1:])])


def _design(tau, branch, breaks):
    sign = np.asarray(branch, float)
    is_pos = (sign > 0).astype(float)
    return np.column_stack([is_pos, 1.0 - is_pos, _columns(np.abs(tau), breaks) * sign[:, None]])


def _check_inputs(tau, branch):
    sign = np.sign(np.asarray(branch, float))
    if sign.shape != tau.shape or np.any(sign == 0):
        raise AnalysisError("branch must give +1 (0 → +Tmax) or -1 (0 → -Tmax) for every sample")
    for s in (1.0, -1.0):
        if not (np.any((sign == s) & (tau == 0)) and np.any(tau * s > 0)):
            raise AnalysisError("catalogue stiffness needs both loading branches with their zero-torque start")
    return sign


def fit_fixed_breaks(
    torque_nm,
    angle_rad,
    *,
    branch,
    breaks_nm,
    angle_std_rad,
    torque_std_nm,
    torque_sources=None,
    with_uncertainty=True,
    gate_sources=None,
) -> dict:
    """K1..K(m+1) of the loading branches with the break torques fixed (linear least squares).

    Parameters
    ----------
    torque_nm, angle_rad : array_like (n,)
        Loading-branch samples (N·m, rad), each branch with its zero-torque start.
    branch : array_like of ±1
        +1 for the 0 → +Tmax branch, −1 for 0 → −Tmax.
    breaks_nm : sequence of float
        Increasing break torques (N·m), e.g. the catalogue's (T1, T2).
    angle_std_rad, torque_std_nm : array_like (n,)
        1σ per sample (torque: image-to-image part, for the weights and the gate).
    torque_sources : array_like (n, m), optional
        Loading matrix of the torque errors for the uncertainty (default: independent
        ``torque_std_nm``).
    with_uncertainty : bool
        Compute the uncertainties (off inside the break search).
    gate_sources : array_like (n, m'), optional
        Correlated torque errors for the lack-of-fit test (:func:`.fitcheck.lack_of_fit`).

    Returns
    -------
    dict
        ``k`` (list, N·m/rad), ``std_angle``, ``std_torque`` (lists, 1σ before any
        inflation), ``check`` (:class:`.fitcheck.LackOfFit`), ``breaks_nm``,
        ``points_per_segment``; ``coef_cov``: the covariance of the fitted
        ``(θ₀₊, θ₀₋, c_1..c_{m+1})`` (rad², rad²/N·m, (rad/N·m)²; angle and torque
        parts summed, breaks held), with the uncertainties only.

    Raises
    ------
    AnalysisError
        A branch without its zero start, a segment with fewer than two torque levels
        of data, unordered breaks, or a non-positive compliance.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.arange(0, 9) * 0.05
    >>> h = np.minimum(x, 0.1) / 1000 + np.clip(x - 0.1, 0, 0.2) / 2000 + np.maximum(x - 0.3, 0) / 4000
    >>> tau = np.concatenate([x, -x]); th = np.concatenate([h, -h])
    >>> r = fit_fixed_breaks(tau, th, branch=np.repeat([1, -1], 9), breaks_nm=(0.1, 0.3),
    ...                      angle_std_rad=1e-6, torque_std_nm=0.0)
    >>> [round(k) for k in r["k"]]
    [1000, 2000, 4000]
    """
    tau = np.asarray(torque_nm, float).reshape(-1)
    th = np.asarray(angle_rad, float).reshape(-1)
    sa = np.broadcast_to(np.asarray(angle_std_rad, float), tau.shape)
    st = np.broadcast_to(np.asarray(torque_std_nm, float), tau.shape)
    sign = _check_inputs(tau, branch)
    brk = [float(b) for b in breaks_nm]
    if any(b <= 0 for b in brk) or any(b2 <= b1 for b1, b2 in zip(brk, brk[1:])):
        raise AnalysisError(f"break torques must be positive and increasing, got {brk} N·m")
    x = np.abs(tau)
    edges = [0.0, *brk, np.inf]
    counts = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        lv = np.unique(x[(x >= lo - 1e-12) & (x <= hi + 1e-12)])
        counts.append(int(lv.size))
        if lv.size < 2:
            raise AnalysisError(
                f"segment {lo:g} to {hi:g} N·m has {lv.size} measured torque level(s); a stiffness needs at least two"
            )
    a = _design(tau, sign, brk)
    comp = None
    w = 1.0 / np.where(sa > 0, sa**2, 1.0)
    for _ in range(2):  # effective variance: the local compliance enters the weights
        w_used = w
        sw = np.sqrt(w)
        coef = np.linalg.lstsq(a * sw[:, None], th * sw, rcond=None)[0]
        comp_seg = coef[2:]
        seg = np.searchsorted(np.asarray(brk), x, side="right")
        comp = np.abs(comp_seg[seg])
        w = 1.0 / (sa**2 + (comp * st) ** 2)
    if not np.all(coef[2:] > 0):
        raise AnalysisError(
            "catalogue stiffness: a segment has a non-positive compliance (the branches are not monotone there)"
        )
    resid = th - a @ coef
    w_fit = w_used
    check = lack_of_fit(
        resid,
        angle_std_rad=sa,
        torque_std_nm=st,
        compliance_rad_per_nm=comp,
        n_params=a.shape[1],
        torque_sources=gate_sources if with_uncertainty else None,
        jacobian=a,
        weights=w_fit,
    )
    k = [1.0 / c for c in coef[2:]]
    base = {
        "k": k,
        "check": check,
        "breaks_nm": brk,
        "points_per_segment": counts,
        "compliance": comp,
        "residual_rad": resid,
        "coef": coef,
        "weights": w_fit,
    }
    if not with_uncertainty:
        return base
    if torque_sources is None:
        src = np.diag(st)
    else:
        src = np.asarray(torque_sources, float).reshape(tau.size, -1)
    jt = torque_source_jacobian(lambda t: _design(t, sign, brk) @ coef, tau, src)
    try:
        cov_a, cov_t = linearised_covariance(a, w, sa**2, jt, np.ones(jt.shape[1]))
    except np.linalg.LinAlgError:
        raise AnalysisError("catalogue stiffness: the segments are not identified (singular normal matrix)") from None
    s_a = [math.sqrt(max(cov_a[j, j], 0.0)) * k[j - 2] ** 2 for j in range(2, a.shape[1])]
    s_t = [math.sqrt(max(cov_t[j, j], 0.0)) * k[j - 2] ** 2 for j in range(2, a.shape[1])]
    return {**base, "std_angle": s_a, "std_torque": s_t, "coef_cov": cov_a + cov_t}


def break_bootstrap(
    torque_nm,
    *,
    branch,
    fit,
    angle_std_rad,
    torque_sources,
    n_draws=200,
    seed=0,
    iterations=10,
) -> dict:
    """Uncertainty of K1..K(m+1) **and** the fitted breaks: a parametric bootstrap that refits the breaks.

    Parameters
    ----------
    torque_nm : array_like (n,)
        The loading-branch torques of the fit (N·m); the angles enter through
        ``fit`` (the draws are about the fitted model).
    branch : array_like of ±1
        As :func:`fit_fixed_breaks`.
    fit : dict
        The :func:`fit_fixed_breaks` result at the fitted breaks (its ``coef``,
        ``breaks_nm``, ``weights``, ``compliance``).
    angle_std_rad : array_like (n,)
        1σ of each angle, rad.
    torque_sources : array_like (n, m)
        Loading matrix of the torque errors (N·m per unit source,
        :func:`.uncertainty.torque_sources`), every correlation included.
    n_draws : int
        Draws per error source (angle, torque).
    seed : int
        Seed of ``numpy.random.default_rng``.
    iterations : int
        Levenberg–Marquardt iterations of each refit.

    Returns
    -------
    dict
        ``std_angle``, ``std_torque``: lists of the 1σ of each K (N·m/rad);
        ``breaks_std_angle``, ``breaks_std_torque``: of each break (N·m);
        ``u95``, ``breaks_u95``: the half-width of each K's and each break's 95 %
        interval from the draws of both sources at once (see Notes; NaN when fewer
        than half the draws are valid or fewer than 19 are);
        ``draws``: the draws per source; ``valid``: the share of draws whose refit
        converged to ordered breaks with positive compliances (the stds are over
        those; NaN when fewer than half did).

    Notes
    -----
    **Why a bootstrap, and which.** The break of a continuous hinge is weakly
    identified (a few levels on each side of it), so K and T are strongly correlated
    and the first-order covariance at fixed breaks understates K's scatter by an
    order of magnitude; the linearisation in T is also poor once the break's scatter
    reaches the spacing of the levels (the χ² is not differentiable where T crosses
    a level). A profile likelihood would give T's interval but not K's without a
    second profile per K. A *parametric* bootstrap gives all of them at once: the
    fitted model plus draws of the stated noise, ``θ* = f̂(τ) + σθ·z`` (angle part)
    and ``θ* = f̂(τ) + f̂'(τ)·L·ξ`` (torque part: the angle answers the true torque
    ``τ + L·ξ``, read at the nominal one, with every correlation of the weight
    pieces in ``L``), each refitted with its own breaks. The residuals are not
    resampled: there are only ~2 per level, and a misfit is the lack-of-fit gate's
    job (a rejected fit is flagged and its uncertainty inflated by ``√χ²_red``).

    **The refit.** All draws at once: a vectorised Levenberg–Marquardt on
    ``(θ₀₊, θ₀₋, c_1..c_{m+1}, T_1..T_m)`` from the fitted values, with the fit's
    weights. Between measured levels the model at the samples is smooth in ``T``
    (``∂θ/∂T_k = ±(c_{k−1} − c_k)`` for ``|τ| > T_k``, 0 below), so the steps cross
    levels where the data ask for it. The number of breaks is the fitted model's.
    A draw whose refit leaves a segment with fewer than two measured levels, an
    unordered break or a non-positive compliance is not counted.

    **The interval, not only the std.** Where the break is resolved to well within
    the spacing of the levels the draws are close to normal and ``k·std`` is their
    95 % interval. Where it is not, the refit moves the break from one gap between
    levels to the next, K and T jump with it, and the draws' distribution has
    heavier tails than a normal one of the same std (and, the estimator being
    nonlinear, an offset from the fit): ``2·std`` then covers less than 95 %. So the
    draws are also taken with both sources at once (``θ* = f̂ + σθ·z + f̂'·L·ξ``,
    the same ``z`` and ``ξ`` as the two parts) and each quantity's 95 % interval is
    read from them directly, symmetric about the fit (Hall's symmetric bootstrap
    interval): ``u95 = |q* − q̂|₍ᵣ₎``, the r-th smallest of the D valid draws'
    distances from the fit with ``r = ⌈0.95·(D + 1)⌉``. A further draw exchangeable
    with these D lies within the r-th smallest distance with probability
    ``r/(D + 1) ≥ 95 %`` whatever the distribution, so a finite D does not shorten
    the interval (D ≥ 19 is needed for r ≤ D).
    """
    tau = np.asarray(torque_nm, float).reshape(-1)
    sign = np.sign(np.asarray(branch, float)).reshape(-1)
    sa = np.broadcast_to(np.asarray(angle_std_rad, float), tau.shape)
    L = np.asarray(torque_sources, float).reshape(tau.size, -1)
    x = np.abs(tau)
    brk0 = np.asarray(fit["breaks_nm"], float)
    coef0 = np.asarray(fit["coef"], float)
    w = np.asarray(fit["weights"], float)
    m = brk0.size
    is_pos = (sign > 0).astype(float)
    offsets = np.column_stack([is_pos, 1.0 - is_pos])
    levels = np.unique(x)
    model0 = _design(tau, sign, list(brk0)) @ coef0
    rng = np.random.default_rng(seed)
    y_angle = model0[None, :] + rng.standard_normal((n_draws, tau.size)) * sa[None, :]
    y_torque = model0[None, :] + (rng.standard_normal((n_draws, L.shape[1])) @ L.T) * fit["compliance"][None, :]
    y_both = y_angle + y_torque - model0[None, :]

    def design(brk):  # (D, n, m + 3) design and the (D, n, m) derivative mask [x > T_k]
        d = brk.shape[0]
        lo = np.concatenate([np.zeros((d, 1)), brk], axis=1)
        hi = np.concatenate([brk, np.full((d, 1), np.inf)], axis=1)
        cols = np.clip(x[None, :, None] - lo[:, None, :], 0.0, (hi - lo)[:, None, :]) * sign[None, :, None]
        a = np.concatenate([np.broadcast_to(offsets, (d, *offsets.shape)), cols], axis=2)
        return a, (x[None, :, None] > brk[:, None, :]) * sign[None, :, None]

    def chi2_jac(p, y):
        brk = p[:, m + 3 :]
        a, above = design(brk)
        r = y - (a @ p[:, : m + 3, None])[:, :, 0]
        c = p[:, 2 : m + 3]
        dt = above * (c[:, :-1] - c[:, 1:])[:, None, :]
        return np.sum(w * r * r, axis=1), r, np.concatenate([a, dt], axis=2)

    def refit(y):
        d = y.shape[0]
        p = np.tile(np.concatenate([coef0, brk0]), (d, 1))
        lam = np.full(d, 1e-3)
        chi, r, jac = chi2_jac(p, y)
        eye = np.eye(p.shape[1])
        for _ in range(iterations):
            jw = jac * w[None, :, None]
            jtj = jw.transpose(0, 2, 1) @ jac
            diag = np.einsum("dkk->dk", jtj)
            a_mat = jtj + lam[:, None, None] * diag[:, :, None] * eye + 1e-300 * eye
            try:
                step = np.linalg.solve(a_mat, jw.transpose(0, 2, 1) @ r[:, :, None])[:, :, 0]
            except np.linalg.LinAlgError:
                break
            p_new = p + step
            brk = p_new[:, m + 3 :]
            ok = np.all(brk > 0, axis=1) & np.all(np.diff(brk, axis=1) > 0, axis=1) & (brk[:, -1] < levels[-1])
            chi_new, r_new, jac_new = chi2_jac(np.where(ok[:, None], p_new, p), y)
            better = ok & (chi_new < chi)
            p = np.where(better[:, None], p_new, p)
            chi = np.where(better, chi_new, chi)
            r = np.where(better[:, None], r_new, r)
            jac = np.where(better[:, None, None], jac_new, jac)
            lam = np.where(better, lam * 0.3, lam * 10.0)
        brk = p[:, m + 3 :]
        edges_lo = np.concatenate([np.zeros((d, 1)), brk], axis=1)
        edges_hi = np.concatenate([brk, np.full((d, 1), np.inf)], axis=1)
        counts = np.searchsorted(levels, edges_hi + 1e-12, side="right") - np.searchsorted(
            levels, edges_lo - 1e-12, side="left"
        )
        valid = np.all(counts >= 2, axis=1) & np.all(p[:, 2 : m + 3] > 0, axis=1) & np.all(np.isfinite(p), axis=1)
        with np.errstate(divide="ignore"):
            k = 1.0 / p[:, 2 : m + 3]
        return k, brk, valid

    def stds(values, valid):
        if valid.sum() < max(2, valid.size // 2):
            return [float("nan")] * values.shape[1]
        return [float(v) for v in np.std(values[valid], axis=0, ddof=1)]

    def half_widths(values, fitted, valid):
        d = int(valid.sum())
        r = math.ceil(0.95 * (d + 1))
        if d < max(2, valid.size // 2) or r > d:
            return [float("nan")] * values.shape[1]
        dist = np.sort(np.abs(values[valid] - np.asarray(fitted, float)[None, :]), axis=0)
        return [float(v) for v in dist[r - 1]]

    k_a, b_a, v_a = refit(y_angle)
    k_t, b_t, v_t = refit(y_torque)
    k_b, b_b, v_b = refit(y_both)
    return {
        "std_angle": stds(k_a, v_a),
        "std_torque": stds(k_t, v_t),
        "breaks_std_angle": stds(b_a, v_a),
        "breaks_std_torque": stds(b_t, v_t),
        "u95": half_widths(k_b, 1.0 / coef0[2:], v_b),
        "breaks_u95": half_widths(b_b, brk0, v_b),
        "draws": int(n_draws),
        "valid": float(min(v_a.mean(), v_t.mean())),
    }


class BreakChi2:
    """Effective-variance χ² of the fixed-break fit as a function of the breaks: the
    inner loop of the break search of :func:`fit_catalogue_breaks` (no uncertainty, no test).

    Parameters
    ----------
    tau, th : ndarray (n,)
        Loading-branch torques (N·m) and angles (rad), as :func:`fit_fixed_breaks`.
    sign : ndarray (n,) of ±1
        The branch of each sample (+1: 0 → +Tmax, −1: 0 → −Tmax).
    sa, st : ndarray (n,)
        1σ of each angle (rad) and of each torque (N·m, image-to-image part).

    Notes
    -----
    Calling the object with a sequence of increasing breaks ``(T_1..T_m)`` (N·m)
    returns ``(χ², True)``, or ``(inf, None)`` when the placement is unordered,
    leaves a segment with fewer than two measured levels, or gives a non-positive
    compliance. The arithmetic per call is that of :func:`fit_fixed_breaks` (same
    design matrix, same ``lstsq``, two effective-variance passes), so the χ² values are
    the same to the last bit; what does not depend on the breaks (|τ|, the branch
    columns, the measured levels, the first weights) is computed once, as the search
    calls this ~250 times per loop. :meth:`many` ranks many placements at once.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.arange(0, 9) * 0.05
    >>> h = np.minimum(x, 0.1) / 1000 + np.maximum(x - 0.1, 0) / 4000
    >>> tau, th, sign = np.concatenate([x, -x]), np.concatenate([h, -h]), np.repeat([1.0, -1.0], 9)
    >>> chi2 = BreakChi2(tau, th, sign, np.full(18, 1e-6), np.zeros(18))
    >>> round(chi2([0.1])[0], 9), chi2([0.3, 0.2])
    (0.0, (inf, None))
    """

    def __init__(self, tau, th, sign, sa, st):
        self.th, self.sa2, self.st = th, sa**2, st
        self.x = np.abs(tau)
        self.sign = np.asarray(sign, float)
        is_pos = (self.sign > 0).astype(float)
        self.offsets = np.column_stack([is_pos, 1.0 - is_pos])
        self.levels = np.unique(self.x)
        self.w0 = 1.0 / np.where(sa > 0, self.sa2, 1.0)

    def __call__(self, brk):
        brk = list(brk)
        if any(b <= 0 for b in brk) or any(b2 <= b1 for b1, b2 in zip(brk, brk[1:])):
            return np.inf, None
        edges = np.array([0.0, *brk, np.inf])
        lo, hi = edges[:-1], edges[1:]
        lv = self.levels
        # measured levels in each [lo, hi] (as np.unique of the samples there), all segments at once
        if np.any(np.searchsorted(lv, hi + 1e-12, side="right") - np.searchsorted(lv, lo - 1e-12, side="left") < 2):
            return np.inf, None
        # the columns of _columns(), all at once: the same elementwise clip
        cols = np.clip(self.x[:, None] - lo[None, :], 0.0, (hi - lo)[None, :]) * self.sign[:, None]
        a = np.concatenate([self.offsets, cols], axis=1)
        th, w = self.th, self.w0
        seg = np.searchsorted(edges[1:-1], self.x, side="right")
        for _ in range(2):
            sw = np.sqrt(w)
            coef = np.linalg.lstsq(a * sw[:, None], th * sw, rcond=None)[0]
            w_fit = w
            w = 1.0 / np.maximum(self.sa2 + (np.abs(coef[2:][seg]) * self.st) ** 2, 1e-300)
        if not np.all(coef[2:] > 0):
            return np.inf, None
        r = th - a @ coef
        return float(np.sum(w_fit * r * r)), True

    def many(self, breaks) -> np.ndarray:
        """Approximate χ² of many break placements at once, shape ``(B,)`` for ``breaks`` ``(B, m)``.

        The same two effective-variance passes as :meth:`__call__`, as one stacked
        normal-equation solve per pass instead of an ``lstsq`` per placement: it only
        ranks the grid's placements (:func:`first_best_placement`), whose winners are then
        evaluated by :meth:`__call__`. ``inf`` where the placement is invalid (unordered,
        a segment with fewer than two measured levels) or a compliance is clearly
        negative; a compliance within rounding of zero is left to :meth:`__call__`.
        """
        brk = np.atleast_2d(np.asarray(breaks, float))
        n_b = brk.shape[0]
        lo = np.concatenate([np.zeros((n_b, 1)), brk], axis=1)
        hi = np.concatenate([brk, np.full((n_b, 1), np.inf)], axis=1)
        lv = self.levels
        counts = np.searchsorted(lv, hi + 1e-12, side="right") - np.searchsorted(lv, lo - 1e-12, side="left")
        ok = np.all(brk > 0, axis=1) & np.all(np.diff(brk, axis=1) > 0, axis=1) & np.all(counts >= 2, axis=1)
        cols = np.clip(self.x[None, :, None] - lo[:, None, :], 0.0, (hi - lo)[:, None, :]) * self.sign[None, :, None]
        a = np.concatenate([np.broadcast_to(self.offsets, (n_b, *self.offsets.shape)), cols], axis=2)
        seg = np.sum(brk[:, None, :] <= self.x[None, :, None], axis=2)  # searchsorted(breaks, x, "right")
        eye = np.eye(a.shape[2])
        th, w = self.th, np.broadcast_to(self.w0, (n_b, self.x.size))
        for _ in range(2):
            aw = a * w[:, :, None]
            ata = np.where(ok[:, None, None], np.einsum("bnk,bnl->bkl", aw, a), eye)
            coef = np.linalg.solve(ata, np.einsum("bnk,n->bk", aw, th)[:, :, None])[:, :, 0]
            w_fit = w
            comp = np.take_along_axis(coef[:, 2:], seg, axis=1)
            w = 1.0 / np.maximum(self.sa2 + (np.abs(comp) * self.st) ** 2, 1e-300)
        c = coef[:, 2:]
        ok &= np.all(c > -1e-9 * np.max(np.abs(c), axis=1, keepdims=True), axis=1)
        r = th - np.einsum("bnk,bk->bn", a, coef)
        return np.where(ok, np.sum(w_fit * r * r, axis=1), np.inf)


def first_best_placement(chi2: BreakChi2, candidates) -> tuple[float, list | None]:
    """The first of `candidates` with the least exact χ², as a plain loop over them would find it.

    Parameters
    ----------
    chi2 : BreakChi2
        The χ² of the loop's loading branches.
    candidates : array_like (B, m)
        Break placements (N·m), one per row.

    Returns
    -------
    tuple
        ``(χ², breaks)``: the exact :meth:`BreakChi2.__call__` value and the placement
        as a list, the first of equal minima; ``(inf, None)`` when none is valid.

    Notes
    -----
    The stacked :meth:`BreakChi2.many` ranks them and only those within its rounding
    (``1e-6`` relative, ``1e-10`` of the data's weighted sum of squares) of the best
    exact value are fitted by ``lstsq`` (:func:`vision_torsion.numerics.first_least`),
    so the answer is that of ``min`` over ``[chi2(c)[0] for c in candidates]``.
    """
    cands = np.atleast_2d(np.asarray(candidates, float))
    if cands.shape[0] == 0:
        return np.inf, None
    slack = 1e-10 * float(np.sum(chi2.w0 * chi2.th**2))
    best, k = first_least(chi2.many(cands), lambda i: chi2(cands[i])[0], rtol=1e-6, atol=slack)
    return (best, cands[k].tolist()) if k is not None else (np.inf, None)


def _break_slope_z(fit) -> np.ndarray:
    """``|c_k − c_{k+1}| / σ`` at each break of a :func:`fit_fixed_breaks` result (its ``coef_cov``)."""
    c = np.asarray(fit["coef"], float)[2:]
    cov = np.asarray(fit["coef_cov"], float)[2:, 2:]
    d = np.diff(c)
    sd = np.sqrt(np.maximum(np.diag(cov)[1:] + np.diag(cov)[:-1] - 2.0 * np.diag(cov, 1), 0.0))
    # exact data (σ = 0): any change of slope is a break, none is not
    return np.divide(np.abs(d), sd, out=np.where(d == 0, 0.0, np.inf), where=sd > 0)


def fit_catalogue_breaks(
    torque_nm,
    angle_rad,
    *,
    branch,
    angle_std_rad,
    torque_std_nm,
    torque_sources=None,
    gate_sources=None,
    n_draws=200,
    seed=0,
) -> dict:
    """Fit the break torques too: one break (two segments) or two (three), by the stated criterion.

    Returns the :func:`fit_fixed_breaks` dict of the chosen model plus
    ``n_breaks`` (1 or 2), ``delta_chi2`` (one break minus two) and ``criterion``.
    With ``n_draws > 0`` its ``std_angle``/``std_torque`` are those of
    :func:`break_bootstrap` (``n_draws`` draws per source, ``seed``): the breaks'
    uncertainty included; ``breaks_std_angle``, ``breaks_std_torque`` (N·m),
    ``u95``, ``breaks_u95`` (the draws' own 95 % half-widths, both sources at once),
    ``draws`` and ``bootstrap_valid`` are added. With ``n_draws = 0`` the
    uncertainties are first order with the breaks held (no break uncertainty).

    Notes
    -----
    **The criterion.** Two breaks are kept when they lower ``χ²`` by more than
    ``χ²₂`` at :data:`TWO_BREAK_ALPHA` *and* the compliances either side of each break
    differ by more than ``z`` σ (their difference's σ from ``coef_cov``, the breaks
    held, every torque correlation included), ``z`` the two-sided
    :data:`BREAK_SLOPE_ALPHA` point Bonferroni-corrected over the ``N`` two-break
    placements of the grid (``z = Φ⁻¹(1 − α/2N)``, 3.53 for the 120 pairs of 19
    levels): the breaks are put where the fit gains most, so a break's contrast is
    the largest of ``N`` and is tested as such. The ``χ²`` test alone is searched over every
    placement of two breaks, so its false-alarm rate exceeds its nominal 1 %, and a
    false alarm typically puts a break where nothing changes (e.g. inside the soft
    zone, K1 ≈ K2): the stiffnesses are then labelled one segment off, K2 being the
    soft slope where the gear's K2 is the stiff one. A break whose neighbouring
    slopes agree within their uncertainty is not a break, so the segments are
    **merged** (the one-break fit is reported) rather than the two-break figures
    flagged: the merged fit is the model the data support, its K1, K2 are the
    figures the user asked for, and flagging would still show a mislabelled K2 and
    withhold K1. ``criterion`` says when a break was merged and why.

    **The search.** A grid over the mid-points between measured levels, refined by a
    bounded scalar search (one break) or Nelder–Mead (two). An invalid placement
    (``χ² = inf``: a non-positive compliance, as noisy, weakly kinked data give) is
    handed to the bounded search as a finite value above the grid's best, never as
    ``inf`` (Brent's parabola through it is NaN); Nelder–Mead only compares values, so
    it may see ``inf``. A refinement is kept only where it is valid and beats the grid.

    Raises
    ------
    AnalysisError
        Fewer than 4 distinct torque magnitudes, no placement of a break works, or
        (with ``n_draws > 0``) fewer than half of the bootstrap's refits are valid, so
        the breaks are not identified and no uncertainty can be given.
    """
    tau = np.asarray(torque_nm, float).reshape(-1)
    th = np.asarray(angle_rad, float).reshape(-1)
    sa = np.broadcast_to(np.asarray(angle_std_rad, float), tau.shape)
    st = np.broadcast_to(np.asarray(torque_std_nm, float), tau.shape)
    sign = _check_inputs(tau, branch)
    levels = np.unique(np.abs(tau))
    if levels.size < 4:
        raise AnalysisError(f"fitting break torques needs at least 4 distinct torque magnitudes, got {levels.size}")
    mids = 0.5 * (levels[1:] + levels[:-1])
    chi2 = BreakChi2(tau, th, sign, sa, st)

    def bounded(fun, best):
        # Brent's bounded search does arithmetic on the objective (its parabola through three
        # values); an infinite χ² (an invalid placement) would make it NaN. Such a placement
        # gets a finite value above the grid's best instead, so the search turns back, and
        # the refinement is kept only where it is valid and beats the grid.
        penalty = 2.0 * abs(best) + 1.0
        return lambda b: min(fun(b), penalty)

    def best_one():
        v, m = first_best_placement(chi2, mids[1:-1, None])
        if m is None:  # no valid placement: the first mid-point, as min() over the infinite values gave
            return [float(mids[1])]
        m = m[0]
        i = int(np.flatnonzero(mids == m)[0])
        res = optimize.minimize_scalar(
            bounded(lambda b: chi2([b])[0], v), bounds=(levels[i], levels[i + 1]), method="bounded"
        )
        return [float(res.x)] if res.fun <= v and np.isfinite(chi2([res.x])[0]) else [float(m)]

    def best_two():
        pairs = [(mids[i], mids[j]) for i in range(1, mids.size - 1) for j in range(i + 1, mids.size - 1)]
        best = first_best_placement(chi2, np.reshape(pairs, (-1, 2)))
        if best[1] is None:
            return None
        # Nelder–Mead only compares and sorts the values (its spread is taken from the best
        # vertex, which is finite): an infinite χ² is safe here and simply rejected
        res = optimize.minimize(
            lambda b: chi2(sorted(b))[0] if b[0] < b[1] else np.inf,
            np.array(best[1]),
            method="Nelder-Mead",
            options={"xatol": levels[-1] * 1e-6, "maxiter": 200},
        )
        return sorted(res.x.tolist()) if res.fun <= best[0] else best[1]

    b1 = best_one()
    c1, r1 = chi2(b1)
    b2 = best_two() if levels.size >= 6 else None
    c2, r2 = chi2(b2) if b2 is not None else (np.inf, None)
    if r1 is None and r2 is None:
        raise AnalysisError("no placement of the break torques gives positive segment compliances")
    crit = float(special.chdtri(2, TWO_BREAK_ALPHA))  # scipy.stats.chi2.isf
    delta = c1 - c2
    two = r2 is not None and (r1 is None or delta > crit)
    data = dict(branch=sign, angle_std_rad=sa, torque_std_nm=st, torque_sources=torque_sources,
                gate_sources=gate_sources)
    n_pairs = max((mids.size - 2) * (mids.size - 3) // 2, 1)  # the two-break placements of the grid
    z_crit = float(special.ndtri(1.0 - BREAK_SLOPE_ALPHA / (2.0 * n_pairs)))
    criterion = (f"two breaks kept when they lower χ² by more than {crit:.3g} (χ²₂ at {TWO_BREAK_ALPHA:g}) and "
                 f"the compliances either side of each differ by more than {z_crit:.3g} σ")
    out = fit_fixed_breaks(tau, th, breaks_nm=b2 if two else b1, **data)
    if two and r1 is not None:
        z = _break_slope_z(out)
        if np.min(z) <= z_crit:
            j = int(np.argmin(z))
            criterion += (f"; the break at {b2[j]:.4g} N·m lowered χ² by {delta:.3g} but the compliances either "
                          f"side of it differ by only {z[j]:.2g} σ (≤ {z_crit:.3g}), so it is merged (one break)")
            two = False
            out = fit_fixed_breaks(tau, th, breaks_nm=b1, **data)
    out.update(
        n_breaks=2 if two else 1,
        delta_chi2=float(delta) if np.isfinite(delta) else None,
        criterion=criterion,
    )
    if n_draws:
        src = np.diag(st) if torque_sources is None else torque_sources
        boot = break_bootstrap(
            tau, branch=sign, fit=out, angle_std_rad=sa, torque_sources=src, n_draws=n_draws, seed=seed
        )
        if not np.all(np.isfinite([*boot["std_angle"], *boot["std_torque"], *boot["breaks_std_angle"],
                                   *boot["breaks_std_torque"]])):
            # a figure without its uncertainty is withheld, never shown with a NaN ±
            raise AnalysisError(
                f"the fitted break torques {', '.join(f'{b:.4g}' for b in out['breaks_nm'])} N·m are not "
                f"identified: only {100 * boot['valid']:.0f} % of the bootstrap's refits (at least half needed) "
                "kept ordered breaks with two measured levels per segment and positive compliances, so the "
                "uncertainty of K and T cannot be given; give the catalogue T1/T2"
            )
        out.update(
            std_angle=boot["std_angle"],
            std_torque=boot["std_torque"],
            breaks_std_angle=boot["breaks_std_angle"],
            breaks_std_torque=boot["breaks_std_torque"],
            u95=boot["u95"],
            breaks_u95=boot["breaks_u95"],
            draws=boot["draws"],
            bootstrap_valid=boot["valid"],
        )
    return out
