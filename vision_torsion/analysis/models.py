"""Hysteresis models of the torque–angle loop: the paper's bilinear stiffness switch
and a torque-driven Bouc–Wen model, each as a simulator and a least-squares fit.

Both models are *torque driven*: the applied torque sequence is the input and the
rotation angle of the input shaft the output, which is how the rig works (weights set
the torque, the camera reads the angle).

Angles are in **radians** here (stiffness in N·m/rad); the callers convert to degrees
for tables and reports.

Notes
-----
**Bilinear stiffness switching** (main paper, seed 001, the case equation for
``k(τ, τ̇)``). The paper writes the switch with the sign of ``τ̇`` for the positive
half of the loop; its Table 1 gives a *low* stiffness for "negative loading"
(0 → −Tmax, where ``τ̇ < 0``), so loading and unloading are read as *magnitude*
increasing or decreasing:

- unloading, ``|τ|`` decreasing (``τ·τ̇ < 0``): ``k = k_u``;
- loading, ``|τ|`` increasing, ``|τ| < τ_c``: ``k = k_l``;
- loading, ``|τ| ≥ τ_c``: ``k = k_u``.

The model has no hidden state: the stiffness of an increment depends only on the
torque and the direction of that increment, so the angle of a torque sequence is
``θ_start + Σ Δθ`` with each ``Δθ = c_u·U + c_l·L`` (compliances ``c = 1/k``; ``L`` the
part of the increment that lies in the loading band ``0 < ±τ < τ_c``, ``U`` the rest).
A symmetric cycle +T → −T → +T therefore closes exactly, and several cycles form one
periodic loop. The closed loop has

- loop width at zero torque (the largest width, the paper's hysteresis):
  ``τ_c·(1/k_l − 1/k_u)`` (rad);
- loop area ``W = τ_c²·(1/k_l − 1/k_u)`` (J), for ``τ_c ≤ T``.

With the paper's Table 1 stiffnesses (k_u ≈ 4.4, k_l ≈ 0.3 N·m/rad) and τ_c = 0.15 N·m
these are ≈ 27° and ≈ 0.070 J, not the ≈ 50° and ≈ 0.018 J the paper quotes: the
paper's figures are not mutually consistent under its own model, which is why the
tests use the model's closed forms as truth, not the paper's numbers.

**Bouc–Wen, torque driven** (Bouc 1967; Wen 1976; see Ismail, Ikhouane & Rodellar,
Arch. Comput. Methods Eng. 16, 2009 for the standard form). The angle is
``θ = θ₀ + τ/k_e + z`` with the hysteretic angle ``z`` following
``ż = A·τ̇ − β·|τ̇|·|z|^(n−1)·z − γ·τ̇·|z|^n``. Rate independent, so it is integrated
in torque. Writing ``u = z/z_s`` with the saturation angle ``z_s = (A/(β+γ))^(1/n)``,
``a = A/z_s`` and ``ρ = β/(β+γ)``:

``du/dτ = a·(1 − |u|^n·(ρ·sgn(τ̇·u) + 1 − ρ))``.

With ``γ > β`` (``ρ < ½``) the compliance is small just after a reversal, large when
``z`` crosses zero and small again at saturation: the smooth version of the
stiff–soft–stiff switch of the bilinear model. Between reversals ``u`` is found
exactly (to table accuracy) by inverting the tabulated integral
``Ψ(u) = ∫₀ᵘ dv / (a·f(v))`` instead of stepping an ODE solver, which keeps a fit to
a loop at a few milliseconds per model call.

*Limitation, found on the paper's loops*: after a reversal the Bouc–Wen state
leaves saturation at a rate set by how deeply it saturated, i.e. by how far the torque
ran past the previous transition. It therefore cannot hold the stiff state over the
whole unloading branch and switch only *after* zero torque, as the paper's model
does, and on a sharp bilinear loop it leaves a residual of several degrees (its
``reduced_chi2`` says so). It is reported as the smooth-transition alternative, and
the comparison of the two residuals tells which description the data support; its
parameter uncertainties reflect measurement noise only, not this model error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from ..errors import AnalysisError
from ..numerics import numeric_jacobian
from ..validate import check_number
from .uncertainty import (
    least_squares_weights,
    linearised_covariance,
    parameter_stds,
    torque_source_jacobian,
)

__all__ = [
    "bilinear_response",
    "bilinear_loop_width",
    "bilinear_loop_energy",
    "BilinearFit",
    "fit_bilinear",
    "bilinear_increments",
    "bilinear_linear_solve",
    "bilinear_profile_sse",
    "bouc_wen_response",
    "BoucWenFit",
    "fit_bouc_wen",
]


def _as_torque(torque_nm) -> np.ndarray:
    tau = np.array(torque_nm, dtype=float, copy=True).reshape(-1)
    if tau.size == 0:
        raise AnalysisError("torque sequence is empty: at least one torque value is needed")
    if not np.all(np.isfinite(tau)):
        raise AnalysisError("torque sequence contains a non-finite value (NaN or inf)")
    return tau


def _check_stiffness(**values) -> None:
    for name, v in values.items():
        check_number(v, name=name, error=AnalysisError, low=0, low_open=True, unit="N·m/rad")


def _loading_part(a: np.ndarray, b: np.ndarray, tau_c: float) -> np.ndarray:
    """Signed part of each increment a→b that lies in the loading band (|τ|<τ_c, |τ| rising)."""
    up = np.clip(b, 0.0, tau_c) - np.clip(a, 0.0, tau_c)
    down = np.clip(b, -tau_c, 0.0) - np.clip(a, -tau_c, 0.0)
    return np.where(b > a, up, down)


def bilinear_increments(tau: np.ndarray, tau_c: float) -> tuple[np.ndarray, np.ndarray]:
    """Torque amounts taken at the unloading (U) and loading (L) compliance, per sample.

    Parameters
    ----------
    tau : numpy.ndarray, shape (n,)
        Torques in acquisition order (N·m).
    tau_c : float
        Critical torque of the bilinear model (N·m), >= 0.

    Returns
    -------
    (U, L) : two numpy.ndarray, shape (n,)
        Cumulative from the first sample (N·m, 0 there): the model's angle is
        ``theta = theta_start + c_u*U + c_l*L`` with the compliances ``c = 1/k`` (rad/(N·m)).
    """
    a, b = tau[:-1], tau[1:]
    lo = _loading_part(a, b, tau_c)
    un = (b - a) - lo
    zero = np.zeros(1)
    return np.concatenate([zero, np.cumsum(un)]), np.concatenate([zero, np.cumsum(lo)])


def _bilinear_centred_start(tau: np.ndarray, c_u: float, c_l: float, tau_c: float) -> float:
    """Angle of tau[0] on the centred periodic major loop, reached by loading."""
    amp = float(np.max(np.abs(tau)))
    t0 = float(tau[0])
    if t0 != 0.0:
        sign = math.copysign(1.0, t0)
    else:
        nonzero = tau[tau != 0.0]
        sign = math.copysign(1.0, nonzero[0]) if nonzero.size else 1.0
    theta_top = amp * c_u + (c_l - c_u) * min(amp, tau_c) / 2.0
    x = sign * t0  # torque seen from the loading side, >= 0 by construction
    theta_up = -theta_top + c_u * (x + amp) + (c_l - c_u) * min(max(x, 0.0), tau_c)
    return sign * theta_up


def bilinear_response(torque_nm, *, k_u, k_l, tau_c, theta_start="centred") -> np.ndarray:
    """Angles (rad) of the paper's bilinear stiffness-switching model for a torque sequence.

    Parameters
    ----------
    torque_nm : array_like, shape (n,)
        Applied torque at each sample, N·m, in the order it was applied. Between two
        samples the torque is taken to change monotonically (a weight step).
    k_u : float
        Unloading stiffness, N·m/rad (``|τ|`` decreasing, and loading at ``|τ| ≥ τ_c``).
    k_l : float
        Loading stiffness after a reversal, N·m/rad (``|τ|`` increasing, ``|τ| < τ_c``).
    tau_c : float
        Critical torque magnitude of the switch, N·m (``≥ 0``).
    theta_start : float or "centred", optional
        Angle of the first sample, rad. ``"centred"`` (default) puts the first sample
        on the periodic major loop of amplitude ``max|τ|`` centred on zero angle,
        as reached by loading towards the sign of the first torque (for a first torque
        of 0, towards the sign of the first non-zero torque). A session that starts
        at +Tmax after a positive loading, as in the paper, is then a closed loop
        from its first sample on, with ``θ(+Tmax) = −θ(−Tmax)``.

    Returns
    -------
    numpy.ndarray, shape (n,)
        Rotation angle, **radians**, positive with positive torque.

    Raises
    ------
    AnalysisError
        Empty or non-finite torque, non-positive stiffness, negative ``tau_c``, or a
        ``theta_start`` that is neither a finite number nor ``"centred"``.

    Notes
    -----
    ``dθ = dτ/k(τ, τ̇)`` with ``k = k_u`` when unloading, ``k_l`` when loading below
    ``τ_c`` and ``k_u`` when loading at or above it (paper, bilinear model). Each
    increment is split exactly at 0 and ``±τ_c``, so the result does not depend on
    how finely the torque is sampled.

    Examples
    --------
    >>> import numpy as np
    >>> tau = np.array([0.36, 0.0, -0.36, 0.0, 0.36])
    >>> th = bilinear_response(tau, k_u=4.4, k_l=0.3, tau_c=0.15)
    >>> bool(np.isclose(th[0], th[-1])), bool(np.isclose(th[0], -th[2]))
    (True, True)
    >>> float(np.degrees(th[1] - th[3]).round(2))  # loop width at zero torque: τ_c·(1/k_l − 1/k_u)
    26.69
    """
    tau = _as_torque(torque_nm)
    _check_stiffness(k_u=k_u, k_l=k_l)
    check_number(tau_c, name="tau_c", error=AnalysisError, low=0, unit="N·m")
    c_u, c_l = 1.0 / float(k_u), 1.0 / float(k_l)
    if isinstance(theta_start, str):
        if theta_start != "centred":
            raise AnalysisError(f"theta_start must be a number (rad) or 'centred', got {theta_start!r}")
        start = _bilinear_centred_start(tau, c_u, c_l, float(tau_c))
    else:
        start = check_number(theta_start, name="theta_start", error=AnalysisError, unit="rad")
    un, lo = bilinear_increments(tau, float(tau_c))
    return start + c_u * un + c_l * lo


def bilinear_loop_width(*, k_u, k_l, tau_c, max_torque_nm) -> float:
    """Width (rad) of the closed bilinear loop at zero torque, its largest width.

    ``min(τ_c, T)·(1/k_l − 1/k_u)`` for a symmetric cycle of amplitude ``T``.
    """
    _check_stiffness(k_u=k_u, k_l=k_l)
    return min(tau_c, max_torque_nm) * (1.0 / k_l - 1.0 / k_u)


def bilinear_loop_energy(*, k_u, k_l, tau_c, max_torque_nm) -> float:
    """Energy (J) dissipated per symmetric cycle by the bilinear model: ``min(τ_c,T)²·(1/k_l − 1/k_u)``."""
    _check_stiffness(k_u=k_u, k_l=k_l)
    t = min(tau_c, max_torque_nm)
    return t * t * (1.0 / k_l - 1.0 / k_u)


# ---------------------------------------------------------------------------------
# Shared fitting helpers
# ---------------------------------------------------------------------------------


def _reduced_chi2(resid: np.ndarray, angle_std: np.ndarray, n_params: int) -> float:
    """Σ(r/σ)²/(n − p); NaN without angle uncertainties or degrees of freedom."""
    dof = resid.size - n_params
    if dof <= 0 or not np.all(angle_std > 0):
        return float("nan")
    return float(np.sum((resid / angle_std) ** 2) / dof)


def _fit_inputs(torque_nm, angle_rad, angle_std_rad, torque_std_nm, torque_groups, torque_sources=None, *,
                model: str, min_samples: int):
    """Validated fit inputs: torque, angle, angle std and the torque-error loading matrix."""
    tau = _as_torque(torque_nm)
    if tau.size < min_samples:
        raise AnalysisError(f"{model} fit needs at least {min_samples} samples, got {tau.size}")
    if not (tau.max() > 0 and tau.min() < 0):
        raise AnalysisError(f"{model} fit needs torque of both signs (the torque never reverses)")
    th = np.array(angle_rad, dtype=float, copy=True).reshape(-1)
    if th.shape != tau.shape:
        raise AnalysisError(f"angle and torque sequences differ in length ({th.size} vs {tau.size})")
    if not np.all(np.isfinite(th)):
        raise AnalysisError("angle sequence contains a non-finite value (NaN or inf)")
    sa = (np.zeros_like(tau) if angle_std_rad is None
          else np.broadcast_to(np.asarray(angle_std_rad, float), tau.shape).copy())
    if torque_sources is not None:
        src = np.asarray(torque_sources, dtype=float)
        if src.ndim != 2 or src.shape[0] != tau.size or not np.all(np.isfinite(src)):
            raise AnalysisError(
                f"torque_sources must be a finite (n_samples, n_sources) array with n_samples = {tau.size}"
            )
        return tau, th, sa, src
    st = (
        np.zeros_like(tau)
        if torque_std_nm is None
        else np.broadcast_to(np.asarray(torque_std_nm, float), tau.shape).copy()
    )
    groups = np.arange(tau.size) if torque_groups is None else np.asarray(torque_groups, dtype=int).reshape(-1)
    if groups.shape != tau.shape:
        raise AnalysisError("torque_groups must give one group index per sample")
    # one standard deviation per group (the largest, if rows disagree), as a loading matrix
    n_groups = int(groups.max()) + 1
    group_std = np.zeros(n_groups)
    np.maximum.at(group_std, groups, st)
    src = np.zeros((tau.size, n_groups))
    src[np.arange(tau.size), groups] = group_std[groups]
    return tau, th, sa, src


def _torque_covariance(model, jac, w, sa, tau, sources):
    """First-order angle and torque covariance of a fit (module :mod:`.uncertainty`)."""
    jac_src = torque_source_jacobian(model, tau, sources)
    return linearised_covariance(jac, w, sa**2, jac_src, np.ones(jac_src.shape[1]))


# ---------------------------------------------------------------------------------
# Bilinear fit
# ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class BilinearFit:
    """Least-squares fit of :func:`bilinear_response` to one loop.

    Attributes
    ----------
    k_u_nm_per_rad, k_l_nm_per_rad, tau_c_nm, theta0_rad : float
        Fitted parameters (``theta0_rad``: angle of the first sample).
    std_angle, std_torque : dict
        1σ of each parameter from angle errors and from torque errors (first-order
        propagation through the fit), keyed ``"k_u"``, ``"k_l"``, ``"tau_c"``, ``"theta0"``.
    residual_rms_rad : float
        RMS of the angle residuals, rad.
    n_points : int
    """

    k_u_nm_per_rad: float
    k_l_nm_per_rad: float
    tau_c_nm: float
    theta0_rad: float
    std_angle: dict = field(default_factory=dict)
    std_torque: dict = field(default_factory=dict)
    residual_rms_rad: float = float("nan")
    n_points: int = 0
    reduced_chi2: float = float("nan")

    def std(self, name: str) -> float:
        """Combined 1σ of parameter ``name`` (angle and torque parts in quadrature)."""
        return float(np.hypot(self.std_angle[name], self.std_torque[name]))

    def predict(self, torque_nm) -> np.ndarray:
        """Model angles (rad) for a torque sequence that starts at this fit's first sample."""
        return bilinear_response(
            torque_nm,
            k_u=self.k_u_nm_per_rad,
            k_l=self.k_l_nm_per_rad,
            tau_c=self.tau_c_nm,
            theta_start=self.theta0_rad,
        )


def bilinear_linear_solve(un, lo, th, w):
    """The weighted least-squares fit ``th = theta0 + c_u*un + c_l*lo`` (``numpy.linalg.lstsq``).

    Parameters
    ----------
    un, lo : numpy.ndarray, shape (n,)
        The cumulative torque amounts of :func:`bilinear_increments` (N·m).
    th : numpy.ndarray, shape (n,)
        Angles (rad).
    w : numpy.ndarray, shape (n,)
        Weights (1/rad²).

    Returns
    -------
    (numpy.ndarray, float)
        ``(theta0, c_u, c_l)`` (rad, rad/(N·m), rad/(N·m)) and the weighted sum of squares.
    """
    x = np.column_stack([np.ones_like(un), un, lo])
    sw = np.sqrt(w)
    coef, *_ = np.linalg.lstsq(x * sw[:, None], th * sw, rcond=None)
    r = th - x @ coef
    return coef, float(np.sum(w * r * r))


def bilinear_profile_sse(tau, th, w, grid):
    """Weighted SSE of the linear fit at every switch torque of `grid` (N·m), in one pass.

    `tau` (N·m), `th` (rad) and `w` (1/rad²) as :func:`bilinear_linear_solve` takes them;
    returns an array of the grid's shape. The same profile as
    ``bilinear_linear_solve(*bilinear_increments(tau, tc), th, w)[1]``
    for each ``tc`` (agrees to ~1e-9 relative; ``tests/test_analysis_speed.py``), but the
    increments of all candidates are built as one array and the 3-parameter weighted
    normal equations solved as a stack: the grid was ~400 separate ``lstsq`` calls per
    loop. It only chooses the bracket the exact profile is then refined in.
    """
    tc = np.asarray(grid, float)[:, None]
    a, b = tau[None, :-1], tau[None, 1:]
    up = np.clip(b, 0.0, tc) - np.clip(a, 0.0, tc)
    down = np.clip(b, -tc, 0.0) - np.clip(a, -tc, 0.0)
    lo_inc = np.where(b > a, up, down)
    zero = np.zeros((tc.shape[0], 1))
    lo = np.concatenate([zero, np.cumsum(lo_inc, axis=1)], axis=1)
    un = np.concatenate([zero, np.cumsum((b - a) - lo_inc, axis=1)], axis=1)
    x = np.stack([np.ones_like(un), un, lo], axis=2)  # (grid, n, 3)
    xw = x * w[None, :, None]
    normal = np.einsum("gni,gnj->gij", xw, x)
    rhs = np.einsum("gni,n->gi", xw, th)
    coef = np.linalg.solve(normal, rhs[..., None])[..., 0]
    r = th[None, :] - np.einsum("gni,gi->gn", x, coef)
    return np.sum(w[None, :] * r * r, axis=1)


def fit_bilinear(
    torque_nm, angle_rad, *, angle_std_rad=None, torque_std_nm=None, torque_groups=None, torque_sources=None, n_grid=400
) -> BilinearFit:
    """Fit the bilinear stiffness-switching model to a torque–angle sequence.

    Parameters
    ----------
    torque_nm, angle_rad : array_like, shape (n,)
        Samples in acquisition order (N·m, rad). Should span both torque signs.
    angle_std_rad, torque_std_nm : array_like or float, optional
        1σ of each angle (rad, independent between samples) and torque (N·m).
    torque_groups : array_like of int, optional
        Samples sharing a group index share one torque error (the same weights on the
        pans); default: independent torque errors.
    torque_sources : array_like, shape (n, m), optional
        Loading matrix ``L`` of correlated torque errors, ``δτ = L·ξ`` with
        independent unit sources (N·m per source; e.g. the weight pieces, see
        :func:`.uncertainty.torque_sources`). Replaces ``torque_std_nm`` and
        ``torque_groups`` when given.
    n_grid : int, optional
        Number of τ_c candidates for the profile search before refinement.

    Returns
    -------
    BilinearFit

    Raises
    ------
    AnalysisError
        Fewer than 6 samples; torque that does not reach both signs; a switch torque
        at the edge of the sampled range (``τ_c`` not identified); a singular fit.

    Notes
    -----
    For fixed ``τ_c`` the model is linear in ``(θ₀, 1/k_u, 1/k_l)``, so ``τ_c`` is
    found by profiling the weighted sum of squares over a grid and refining with a
    bounded scalar minimisation; the linear parameters are then exact. Uncertainties
    are first-order (Jacobian) propagation of the angle and torque uncertainties
    through this weighted least-squares estimate: with ``G = (JᵀWJ)⁻¹JᵀW``,
    ``cov = G·diag(σθ²)·Gᵀ + (G·J_τ·L)(G·J_τ·L)ᵀ``, so correlated torque errors
    (``cov(δτ) = L·Lᵀ``) are propagated with all their correlations.
    """
    tau, th, sa, sources = _fit_inputs(torque_nm, angle_rad, angle_std_rad, torque_std_nm, torque_groups,
                                       torque_sources, model="bilinear", min_samples=6)
    w = least_squares_weights(sa)
    amp = float(np.max(np.abs(tau)))

    def profile(tc):
        un, lo = bilinear_increments(tau, tc)
        return bilinear_linear_solve(un, lo, th, w)

    grid = np.linspace(0.0, amp, n_grid + 1)[1:-1]
    try:
        sse = bilinear_profile_sse(tau, th, w, grid)
    except np.linalg.LinAlgError:  # a degenerate candidate: profile each one on its own
        sse = np.array([profile(tc)[1] for tc in grid])
    i = int(np.argmin(sse))
    lo_b, hi_b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
    res = optimize.minimize_scalar(
        lambda tc: profile(tc)[1], bounds=(lo_b, hi_b), method="bounded", options={"xatol": amp * 1e-9}
    )
    tc = float(res.x)
    levels = np.unique(np.abs(tau[tau != 0]))
    if tc <= levels.min() or tc >= amp - 1e-12 * amp:
        raise AnalysisError(
            f"bilinear fit: the switch torque τ_c = {tc:.4g} N·m is at the edge of the sampled "
            f"torque range (0, {amp:.4g}] N·m, so it is not identified by the data"
        )
    coef, _ = profile(tc)
    theta0, c_u, c_l = (float(v) for v in coef)
    if not (c_u > 0 and c_l > 0):
        raise AnalysisError(
            f"bilinear fit gives a non-positive compliance (1/k_u = {c_u:.4g}, 1/k_l = {c_l:.4g} rad/(N·m)): "
            "the data do not look like a stiffness-switching loop"
        )

    def model(p, t=tau):
        un, lo = bilinear_increments(t, p[3])
        return p[0] + p[1] * un + p[2] * lo

    p = np.array([theta0, c_u, c_l, tc])
    r = th - model(p)
    jac = numeric_jacobian(model, p, np.array([1e-6, c_u * 1e-6, c_l * 1e-6, amp * 1e-7]))
    try:
        cov_a, cov_t = _torque_covariance(lambda t: model(p, t), jac, w, sa, tau, sources)
    except np.linalg.LinAlgError:
        raise AnalysisError("bilinear fit: the parameters are not identified (singular normal matrix)") from None
    # compliance -> stiffness: k = 1/c, dk = dc/c²
    conv = np.diag([1.0, -1.0 / c_u**2, -1.0 / c_l**2, 1.0])
    cov_a, cov_t = conv @ cov_a @ conv.T, conv @ cov_t @ conv.T
    s_a, s_t = parameter_stds(["theta0", "k_u", "k_l", "tau_c"], cov_a, cov_t)
    return BilinearFit(
        k_u_nm_per_rad=1.0 / c_u,
        k_l_nm_per_rad=1.0 / c_l,
        tau_c_nm=tc,
        theta0_rad=theta0,
        std_angle=s_a,
        std_torque=s_t,
        residual_rms_rad=float(np.sqrt(np.mean(r * r))),
        n_points=int(tau.size),
        reduced_chi2=_reduced_chi2(r, sa, 4),
    )


# ---------------------------------------------------------------------------------
# Bouc–Wen (torque driven)
# ---------------------------------------------------------------------------------

_T_GRID = np.linspace(0.0, 32.0, 1601)  # u = ±(1 − e^{−t}): clusters the table near saturation


def _psi_table(a: float, rho: float, n: float):
    """Tabulate Ψ(u) = ∫₀ᵘ dv/(a f(v)) for upward motion (f = 1−|v|^n·(ρ·sgn v + 1 − ρ))."""
    e = np.exp(-_T_GRID)
    v = 1.0 - e  # |u|
    vn = v**n
    f_pos = 1.0 - vn  # u > 0, moving up: towards saturation
    f_neg = 1.0 - vn * (1.0 - 2.0 * rho)  # u < 0, moving up: away from saturation
    # dv = e dt; at large t the ratio e/f_pos tends to 1/n (f_pos ≈ n(1−v) = n e)
    with np.errstate(divide="ignore", invalid="ignore"):
        g_pos = np.where(f_pos > 1e-300, e / f_pos, 1.0 / n)
    g_pos[0] = 1.0
    g_neg = e / f_neg
    dt = np.diff(_T_GRID)
    psi_pos = np.concatenate([[0.0], np.cumsum(0.5 * (g_pos[1:] + g_pos[:-1]) * dt)]) / a
    psi_neg = np.concatenate([[0.0], np.cumsum(0.5 * (g_neg[1:] + g_neg[:-1]) * dt)]) / a
    u_tab = np.concatenate([-v[::-1], v[1:]])
    psi_tab = np.concatenate([-psi_neg[::-1], psi_pos[1:]])
    return u_tab, psi_tab


def _bw_hysteretic(tau: np.ndarray, u0: float, a: float, rho: float, n: float) -> np.ndarray:
    """Normalised hysteretic state u at each sample, starting from u0 at tau[0]."""
    u_tab, psi_tab = _psi_table(a, rho, n)
    u = np.empty_like(tau)
    u[0] = u0
    d = np.sign(np.diff(tau))
    # runs of constant direction (zero steps join the current run)
    start = 0
    cur = float(u0)
    i = 1
    while i < tau.size:
        direction = d[i - 1]
        j = i
        while j < tau.size and (d[j - 1] == direction or d[j - 1] == 0):
            j += 1
        seg = tau[start:j]
        if direction == 0:
            u[i:j] = cur
        else:
            s = 1.0 if direction > 0 else -1.0
            # moving down is moving up in the mirrored variable −u
            p0 = np.interp(s * cur, u_tab, psi_tab)
            uu = s * np.interp(p0 + s * (seg[1:] - seg[0]), psi_tab, u_tab)
            u[i:j] = uu
            cur = float(uu[-1])
        start = j - 1
        i = j
    return u


def bouc_wen_response(torque_nm, *, k_e, z_s, a, rho, n, theta0=0.0, u0="periodic") -> np.ndarray:
    """Angles (rad) of the torque-driven Bouc–Wen model ``θ = θ₀ + τ/k_e + z``.

    Parameters
    ----------
    torque_nm : array_like, shape (n_samples,)
        Torque sequence, N·m.
    k_e : float
        Elastic (stiff) stiffness, N·m/rad.
    z_s : float
        Saturation of the hysteretic angle, rad.
    a : float
        ``A/z_s``: sharpness of the transition, 1/(N·m); the peak hysteretic
        compliance is ``a·z_s`` rad/(N·m).
    rho : float
        ``β/(β+γ)`` in (0, ½]: compliance just after a reversal relative to the peak
        is ``2ρ``. Small ρ gives the stiff–soft–stiff shape of the paper's loops.
    n : float
        Bouc–Wen exponent (> 0); larger is a sharper transition.
    theta0 : float, optional
        Angle offset, rad.
    u0 : float or "periodic", optional
        Initial ``z/z_s`` in (−1, 1). ``"periodic"`` (default) runs the sequence once
        from saturation towards the first sample's side and starts from where it
        ends, so a closed cycle is the periodic steady state.

    Returns
    -------
    numpy.ndarray
        Angles, rad.

    Examples
    --------
    >>> import numpy as np
    >>> tau = np.concatenate([np.linspace(0.36, -0.36, 37), np.linspace(-0.36, 0.36, 37)])
    >>> th = bouc_wen_response(tau, k_e=4.4, z_s=0.25, a=13.0, rho=0.01, n=3.0)
    >>> bool(abs(th[0] - th[-1]) < 1e-6)  # a periodic cycle closes
    True
    """
    tau = _as_torque(torque_nm)
    _check_stiffness(k_e=k_e, z_s=z_s, a=a, n=n)
    if not (0.0 < rho <= 0.5):
        raise AnalysisError(f"rho must lie in (0, 0.5], got {rho!r}")
    if isinstance(u0, str):
        if u0 != "periodic":
            raise AnalysisError(f"u0 must be a number in (-1, 1) or 'periodic', got {u0!r}")
        side = 1.0 if (tau[0] > 0 or (tau[0] == 0 and np.all(tau <= 0))) else -1.0
        start = side * (1.0 - 1e-9)
        u0v = float(_bw_hysteretic(np.append(tau, tau[0]), start, a, rho, n)[-1])
    else:
        u0v = float(u0)
        if not -1.0 < u0v < 1.0:
            raise AnalysisError(f"u0 must lie in (-1, 1), got {u0!r}")
    u = _bw_hysteretic(tau, u0v, a, rho, n)
    return theta0 + tau / k_e + z_s * u


@dataclass(frozen=True)
class BoucWenFit:
    """Least-squares fit of :func:`bouc_wen_response` to one loop.

    ``params`` holds ``k_e`` (N·m/rad), ``z_s`` (rad), ``a`` (1/(N·m)), ``rho``, ``n``,
    ``theta0`` (rad); ``std_angle``/``std_torque`` their 1σ from angle and torque
    errors (first order). ``residual_rms_rad`` is the angle residual RMS.
    """

    params: dict
    std_angle: dict
    std_torque: dict
    residual_rms_rad: float
    n_points: int
    reduced_chi2: float = float("nan")

    def std(self, name: str) -> float:
        """Combined 1σ of parameter ``name``."""
        return float(np.hypot(self.std_angle[name], self.std_torque[name]))

    def predict(self, torque_nm) -> np.ndarray:
        """Model angles (rad) for a torque sequence (periodic start)."""
        p = self.params
        return bouc_wen_response(
            torque_nm, k_e=p["k_e"], z_s=p["z_s"], a=p["a"], rho=p["rho"], n=p["n"], theta0=p["theta0"]
        )


_BW_NAMES = ["theta0", "k_e", "z_s", "a", "rho", "n"]


def _bw_starts(tau, th, sa, amp):
    """Starting points mapped from a bilinear fit (or a generic guess if that fails).

    The hysteretic angle crosses zero about ``T + τ_c/2`` of torque after a reversal;
    for exponent ``n`` that needs ``ln(1/(2ρ)) ≈ n·(a·(T + τ_c/2) − 1)`` (the integral
    ``∫₀¹ dv/(1 − (1−2ρ)vⁿ) ≈ 1 + ln(1/(2ρ))/n``).
    """
    try:
        bil = fit_bilinear(tau, th, angle_std_rad=sa, n_grid=100)
        k_e, tc = bil.k_u_nm_per_rad, bil.tau_c_nm
        z_s = 0.5 * bilinear_loop_width(k_u=k_e, k_l=bil.k_l_nm_per_rad, tau_c=tc, max_torque_nm=amp)
        theta0 = float(np.mean(th))
        if not z_s > 0:
            raise AnalysisError("bilinear start has no hysteresis")
    except AnalysisError:
        k_e, tc = 4.0 * amp / max(float(np.ptp(th)), 1e-12), amp / 2.0
        z_s, theta0 = float(np.ptp(th)) / 4.0, float(np.mean(th))
    a = 2.0 / tc
    starts = []
    for n0 in (2.0, 4.0, 8.0):
        rho0 = min(max(0.5 * math.exp(-n0 * (a * (amp + tc / 2.0) - 1.0)), 1e-12), 0.4)
        starts.append([theta0, math.log(k_e), math.log(z_s), math.log(a), math.log(rho0), math.log(n0)])
    return starts


def _bw_unpack(q):
    # fit variables: theta0, log k_e, log z_s, log a, log rho, log n  (positivity by construction)
    return q[0], math.exp(q[1]), math.exp(q[2]), math.exp(q[3]), min(math.exp(q[4]), 0.5), math.exp(q[5])


def fit_bouc_wen(
    torque_nm,
    angle_rad,
    *,
    angle_std_rad=None,
    torque_std_nm=None,
    torque_groups=None,
    torque_sources=None,
    initial=None,
) -> BoucWenFit:
    """Fit the torque-driven Bouc–Wen model to a loop (periodic start).

    Parameters
    ----------
    torque_nm, angle_rad : array_like
        Samples in acquisition order (N·m, rad).
    angle_std_rad, torque_std_nm, torque_groups, torque_sources : optional
        As in :func:`fit_bilinear`.
    initial : dict, optional
        Starting values ``k_e``, ``z_s``, ``a``, ``rho``, ``n``, ``theta0``. By default
        derived from the data: ``k_e`` from the stiffest phase, ``z_s`` half the loop
        width, a transition over about a third of the torque amplitude.

    Returns
    -------
    BoucWenFit

    Raises
    ------
    AnalysisError
        Fewer than 8 samples, no torque reversal, or a fit that does not converge or
        leaves a parameter unidentified.

    Notes
    -----
    Trust-region least squares (``scipy.optimize.least_squares``) on log-transformed
    positive parameters, started from a small set of sharpness/exponent guesses; the
    best is kept. Uncertainties: first-order propagation as in :func:`fit_bilinear`.
    """
    tau, th, sa, sources = _fit_inputs(torque_nm, angle_rad, angle_std_rad, torque_std_nm, torque_groups,
                                       torque_sources, model="Bouc–Wen", min_samples=8)
    w = least_squares_weights(sa)
    sw = np.sqrt(w)
    amp = float(np.max(np.abs(tau)))

    def model(q, t=tau):
        theta0, k_e, z_s, a, rho, n = _bw_unpack(q)
        return bouc_wen_response(t, k_e=k_e, z_s=z_s, a=a, rho=rho, n=n, theta0=theta0)

    def resid(q):
        return (th - model(q)) * sw

    if initial is None:
        starts = _bw_starts(tau, th, sa, amp)
    else:
        starts = [
            [
                initial["theta0"],
                math.log(initial["k_e"]),
                math.log(initial["z_s"]),
                math.log(initial["a"]),
                math.log(initial["rho"]),
                math.log(initial["n"]),
            ]
        ]
    lower = np.array([-np.inf, -np.inf, -np.inf, -np.inf, math.log(1e-12), math.log(0.3)])
    upper = np.array([np.inf, np.inf, np.inf, np.inf, math.log(0.5), math.log(40.0)])
    best = None
    for q0 in starts:
        q0 = np.clip(np.asarray(q0, float), lower + 1e-9, upper - 1e-9)
        try:
            res = optimize.least_squares(resid, q0, bounds=(lower, upper), x_scale="jac", max_nfev=400)
        except (ValueError, FloatingPointError):
            continue
        if np.all(np.isfinite(res.fun)) and (best is None or res.cost < best.cost):
            best = res
    if best is None:
        raise AnalysisError("Bouc–Wen fit did not converge from any starting point")
    q = best.x
    r = th - model(q)
    steps = np.array([1e-7, 1e-6, 1e-6, 1e-6, 1e-5, 1e-5])
    jac_q = numeric_jacobian(model, q, steps)
    try:
        cov_a, cov_t = _torque_covariance(lambda t: model(q, t), jac_q, w, sa, tau, sources)
    except np.linalg.LinAlgError:
        raise AnalysisError("Bouc–Wen fit: the parameters are not identified (singular normal matrix)") from None
    vals = _bw_unpack(q)
    conv = np.diag([1.0] + list(vals[1:]))  # d exp(x) = exp(x) dx
    s_a, s_t = parameter_stds(_BW_NAMES, conv @ cov_a @ conv, conv @ cov_t @ conv)
    return BoucWenFit(
        params=dict(zip(_BW_NAMES, (float(v) for v in vals))),
        std_angle=s_a,
        std_torque=s_t,
        residual_rms_rad=float(np.sqrt(np.mean(r * r))),
        n_points=int(tau.size),
        reduced_chi2=_reduced_chi2(r, sa, len(_BW_NAMES)),
    )
