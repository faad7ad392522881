"""Is a fit good enough to show? The lack-of-fit gate, and the stiffness of a phase
whose stiffness switches.

Every slope and model fit of :mod:`.session_analysis` goes through :func:`lack_of_fit`
before it is reported: its residuals are compared with the noise the table implies,

``σ_eff,i² = σθ,i² + (dθ/dτ)ᵢ²·στ,i²``

(the angle noise, and the torque noise carried into angle through the local
compliance of the fitted model, Orear's effective variance). ``χ² = Σ rᵢ²/σ_eff,i²``
with ``dof = n − p`` (``p`` the fitted parameters; for a non-negative least-squares
fit the parameters that are not at zero). The fit is **rejected** when
``P(χ²_dof ≥ χ²) < LACK_OF_FIT_ALPHA`` (0.001: with some 40 fits per session, about
one session in 25 has one false rejection, and a rejection is never silent).

What happens to a rejected figure is decided per figure in :mod:`.session_analysis`
(documented there): a straight-line phase stiffness is **withheld** (it has no
meaning when the stiffness switches; the two stiffnesses below/above the switch and
the secant take its place); model parameters are **flagged** and their uncertainty
multiplied by ``√χ²_red``.

``στ`` here is the part of the torque uncertainty that differs between images: the
common scale error of g and r (``torque_common_std_nm``) moves every torque in
proportion and leaves no residual, so it is removed first (:func:`local_torque_std`).
The weight-piece errors are a random walk in the step number (:mod:`.uncertainty`);
their marginal 1σ is used as if independent, which overstates the scatter a fit can
leave, so the gate errs towards accepting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special  # chdtrc is scipy.stats.chi2.sf, without importing scipy.stats

from ..errors import AnalysisError
from ..numerics import first_least, weighted_lstsq
from .uncertainty import least_squares_weights, linearised_covariance

__all__ = [
    "LACK_OF_FIT_ALPHA",
    "LackOfFit",
    "lack_of_fit",
    "path_compliance",
    "side_compliance",
    "spike_scores",
    "marginal_lack_of_fit",
    "local_torque_std",
    "fit_switch",
    "least_midpoint",
    "switch_in_bracket",
    "secant",
]

#: Significance level of the lack-of-fit test.
LACK_OF_FIT_ALPHA = 1e-3


@dataclass(frozen=True)
class LackOfFit:
    """Result of :func:`lack_of_fit`.

    Attributes
    ----------
    chi2, dof, reduced_chi2, p_value : float, int, float, float
        ``χ²``, its degrees of freedom, ``χ²/dof`` and ``P(χ²_dof ≥ χ²)``.
    rejected : bool
        ``p_value < alpha``.
    residual_rms_rad, noise_rms_rad : float
        RMS residual and RMS of ``σ_eff`` (what a fitting model would leave).
    testable : bool
        False when there is no degree of freedom or no uncertainty to test against;
        then ``rejected`` is False and ``reason`` says why.
    reason : str
    """

    chi2: float
    dof: int
    reduced_chi2: float
    p_value: float
    rejected: bool
    residual_rms_rad: float
    noise_rms_rad: float
    testable: bool = True
    reason: str = ""

    @property
    def inflation(self) -> float:
        """``√max(χ²_red, 1)``: the factor applied to a flagged fit's uncertainty."""
        return math.sqrt(max(self.reduced_chi2, 1.0)) if self.testable else 1.0

    def describe(self) -> str:
        """One sentence for a report: why the fit was rejected."""
        return (
            f"lack of fit: χ²_red = {self.reduced_chi2:.3g} (dof {self.dof}, p = {self.p_value:.2g}); residual "
            f"RMS {math.degrees(self.residual_rms_rad):.3g}° against {math.degrees(self.noise_rms_rad):.3g}° "
            "of noise"
        )

    def to_dict(self) -> dict:
        return {
            "chi2": self.chi2,
            "dof": self.dof,
            "reduced_chi2": self.reduced_chi2,
            "p_value": self.p_value,
            "rejected": self.rejected,
            "residual_rms_deg": math.degrees(self.residual_rms_rad),
            "noise_rms_deg": math.degrees(self.noise_rms_rad),
            "testable": self.testable,
            "reason": self.reason,
        }


def local_torque_std(torque_std_nm, torque_common_std_nm=None) -> np.ndarray:
    """The image-to-image part of the torque 1σ: ``sqrt(στ² − στ,common²)`` (N·m)."""
    st = np.asarray(torque_std_nm, float)
    if torque_common_std_nm is None:
        return st.copy()
    sc = np.nan_to_num(np.asarray(torque_common_std_nm, float), nan=0.0)  # an absent column means no common part
    return np.sqrt(np.clip(st**2 - sc**2, 0.0, None))


def path_compliance(torque_nm, model_angle_rad) -> np.ndarray:
    """Local compliance ``|dθ/dτ|`` (rad/(N·m)) of a model along the sampled torque path.

    The mean of the model's ``|Δθ/Δτ|`` over the one or two path segments that touch
    each sample (segments without a torque change are skipped), so it works for
    path-dependent (hysteretic) models as well as for curves.

    Examples
    --------
    >>> path_compliance([0.0, 1.0, 2.0, 1.0], [0.0, 2.0, 3.0, 1.0]).tolist()
    [2.0, 1.5, 1.5, 2.0]
    """
    tau = np.asarray(torque_nm, float)
    th = np.asarray(model_angle_rad, float)
    dt, dth = np.diff(tau), np.diff(th)
    with np.errstate(divide="ignore", invalid="ignore"):
        seg = np.where(dt != 0, np.abs(dth / dt), np.nan)
    left = np.concatenate([[np.nan], seg])
    right = np.concatenate([seg, [np.nan]])
    both = np.vstack([left, right])
    cnt = np.sum(np.isfinite(both), axis=0)
    out = np.where(cnt > 0, np.nansum(both, axis=0) / np.maximum(cnt, 1), 0.0)
    return out


def side_compliance(predict, torque_nm, *, step_nm=None) -> np.ndarray:
    """Local compliance (rad/(N·m)) of a model at each sample, from each side of the sample.

    A torque error at sample ``i`` moves its angle along the model's own branch at that
    sample: ``c₊`` for an error upwards, ``c₋`` downwards (one-sided derivatives of the
    model along its path, only ``τᵢ`` moved by ``±h``). The effective compliance for a
    symmetric error is their RMS ``√((c₊² + c₋²)/2)``: the compliance of the sample's own
    side wherever the model is smooth there, and both sides at a kink. (The secants of
    :func:`path_compliance` average a branch's stiffness across a kink that lies between
    two levels, and mis-state the noise of the levels beside it.)

    Parameters
    ----------
    predict : callable
        ``predict(torque_path)`` → model angles (rad) along a torque path (N·m).
    torque_nm : array_like (n,)
        The sampled torque path.
    step_nm : float, optional
        The perturbation ``h``; default ``1e-6`` of the largest |torque|.

    Examples
    --------
    >>> side_compliance(lambda t: np.where(np.asarray(t) > 1.0, 3.0 * np.asarray(t) - 2.0, t), [0.0, 1.0, 2.0, 3.0])
    array([1.        , 2.23606798, 3.        , 3.        ])
    """
    tau = np.asarray(torque_nm, float).reshape(-1)
    h = float(step_nm) if step_nm else 1e-6 * max(float(np.max(np.abs(tau))), 1e-12)
    # the path is evaluated with its first torque once more in front: a model anchored at its first
    # sample (θ given there) then still moves that sample when its torque moves
    path = np.concatenate([tau[:1], tau])
    base = np.asarray(predict(path), float)
    # samples inside a monotone run are moved together, every other one (moving a sample inside a run
    # leaves the branch the next ones follow); the ends of runs (reversals, where a model may remember the
    # torque) one at a time
    d = np.sign(np.diff(path))
    inner = np.zeros(path.size, bool)
    inner[1:-1] = (d[:-1] == d[1:]) & (d[1:] != 0)
    inner[0] = False
    groups = [np.flatnonzero(inner & (np.arange(path.size) % 2 == r)) for r in (0, 1)]
    groups += [np.array([i]) for i in np.flatnonzero(~inner)[1:]]
    up = np.zeros(path.size)
    down = np.zeros(path.size)
    for g in groups:
        if g.size == 0:
            continue
        moved = path.copy()
        moved[g] += h
        up[g] = np.abs(np.asarray(predict(moved), float)[g] - base[g]) / h
        moved[g] -= 2 * h
        down[g] = np.abs(base[g] - np.asarray(predict(moved), float)[g]) / h
    return np.sqrt(0.5 * (up[1:] ** 2 + down[1:] ** 2))


def _not_testable(dof: int, rms: float, noise: float, reason: str) -> LackOfFit:
    """A :class:`LackOfFit` that could not be tested: no χ², not rejected, `reason` says why."""
    return LackOfFit(float("nan"), dof, float("nan"), float("nan"), False, rms, noise, False, reason)


def lack_of_fit(
    residual_rad,
    *,
    angle_std_rad,
    torque_std_nm,
    compliance_rad_per_nm,
    n_params,
    alpha=LACK_OF_FIT_ALPHA,
    torque_sources=None,
    jacobian=None,
    weights=None,
) -> LackOfFit:
    """Chi-square test of a fit's residuals against the noise the table implies.

    Parameters
    ----------
    residual_rad : array_like (n,)
        Data minus model, rad.
    angle_std_rad, torque_std_nm : array_like (n,)
        1σ per sample (rad; N·m, the image-to-image part, :func:`local_torque_std`).
    compliance_rad_per_nm : array_like (n,) or float
        Local ``dθ/dτ`` of the model at each sample (:func:`path_compliance`).
    n_params : int
        Fitted parameters.
    alpha : float
        Significance level.
    torque_sources : array_like (n, m), optional
        Loading matrix of correlated torque errors (N·m per unit source, without the
        common g, r scale). Then ``χ² = rᵀC⁻¹r`` with the full covariance
        ``C = diag(σθ²) + (c∘L)(c∘L)ᵀ``: the weight pieces' random walk makes the
        residuals of neighbouring levels move together, and a diagonal ``χ²`` would
        count that as lack of fit. ``torque_std_nm`` is then only used for the
        noise RMS.
    jacobian, weights : array_like (n, p) and (n,), optional
        The fit's Jacobian and least-squares weights. With ``torque_sources`` the
        residuals' own covariance ``S = R·C·Rᵀ``, ``R = I − J(JᵀWJ)⁻¹JᵀW``, is used:
        ``χ² = rᵀS⁺r`` with ``dof = rank S`` (exact to first order for any weights;
        a fit weighted by the angle noise alone lets the noisy points pull it, and
        ``rᵀC⁻¹r`` would then count that as lack of fit).

    Returns
    -------
    LackOfFit
        Not testable (never rejected) when ``n ≤ n_params`` or a sample has no
        positive uncertainty.

    Examples
    --------
    >>> r = lack_of_fit([0.0, 0.01, -0.01, 0.0], angle_std_rad=0.01, torque_std_nm=0.0,
    ...                 compliance_rad_per_nm=1.0, n_params=2)
    >>> r.dof, round(r.reduced_chi2, 3), r.rejected
    (2, 1.0, False)
    """
    r = np.asarray(residual_rad, float).reshape(-1)
    sa = np.broadcast_to(np.asarray(angle_std_rad, float), r.shape)
    st = np.broadcast_to(np.asarray(torque_std_nm, float), r.shape)
    c = np.broadcast_to(np.asarray(compliance_rad_per_nm, float), r.shape)
    var = sa**2 + (c * st) ** 2
    dof = int(r.size - n_params)
    rms = float(np.sqrt(np.mean(r**2))) if r.size else float("nan")
    noise = float(np.sqrt(np.mean(var))) if r.size else float("nan")
    if dof <= 0:
        reason = f"no degree of freedom left to test the fit ({r.size} points, {n_params} parameters)"
        return _not_testable(dof, rms, noise, reason)
    if not np.all(np.isfinite(var)) or np.any(var <= 0) or (torque_sources is not None and np.any(sa <= 0)):
        reason = "a sample has no positive angle or torque uncertainty to test the fit against"
        return _not_testable(dof, rms, noise, reason)
    if torque_sources is None:
        chi2 = float(np.sum(r**2 / var))
    else:
        cl = c[:, None] * np.asarray(torque_sources, float).reshape(r.size, -1)
        cov = np.diag(sa**2) + cl @ cl.T
        noise = float(np.sqrt(np.mean(np.diag(cov))))
        if jacobian is not None:
            evals, evecs, keep = _residual_eig(cov, jacobian, weights)
            z = (evecs[:, keep].T @ r) / np.sqrt(evals[keep])
            chi2 = float(z @ z)
            dof = int(keep.sum())
        else:
            try:
                chol = np.linalg.cholesky(cov)
                z = np.linalg.solve(chol, r)
            except np.linalg.LinAlgError:
                return LackOfFit(
                    float("nan"),
                    dof,
                    float("nan"),
                    float("nan"),
                    False,
                    rms,
                    noise,
                    False,
                    "the noise covariance is singular; the fit cannot be tested",
                )
            chi2 = float(z @ z)
    p = float(special.chdtrc(dof, chi2))
    return LackOfFit(chi2, dof, chi2 / dof, p, bool(p < alpha), rms, noise)


def _residual_eig(cov, jacobian, weights):
    """Eigen-decomposition of the residuals' covariance ``S = R·C·Rᵀ``, ``R = I − J(JᵀWJ)⁻¹JᵀW``, and the
    mask of its non-null eigenvalues (:func:`lack_of_fit`)."""
    n = cov.shape[0]
    jac = np.asarray(jacobian, float).reshape(n, -1)
    w = np.ones(n) if weights is None else np.asarray(weights, float)
    jw = jac * w[:, None]
    try:
        g = np.linalg.solve(jac.T @ jw, jw.T)
    except np.linalg.LinAlgError:
        g = np.linalg.pinv(jac.T @ jw) @ jw.T
    proj = np.eye(n) - jac @ g
    srr = proj @ cov @ proj.T
    evals, evecs = np.linalg.eigh(0.5 * (srr + srr.T))
    return evals, evecs, evals > evals.max() * 1e-10


def marginal_lack_of_fit(residual_rad, *, angle_std_rad, torque_sources, jacobian, weights=None, n_params,
                         alpha=LACK_OF_FIT_ALPHA) -> LackOfFit:
    """Lack of fit by the marginal statistic ``χ² = Σ rᵢ²/Cᵢᵢ``, its null distribution calibrated for
    the correlations (Satterthwaite): ``χ² ≈ a·χ²_ν``.

    ``C = diag(σθ²) + L·Lᵀ`` (``torque_sources`` = ``L``, rad per unit source: the torque errors
    already carried into angle), the residuals' covariance ``S = R·C·Rᵀ`` with the fit's projection
    ``R`` (``jacobian``, ``weights``, as :func:`lack_of_fit`); with ``M = D^{-1/2}·S·D^{-1/2}``,
    ``D = diag(C)``: ``E[χ²] = tr M``, ``Var[χ²] = 2·tr M²``, so ``a = tr M²/tr M`` and
    ``ν = (tr M)²/tr M²`` (Satterthwaite 1946; Box 1954). The statistic weighs each residual by
    its own noise only, so a correlation model that is only approximately right cannot make it
    read a small misfit along a direction of little noise as a large one (the full ``rᵀS⁺r`` can);
    the calibration keeps a residual pattern the correlated errors make (many neighbouring
    residuals of one sign) from reading as lack of fit. ``reduced_chi2`` is ``χ²/E[χ²]`` and
    ``dof`` is ``ν`` rounded (at least 1).

    Examples
    --------
    >>> import numpy as np
    >>> r = np.array([0.0, 0.01, -0.01, 0.0])
    >>> c = marginal_lack_of_fit(r, angle_std_rad=0.01, torque_sources=np.zeros((4, 1)),
    ...                          jacobian=np.ones((4, 1)), n_params=1)
    >>> round(c.reduced_chi2, 3), c.dof, c.rejected
    (0.667, 3, False)
    """
    r = np.asarray(residual_rad, float).reshape(-1)
    sa = np.broadcast_to(np.asarray(angle_std_rad, float), r.shape)
    lsrc = np.asarray(torque_sources, float).reshape(r.size, -1)
    cov = np.diag(sa**2) + lsrc @ lsrc.T
    var = np.diag(cov)
    rms = float(np.sqrt(np.mean(r**2))) if r.size else float("nan")
    noise = float(np.sqrt(np.mean(var))) if r.size else float("nan")
    if r.size - n_params <= 0:
        return _not_testable(int(r.size - n_params), rms, noise,
                             f"no degree of freedom left to test the fit ({r.size} points, {n_params} parameters)")
    if not np.all(np.isfinite(var)) or np.any(var <= 0):
        return _not_testable(int(r.size - n_params), rms, noise,
                             "a sample has no positive angle or torque uncertainty to test the fit against")
    evals, evecs, keep = _residual_eig(cov, jacobian, weights)
    s_rr = (evecs[:, keep] * evals[keep]) @ evecs[:, keep].T
    m = s_rr / np.sqrt(np.outer(var, var))
    tr1, tr2 = float(np.trace(m)), float(np.sum(m * m))
    chi2 = float(np.sum(r**2 / var))
    a, nu = tr2 / tr1, tr1 * tr1 / tr2
    p = float(special.chdtrc(nu, chi2 / a))
    return LackOfFit(chi2, max(int(round(nu)), 1), chi2 / tr1, p, bool(p < alpha), rms, noise)


def spike_scores(residual_rad, *, angle_std_rad, compliance_rad_per_nm, torque_sources, jacobian, weights=None):
    """Each sample's score as a lone outlier (a spike), against correlated noise: ``t_i = (S⁺r)_i/√(S⁺)_ii``.

    ``S`` is the residuals' covariance of :func:`lack_of_fit` (angle noise, the torque sources through
    the compliance, the fit's projection). ``t_i`` is the generalised-least-squares estimate of an
    extra offset at sample ``i`` alone over its standard error, so noise shared by many samples (the
    weight pieces' random walk) does not hide a spike nor make its neighbours look like one, and
    ``t_i²`` is what removing sample ``i`` takes off the fit's χ². NaN where ``(S⁺)_ii`` is 0
    (a sample the fit follows exactly).

    Examples
    --------
    >>> x = np.linspace(-1.0, 1.0, 9)
    >>> r = np.zeros(9); r[4] = 0.01
    >>> t = spike_scores(r, angle_std_rad=np.full(9, 1e-3), compliance_rad_per_nm=1.0,
    ...                  torque_sources=np.zeros((9, 1)), jacobian=np.column_stack([np.ones(9), x]))
    >>> int(np.nanargmax(np.abs(t))), round(float(t[4]), 1)
    (4, 9.4)
    """
    r = np.asarray(residual_rad, float).reshape(-1)
    sa = np.broadcast_to(np.asarray(angle_std_rad, float), r.shape)
    c = np.broadcast_to(np.asarray(compliance_rad_per_nm, float), r.shape)
    cl = c[:, None] * np.asarray(torque_sources, float).reshape(r.size, -1)
    evals, evecs, keep = _residual_eig(np.diag(sa**2) + cl @ cl.T, jacobian, weights)
    v = evecs[:, keep]
    pinv = (v / evals[keep]) @ v.T
    d = np.diag(pinv)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(d > 1e-12 * d.max(), (pinv @ r) / np.sqrt(d), np.nan)


def secant(torque_nm, angle_rad, *, angle_std_rad, torque_std_nm):
    """Secant stiffness between the first and last sample, N·m/rad, with its 1σ parts.

    Returns ``(k, std_angle, std_torque)``; the torque errors of the two ends are taken
    independent (a conservative choice for the weight-piece random walk, whose common
    part cancels in the difference).
    """
    tau = np.asarray(torque_nm, float)
    th = np.asarray(angle_rad, float)
    dtau, dth = tau[-1] - tau[0], th[-1] - th[0]
    if dtau == 0 or not dth * dtau > 0:
        raise AnalysisError(
            f"secant: the angle does not change with the torque's sign between the ends "
            f"(Δτ = {dtau:.4g} N·m, Δθ = {math.degrees(dth):.4g}°)"
        )
    k = dtau / dth
    sa = np.asarray(angle_std_rad, float)
    st = np.asarray(torque_std_nm, float)
    std_angle = abs(k / dth) * math.hypot(sa[0], sa[-1])
    std_torque = abs(1.0 / dth) * math.hypot(st[0], st[-1])
    return k, std_angle, std_torque


def fit_switch(torque_nm, angle_rad, *, angle_std_rad, torque_std_nm, min_per_side=2, torque_sources=None):
    """Two stiffnesses of a loading phase: below and above a switch torque.

    ``θ = θ₀ + c₁·min(x, τ_s) + c₂·max(x − τ_s, 0)`` with ``x = |τ − τ_start|`` the
    torque taken since the phase's start; the switch ``τ_s`` is profiled over the
    mid-points between torque levels and then solved exactly between the best one's
    two levels (:func:`switch_in_bracket`), the compliances being a linear
    least-squares fit for each switch (weights ``1/σ_eff²``).

    torque_sources : array_like (n, m), optional
        Loading matrix of correlated torque errors for the uncertainty (the weight
        pieces' random walk moves a slope far more than independent errors would).

    Returns
    -------
    dict
        ``k_below``, ``k_above`` (N·m/rad), ``switch_nm`` (torque from the start, N·m),
        ``std_angle``/``std_torque`` dicts of these (first order, the switch fitted
        with them), ``model`` (rad, per sample), ``compliance`` (rad/(N·m), per sample),
        ``n_params`` (4).

    Raises
    ------
    AnalysisError
        Fewer than ``2·min_per_side + 1`` samples, or a non-positive compliance.
    """
    tau = np.asarray(torque_nm, float)
    th = np.asarray(angle_rad, float)
    sa = np.asarray(angle_std_rad, float)
    st = np.asarray(torque_std_nm, float)
    sgn = 1.0 if tau[-1] >= tau[0] else -1.0
    x = sgn * (tau - tau[0])
    levels = np.unique(x)
    if levels.size < 2 * min_per_side + 1:
        raise AnalysisError(
            f"a switch needs at least {2 * min_per_side + 1} torque levels in the phase, got {levels.size}"
        )
    y = sgn * th

    def design(ts):
        return np.column_stack([np.ones_like(x), np.minimum(x, ts), np.maximum(x - ts, 0.0)])

    mids = 0.5 * (levels[1:] + levels[:-1])
    cands = mids[min_per_side - 1 : mids.size - (min_per_side - 1)]
    w = least_squares_weights(sa)
    best = None
    for _ in range(2):  # effective variance: the weights depend on the local compliance
        # first the mid-point with the least sum of squares, then the exact optimum between its two torque levels
        i = least_midpoint(x, y, w, cands, design)
        if i is None:
            raise AnalysisError("switch fit: no finite sum of squares at any mid-point between torque levels")
        lo_b = levels[max(i + min_per_side - 1, 0)]
        hi_b = levels[min(i + min_per_side, levels.size - 1)]
        ts = switch_in_bracket(x, y, w, lo_b, hi_b, design)
        coef = weighted_lstsq(design(ts), y, w)[0]
        comp = np.where(x < ts, coef[1], coef[2])
        best = (ts, coef)
        var = sa**2 + (comp * st) ** 2
        if not np.all(var > 0):
            break
        w = 1.0 / var
    ts, coef = best
    if not (coef[1] > 0 and coef[2] > 0):
        raise AnalysisError(
            f"switch fit gives a non-positive compliance (below {coef[1]:.3g}, above {coef[2]:.3g} rad/(N·m))"
        )
    a = design(ts)
    comp = np.where(x < ts, coef[1], coef[2])
    if torque_sources is None:
        jac_tau, g_var = np.diag(comp), st**2
    else:
        jac_tau = comp[:, None] * np.asarray(torque_sources, float).reshape(tau.size, -1)
        g_var = np.ones(jac_tau.shape[1])
    # the switch torque is fitted too: its column in the Jacobian (the torque errors move it, and with it the
    # slopes: holding it fixed understates the torque part of k_below ~10x on the paper's loop)
    a_full = np.column_stack([a, np.where(x > ts, coef[1] - coef[2], 0.0)])
    try:
        cov_a, cov_t = linearised_covariance(a_full, w, sa**2, jac_tau, g_var)
    except np.linalg.LinAlgError:
        raise AnalysisError("switch fit: the compliances are not identified (singular normal matrix)") from None
    out = {
        "switch_nm": ts,
        "n_params": 4,
        "std_angle": {"switch_nm": math.sqrt(max(cov_a[3, 3], 0.0))},
        "std_torque": {"switch_nm": math.sqrt(max(cov_t[3, 3], 0.0))},
    }
    for j, name in ((1, "k_below"), (2, "k_above")):
        k = 1.0 / coef[j]
        out[name] = k
        out["std_angle"][name] = math.sqrt(max(cov_a[j, j], 0.0)) * k * k
        out["std_torque"][name] = math.sqrt(max(cov_t[j, j], 0.0)) * k * k
    out["model"] = sgn * (a @ coef)
    out["design"] = a
    out["weights"] = w
    out["compliance"] = np.where(x < ts, coef[1], coef[2])
    return out


def least_midpoint(x, y, w, cands, design):
    """Index of the first of the switch candidates `cands` with the least weighted sum
    of squares of the hinge ``design`` (``lstsq`` each), or None if none is finite.

    `x` is the torque taken since the phase's start (N·m), `y` the angle (rad), `w` the
    weights (1/rad²), `cands` the switch torques to rank (N·m) and ``design(t)`` the
    hinge's design matrix ``[1, min(x, t), max(x - t, 0)]`` (the step of
    :func:`fit_switch` that picks the bracket).

    One stacked normal-equation solve ranks them all; only those within its rounding
    of the best are fitted by ``lstsq`` (:func:`vision_torsion.numerics.first_least`):
    the same candidate as a loop over them.
    """
    c = np.asarray(cands, float)[:, None]
    a = np.stack([np.ones((c.size, x.size)), np.minimum(x[None, :], c), np.maximum(x[None, :] - c, 0.0)], axis=2)
    aw = a * w[None, :, None]
    with np.errstate(all="ignore"):
        try:
            coef = np.linalg.solve(np.einsum("bnk,bnl->bkl", aw, a), np.einsum("bnk,n->bk", aw, y)[:, :, None])
            r = y[None, :] - np.einsum("bnk,bk->bn", a, coef[:, :, 0])
            approx = np.sum(w[None, :] * r * r, axis=1)
        except np.linalg.LinAlgError:  # a singular candidate: rank them all exactly
            approx = np.zeros(c.size)
    slack = 1e-10 * float(np.sum(w * y * y))
    return first_least(np.where(np.isnan(approx), np.inf, approx), lambda j: weighted_lstsq(design(c[j, 0]), y, w)[1],
                       rtol=1e-6, atol=slack)[1]


def switch_in_bracket(x, y, w, lo, hi, design) -> float:
    """The switch torque in ``[lo, hi]`` (two adjacent torque levels, no sample between)
    with the least weighted sum of squares, exactly (N·m; `x`, `y`, `w`, `design` as
    :func:`least_midpoint` takes them).

    With no sample between ``lo`` and ``hi``, a switch there splits the samples the
    same way wherever it is, and the hinge is two straight lines (the samples at or
    below ``lo``; those at or above ``hi``) that meet at the switch. Its sum of squares
    is the two free lines' plus ``g(τ_s)²/v(τ_s)``, ``g`` the free lines' difference at
    ``τ_s`` (linear) and ``v`` its variance factor (a positive quadratic); this has one
    minimum (zero, where the free lines cross) and one maximum. So the optimum is the
    crossing of the two free weighted lines when it lies in ``[lo, hi]``, else the better
    end (Hudson 1966, *J. Amer. Statist. Assoc.* 61, 1097: fitting segmented curves
    whose join points have to be estimated). This replaces a Nelder–Mead search to
    ``1e-9`` of the torque range.
    """
    below, above = x <= lo, x >= hi
    if np.unique(x[below]).size >= 2 and np.unique(x[above]).size >= 2:
        lines = [weighted_lstsq(np.column_stack([np.ones(int(m.sum())), x[m]]), y[m], w[m])[0] for m in (below, above)]
        (a1, b1), (a2, b2) = lines
        if b1 != b2:
            cross = (a2 - a1) / (b1 - b2)
            if lo <= cross <= hi:
                return float(cross)
    sse_lo, sse_hi = (weighted_lstsq(design(t), y, w)[1] for t in (lo, hi))
    return float(lo if sse_lo <= sse_hi else hi)
