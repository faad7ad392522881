"""Figures of one torque–angle loop: stiffness per phase, hysteresis, lost motion,
three-segment and secant stiffness, loop energy and loss factor.

The model-free figures work on *runs* (see :mod:`.loops`): the descending run
(+Tmax → −Tmax) and the ascending run (−Tmax → +Tmax), each given sorted by
increasing torque. They accept 2-D arrays ``(draws, points)`` so that the Monte Carlo
of :mod:`.uncertainty` evaluates all draws at once; 1-D input gives scalars.
Angles are in radians, torques in N·m.

Definitions (formulas)
----------------------
- **Loop width** ``w(τ) = θ_desc(τ) − θ_asc(τ)``, both runs linearly interpolated
  on a common torque grid (the union of their torque levels inside the range both
  cover; the maximum of a difference of two polylines lies on such a level).
  **Hysteresis** (paper): ``max_τ |w(τ)|``. **Hysteresis loss** (catalogue, loop
  width at zero torque): ``w(0)`` = angle left after returning to zero from +Tmax
  minus that after returning from −Tmax.
- **Lost motion** at ``±x·Tmax`` (catalogue / GB/T 35089 style, mid-point formula):
  ``LM = m(+x·Tmax) − m(−x·Tmax)`` with the loop mid-point
  ``m(τ) = (θ_desc(τ) + θ_asc(τ))/2``; x = 3 % and 4 %.
- **Secant stiffness** over ``[τ_a, τ_b]`` (0 ≤ τ_a < τ_b ≤ Tmax) on the *loading*
  branches (ascending run for τ > 0, descending run for τ < 0):
  ``k_sec = (τ_b − τ_a) / mean(θ_asc(τ_b) − θ_asc(τ_a), θ_desc(−τ_a) − θ_desc(−τ_b))``.
- **Loop energy** (paper): ``W = ∮ τ dθ`` of the continuous loop, J (positive for a
  dissipating loop). :func:`loop_energy` is the closed polygon descending run →
  ascending run → back to the start (trapezoids); its chords cut the loop's curvature,
  so :mod:`.session_analysis` takes off the area they add on each branch (:func:`chord_area`,
  with the bound of that estimate in the budget). Lost motion between levels is
  corrected likewise for the interpolation (:func:`chord_error`).
- **Loss factor** ``η = W / (2π·U)`` with ``U = ½·τ_a·θ_a`` the peak elastic energy
  of the equivalent linear spring through the loop tips
  (``τ_a``, ``θ_a`` = half the torque and angle ranges between the tips).
- **Phase stiffness**: least-squares slope of angle on torque within a phase with
  effective-variance weights ``1/(σθ² + b²στ²)`` (Orear 1982), ``k = 1/b``; standard
  uncertainty by first-order propagation (:func:`.uncertainty.linearised_covariance`).
- **Three-segment stiffness** (catalogue K1, K2, K3 with break torques T1, T2): a
  continuous piecewise-linear fit of the loading branches ``θ = θ₀± ± h(|τ|)`` with
  ``h`` of slopes 1/K1, 1/K2, 1/K3 and breaks T1 < T2, both branches sharing K and T.
"""

from __future__ import annotations

import numpy as np

from ..errors import AnalysisError
from ..numerics import fit_breakpoints, numeric_jacobian
from .uncertainty import (
    least_squares_weights,
    linearised_covariance,
    parameter_stds,
    torque_jacobian,
    torque_source_jacobian,
)

__all__ = [
    "interp_rows",
    "loop_width",
    "lost_motion",
    "secant_stiffness",
    "phase_secants",
    "loop_energy",
    "loss_factor",
    "slope_changes",
    "chord_area",
    "chord_error",
    "phase_stiffness",
    "fit_three_segment",
]


def _rows(*arrays):
    return tuple(np.atleast_2d(np.asarray(a, dtype=float)) for a in arrays)


def _out(v, one_d):
    return float(v[0]) if one_d else v


def interp_rows(xq, x, y, *, tol=0.0):
    """Row-wise linear interpolation; NaN outside ``[x_min − tol, x_max + tol]``.

    Parameters
    ----------
    xq : ndarray (D, q) or (q,)
        Query points per row (or shared).
    x, y : ndarray (D, m)
        Abscissae sorted increasing along each row (m ≥ 2), and ordinates.
    tol : float
        How far beyond the data a query may lie (linear extrapolation there).

    Examples
    --------
    >>> import numpy as np
    >>> interp_rows(np.array([[0.5, 3.0]]), np.array([[0.0, 1.0, 2.0]]), np.array([[0.0, 2.0, 4.0]])).tolist()
    [[1.0, nan]]
    """
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    xq = np.broadcast_to(np.asarray(xq, float), (x.shape[0],) + np.shape(xq)[-1:])
    xf, yf = x.reshape(-1), y.reshape(-1)
    starts = (np.arange(x.shape[0]) * x.shape[1])[:, None]
    idx = _count_at_most(xf, starts, x.shape[1], xq) - 1
    # flat indices into the rows (one gather each; the Monte Carlo calls this ~150 times per session)
    flat = np.clip(idx, 0, x.shape[1] - 2) + starts
    x0, x1, y0, y1 = xf[flat], xf[flat + 1], yf[flat], yf[flat + 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (xq - x0) / (x1 - x0)
    out = y0 + t * (y1 - y0)
    outside = (xq < x[:, :1] - tol) | (xq > x[:, -1:] + tol)
    return np.where(outside, np.nan, out)


def _count_at_most(xf, starts, m, xq):
    """How many of each row's `m` sorted values are <= each query: ``searchsorted(row, xq, "right")``
    of every row at once, by bisection (``log2 m`` gathers of the query's shape).

    ``xf`` holds the rows one after another (row ``d`` at ``starts[d]``); NaN, sorted last,
    counts as larger than any query, as in ``np.sum(row <= q)``. The comparison cube that
    sum needs, (rows, queries, m), was ~5 % of ``vision-torsion analyze``'s instructions.
    """
    count = np.zeros(xq.shape, dtype=np.intp)
    step = 1 << max(m.bit_length() - 1, 0)
    while step:
        # may `step` more values be counted? (the last of them is <= the query)
        more = count + step
        fits = more <= m
        fits &= xf[starts + np.minimum(more, m) - 1] <= xq
        count = np.where(fits, more, count)
        step >>= 1
    return count


def _sorted(tau, th):
    tau, th = np.broadcast_arrays(tau, th)
    flat = np.argsort(tau, axis=1, kind="stable") + (np.arange(tau.shape[0]) * tau.shape[1])[:, None]
    return tau.reshape(-1)[flat], th.reshape(-1)[flat]


def loop_width(tau_desc, th_desc, tau_asc, th_asc, *, tol=0.0):
    """Largest loop width and width at zero torque, rad: ``(hysteresis, hysteresis_loss)``.

    Runs need not be sorted. See the module notes for the definitions.
    """
    one_d = np.ndim(tau_desc) == 1
    td, yd, ta, ya = _rows(tau_desc, th_desc, tau_asc, th_asc)
    td, yd = _sorted(td, yd)
    ta, ya = _sorted(ta, ya)
    lo = np.maximum(td[:, :1], ta[:, :1])
    hi = np.minimum(td[:, -1:], ta[:, -1:])
    grid = np.clip(np.concatenate([td, ta], axis=1), lo, hi)
    w = interp_rows(grid, td, yd, tol=tol) - interp_rows(grid, ta, ya, tol=tol)
    with np.errstate(invalid="ignore"):
        absw = np.abs(w)
        hyst = np.where(np.all(np.isnan(w), axis=1), np.nan, np.nanmax(np.where(np.isnan(absw), -np.inf, absw), axis=1))
    zero = np.zeros((td.shape[0], 1))
    w0 = (interp_rows(zero, td, yd, tol=tol) - interp_rows(zero, ta, ya, tol=tol))[:, 0]
    return _out(hyst, one_d), _out(w0, one_d)


def lost_motion(tau_desc, th_desc, tau_asc, th_asc, *, torque_nm, tol=0.0):
    """Lost motion, rad: mid-point of the loop at +torque_nm minus that at −torque_nm."""
    one_d = np.ndim(tau_desc) == 1
    td, yd, ta, ya = _rows(tau_desc, th_desc, tau_asc, th_asc)
    td, yd = _sorted(td, yd)
    ta, ya = _sorted(ta, ya)
    q = np.array([[torque_nm, -torque_nm]])
    mid = 0.5 * (interp_rows(q, td, yd, tol=tol) + interp_rows(q, ta, ya, tol=tol))
    return _out(mid[:, 0] - mid[:, 1], one_d)


def secant_stiffness(tau_desc, th_desc, tau_asc, th_asc, *, lower_nm, upper_nm, tol=0.0):
    """Secant stiffness of the loading branches between ``lower_nm`` and ``upper_nm``, N·m/rad."""
    if not 0 <= lower_nm < upper_nm:
        raise AnalysisError(f"secant interval must satisfy 0 <= lower < upper, got [{lower_nm}, {upper_nm}] N·m")
    one_d = np.ndim(tau_desc) == 1
    td, yd, ta, ya = _rows(tau_desc, th_desc, tau_asc, th_asc)
    td, yd = _sorted(td, yd)
    ta, ya = _sorted(ta, ya)
    pos = interp_rows(np.array([[lower_nm, upper_nm]]), ta, ya, tol=tol)
    neg = interp_rows(np.array([[-lower_nm, -upper_nm]]), td, yd, tol=tol)
    dtheta = 0.5 * ((pos[:, 1] - pos[:, 0]) + (neg[:, 0] - neg[:, 1]))
    with np.errstate(divide="ignore", invalid="ignore"):
        k = (upper_nm - lower_nm) / dtheta
    return _out(np.where(dtheta > 0, k, np.nan), one_d)


def phase_secants(tau_desc, th_desc, tau_asc, th_asc, *, top_nm, bottom_nm, tol=0.0):
    """The secant of each of the four phases, N·m/rad, from the runs: ``{k_<phase>_secant: value}``.

    Over each phase's ends (+Tmax → 0, 0 → −Tmax, −Tmax → 0, 0 → +Tmax): the phase
    secant of :mod:`.session_analysis`, evaluated on the runs so that a Monte Carlo of the
    loop carries the torque errors of the ends with their correlations and the loop's
    amplitude. The bottom tip is the descending run's last image, which also starts
    the ascending branch; ``top_nm``/``bottom_nm`` are the nominal tips.
    """
    td, yd, ta, ya = _rows(tau_desc, th_desc, tau_asc, th_asc)
    td, yd = _sorted(td, yd)
    ta, ya = _sorted(ta, ya)
    hi, lo = float(top_nm), float(bottom_nm)
    d = interp_rows(np.array([[lo, 0.0, hi]]), td, yd, tol=tol)
    a = interp_rows(np.array([[0.0, hi]]), ta, ya, tol=tol)
    with np.errstate(divide="ignore", invalid="ignore"):
        return {
            "k_positive_unloading_secant": hi / (d[:, 2] - d[:, 1]),
            "k_negative_loading_secant": -lo / (d[:, 1] - d[:, 0]),
            "k_negative_unloading_secant": -lo / (a[:, 0] - d[:, 0]),
            "k_positive_loading_secant": hi / (a[:, 1] - a[:, 0]),
        }


def loop_energy(torque_nm, angle_rad):
    """Energy ``∮ τ dθ`` (J) of the closed polygon through the samples in order.

    Examples
    --------
    >>> loop_energy([1.0, -1.0, -1.0, 1.0], [1.0, 1.0, -1.0, -1.0])  # 2 rad × 2 N·m square
    4.0
    """
    one_d = np.ndim(torque_nm) == 1
    tau, th = _rows(torque_nm, angle_rad)
    tau_c = np.concatenate([tau, tau[:, :1]], axis=1)
    th_c = np.concatenate([th, th[:, :1]], axis=1)
    w = np.sum(0.5 * (tau_c[:, 1:] + tau_c[:, :-1]) * np.diff(th_c, axis=1), axis=1)
    # no sign is imposed: in the order descending run → ascending run a dissipating
    # loop is positive, and a negative value would be worth seeing
    return _out(w, one_d)


def slope_changes(x, y, *, pivot=0.0):
    """Slope change at each end of every segment of a branch: ``(h, a, b)``, each ``(D, m − 1)``.

    ``x`` (D, m) increasing along each row, ``y`` the branch's values. For segment
    ``j`` (from ``x_j`` to ``x_{j+1}``, width ``h_j``, secant slope ``s_j``):
    ``a_j = s_j − s_{j−1}`` (the change at its left end) and ``b_j = s_{j+1} − s_j``
    (at its right end), NaN where that neighbour segment does not exist, and at a
    sample within 1e-9 of ``pivot`` (N·m; zero torque, where a run turns from unloading
    to loading: the change there is not a curvature of either side; None for none).
    """
    x, y = _rows(x, y)
    h = np.diff(x, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.diff(y, axis=1) / h
    nan = np.full((x.shape[0], 1), np.nan)
    ds = np.diff(s, axis=1)
    if pivot is not None:
        ds = np.where(np.abs(x[:, 1:-1] - pivot) <= 1e-9, np.nan, ds)
    return h, np.concatenate([nan, ds], axis=1), np.concatenate([ds, nan], axis=1)


def chord_area(x, y, *, pivot=0.0):
    """What the chords through a branch's samples add to its area, and how well that is known.

    Parameters
    ----------
    x, y : ndarray (D, m) or (m,)
        The branch, ``x`` increasing (N·m, rad).

    Returns
    -------
    (mid, systematic, random) : ndarray (D,) or float
        ``∫(chord − f) dx`` estimated as ``mid``, within ``±systematic`` (half-widths
        of the segments whose curvature has one sign, added linearly) and
        ``±random`` (those where it does not, in quadrature). NaN for fewer than
        three samples.

    Notes
    -----
    Between samples ``j`` and ``j+1`` a curve whose slope changes monotonically over
    the segment and its neighbours (convex or concave there) lies between the chord
    and the neighbouring secants extended: with ``a``, ``b`` of
    :func:`slope_changes` of one sign, ``0 ≤ ∫(chord − f) ≤ A = h²·a·b / (2(a + b))``
    (the triangle between the chord and the two extended secants; exact for a single
    kink inside the segment). The estimate is ``A/2 ± A/2``. A segment with one
    neighbour (a branch's end) has ``A = c·h²/2`` from its one slope change ``c``.
    Where ``a`` and ``b`` disagree in sign (the curvature is below the noise, or a
    kink sits on a measured level) the segment adds ``0 ± h²·min(|a|, |b|)/8`` (a
    kink of the smaller change in its middle). A smooth branch gets ``A ≈ 3×`` its
    true ``h³f''/12``, so the half-width covers it. A segment ending at ``pivot``
    (zero torque) is bounded from its other neighbour only (:func:`slope_changes`).
    """
    one_d = np.ndim(x) == 1
    h, a, b = slope_changes(x, y, pivot=pivot)
    with np.errstate(divide="ignore", invalid="ignore"):
        both = np.isfinite(a) & np.isfinite(b)
        same = both & (a * b > 0)
        tri = np.where(same, h * h * a * b / (2.0 * (a + b)), 0.0)
        end = np.where(np.isfinite(a), a, b)
        tri = np.where(~both, 0.5 * end * h * h, tri)  # NaN for a segment with no neighbour: not bounded
        mixed = both & ~same
        rand = np.where(mixed, h * h * np.minimum(np.abs(a), np.abs(b)) / 8.0, 0.0)
    mid = np.sum(tri / 2.0, axis=1)
    sys_ = np.sum(np.abs(tri) / 2.0, axis=1)
    rnd = np.sqrt(np.sum(rand * rand, axis=1))
    return _out(mid, one_d), _out(sys_, one_d), _out(rnd, one_d)


def chord_error(x, y, xq, *, pivot=0.0):
    """Linear interpolation of a branch at ``xq`` minus the branch, and how well that is known.

    Returns ``(mid, half)`` (rad, ``(D,)`` or float): the interpolated value exceeds the
    curve by ``mid ± half``, from the same bounds as :func:`chord_area` at the point:
    with one curvature sign, ``0 ≤ chord − f ≤ D = min(a·t, b·(h − t))`` (``t`` from
    the segment's left end), so ``D/2 ± D/2``; with ``a``, ``b`` of opposite sign
    ``0 ± min(|a|·t, |b|·(h − t))``; in an end segment ``c·(distance to the far end)``
    from its one neighbour (also a segment ending at ``pivot``, zero torque:
    :func:`slope_changes`); zero on a measured level. NaN when ``xq`` is outside the
    branch, the branch has fewer than three samples, or the segment has no neighbour
    to bound it.
    """
    one_d = np.ndim(x) == 1
    x, y = _rows(x, y)
    h, a, b = slope_changes(x, y, pivot=pivot)
    xq = float(xq)
    j = np.clip(np.sum(x <= xq, axis=1) - 1, 0, max(h.shape[1] - 1, 0))
    rows = np.arange(x.shape[0])
    if h.shape[1] < 2:
        nan = np.full(x.shape[0], np.nan)
        return _out(nan, one_d), _out(nan, one_d)
    hj, aj, bj = h[rows, j], a[rows, j], b[rows, j]
    t = xq - x[rows, j]
    with np.errstate(invalid="ignore"):
        both = np.isfinite(aj) & np.isfinite(bj)
        same = both & (aj * bj > 0)
        d_both = np.minimum(np.abs(aj) * t, np.abs(bj) * (hj - t))
        d_left_only = np.abs(aj) * t  # the last segment: its left neighbour bounds it
        d_right_only = np.abs(bj) * (hj - t)
        d = np.where(both, d_both, np.where(np.isfinite(aj), d_left_only, d_right_only))
        sgn = np.sign(np.where(np.isfinite(aj), aj, bj))
        mid = np.where(same | ~both, sgn * d / 2.0, 0.0)
        half = np.where(same | ~both, d / 2.0, d)
        outside = (xq < x[:, 0]) | (xq > x[:, -1])
    return _out(np.where(outside, np.nan, mid), one_d), _out(np.where(outside, np.nan, half), one_d)


def loss_factor(energy_j, torque_top_nm, angle_top_rad, torque_bottom_nm, angle_bottom_rad):
    """Loss factor ``η = W/(2π·U)``, ``U = ½·τ_a·θ_a`` from the loop tips (see module notes)."""
    tau_a = 0.5 * (np.asarray(torque_top_nm) - np.asarray(torque_bottom_nm))
    th_a = 0.5 * (np.asarray(angle_top_rad) - np.asarray(angle_bottom_rad))
    u = 0.5 * tau_a * th_a
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(u > 0, np.asarray(energy_j) / (2 * np.pi * u), np.nan)


def phase_stiffness(torque_nm, angle_rad, *, angle_std_rad, torque_std_nm, torque_sources=None, min_points=3):
    """Least-squares stiffness dτ/dθ of one phase, N·m/rad, with its uncertainty.

    Parameters
    ----------
    torque_nm, angle_rad : array_like (n,)
        Samples of the phase (N·m, rad).
    angle_std_rad, torque_std_nm : array_like (n,)
        1σ per sample; without ``torque_sources`` torque errors are taken independent
        inside one phase (each torque level occurs once in a phase).
    torque_sources : array_like (n, m), optional
        Loading matrix ``L`` of correlated torque errors (``δτ = L·ξ``, N·m per unit
        source, :func:`.uncertainty.torque_sources`); used for the torque part.
    min_points : int
        Fewest samples accepted (3: two for a line, one to check it).

    Returns
    -------
    dict
        ``value`` (N·m/rad), ``std_angle``, ``std_torque`` (1σ, N·m/rad),
        ``residual_rms_rad``, ``n_points``, ``residual_rad`` (per sample) and
        ``compliance_rad_per_nm`` (the fitted slope, for the lack-of-fit gate).

    Raises
    ------
    AnalysisError
        Fewer than ``min_points`` samples, no torque change, or no angle change.
    """
    tau = np.asarray(torque_nm, float)
    th = np.asarray(angle_rad, float)
    sa = np.asarray(angle_std_rad, float)
    st = np.asarray(torque_std_nm, float)
    if tau.size < min_points:
        raise AnalysisError(f"phase has {tau.size} usable point(s); a stiffness needs at least {min_points}")
    if np.ptp(tau) <= 0:
        raise AnalysisError("torque does not change within the phase; no stiffness can be computed")
    x = np.column_stack([np.ones_like(tau), tau])
    b = np.polyfit(tau, th, 1)[0]
    for _ in range(3):  # effective-variance iteration: weights depend on the slope
        var = sa**2 + (b * st) ** 2
        w = least_squares_weights(np.sqrt(var))
        sw = np.sqrt(w)
        coef = np.linalg.lstsq(x * sw[:, None], th * sw, rcond=None)[0]
        b = coef[1]
    if not b > 0:
        raise AnalysisError(f"angle does not increase with torque within the phase (slope {b:.3g} rad/(N·m))")
    resid = th - x @ coef
    # torque errors enter as −b·δτ in the residual: Jacobian d(model)/d(τ_i) = b, so
    # with δτ = L·ξ the Jacobian per unit source is b·L (cov_t = G·b²·L·Lᵀ·Gᵀ)
    if torque_sources is None:
        cov_a, cov_t = linearised_covariance(x, w, sa**2, np.diag(np.full(tau.size, b)), st**2)
    else:
        src = np.asarray(torque_sources, float).reshape(tau.size, -1)
        cov_a, cov_t = linearised_covariance(x, w, sa**2, b * src, np.ones(src.shape[1]))
    k = 1.0 / b
    return {
        "value": k,
        "std_angle": float(np.sqrt(cov_a[1, 1])) * k * k,
        "std_torque": float(np.sqrt(cov_t[1, 1])) * k * k,
        "residual_rms_rad": float(np.sqrt(np.mean(resid**2))),
        "n_points": int(tau.size),
        "residual_rad": resid,
        "compliance_rad_per_nm": float(b),
    }


_SEG_NAMES = ["theta0_pos", "theta0_neg", "k1", "k2", "k3", "t1", "t2"]


def _hinge_columns(x, t1, t2):
    """Torque taken at each of the three compliances for |τ| = x."""
    return np.column_stack([np.minimum(x, t1), np.clip(x - t1, 0.0, t2 - t1), np.maximum(x - t2, 0.0)])


def fit_three_segment(torque_nm, angle_rad, *, branch, angle_std_rad, torque_std_nm=None, groups=None,
                      torque_sources=None):
    """Three-segment stiffness K1, K2, K3 and break torques T1 < T2 of the loading branches.

    Parameters
    ----------
    torque_nm, angle_rad : array_like (n,)
        Samples of the loading branches: 0 → +Tmax (τ ≥ 0) and 0 → −Tmax (τ ≤ 0);
        each branch must contain its zero-torque start.
    branch : array_like of ±1
        Loading branch of each sample: +1 for 0 → +Tmax, −1 for 0 → −Tmax (the two
        zero-torque samples differ by the hysteresis loss, so the sign of the torque
        cannot tell them apart).
    angle_std_rad, torque_std_nm : array_like (n,)
        1σ per sample.
    groups : array_like of int, optional
        Shared torque error index per sample.
    torque_sources : array_like (n, m), optional
        Loading matrix of correlated torque errors (N·m per unit source); replaces
        ``torque_std_nm``/``groups`` for the torque part when given.

    Returns
    -------
    dict
        ``k1, k2, k3`` (N·m/rad), ``t1, t2`` (N·m), each with ``std_angle``/
        ``std_torque`` dicts, ``residual_rms_rad``.

    Raises
    ------
    AnalysisError
        A branch without its zero-torque sample, fewer than 6 distinct torque
        magnitudes, non-positive compliance, or unidentified parameters.

    Notes
    -----
    For fixed (T1, T2) the model is linear in (θ₀₊, θ₀₋, 1/K1, 1/K2, 1/K3); the break
    torques are found by an exhaustive search over the mid-points between torque
    levels (every segment keeps at least two levels) followed by Nelder–Mead refinement
    of the profiled weighted sum of squares.
    """
    tau = np.asarray(torque_nm, float)
    th = np.asarray(angle_rad, float)
    sa = np.asarray(angle_std_rad, float)
    st = np.zeros_like(tau) if torque_std_nm is None else np.asarray(torque_std_nm, float)
    grp = np.arange(tau.size) if groups is None else np.unique(np.asarray(groups), return_inverse=True)[1]
    sign = np.sign(np.asarray(branch, float)).reshape(-1)
    if sign.shape != tau.shape or np.any(sign == 0):
        raise AnalysisError("branch must give +1 (0 → +Tmax) or -1 (0 → -Tmax) for every sample")
    if np.any(tau * sign < 0):
        raise AnalysisError("a sample's torque has the opposite sign of its loading branch")
    for s_ in (1.0, -1.0):
        if not (np.any((sign == s_) & (tau == 0)) and np.any(tau * s_ > 0)):
            raise AnalysisError("three-segment fit needs both loading branches with their zero-torque start")
    x_all, y, s_all, g_all = np.abs(tau), th, sa, grp
    levels = np.unique(x_all)
    if levels.size < 6:
        raise AnalysisError(f"three-segment fit needs at least 6 distinct torque magnitudes, got {levels.size}")
    w = least_squares_weights(s_all)
    is_pos = (sign > 0).astype(float)

    def design(x, t1, t2):
        h = _hinge_columns(x, t1, t2) * sign[:, None]
        return np.column_stack([is_pos, 1.0 - is_pos, h])

    mids = 0.5 * (levels[1:] + levels[:-1])  # mids[k] lies between levels[k] and levels[k+1]
    starts = [(mids[i], mids[j]) for i in range(1, mids.size) for j in range(i + 2, mids.size - 1)]
    fit = fit_breakpoints(lambda t: design(x_all, t[0], t[1]), y, starts, weights=w,
                          feasible=lambda t: levels[1] < t[0] < t[1] < levels[-2],
                          xatol=levels[-1] * 1e-7, fatol_rel=1e-12)
    if fit.breakpoints is None:
        raise AnalysisError("three-segment fit: too few torque levels to place two break torques")
    t1, t2 = (float(v) for v in fit.breakpoints)
    coef = fit.coef
    if not np.all(coef[2:] > 0):
        raise AnalysisError("three-segment fit gives a non-positive compliance: the branches are not monotone")

    def model(p, taus=tau):
        return design(np.abs(taus), p[5], p[6]) @ p[:5]

    p = np.concatenate([coef, [t1, t2]])
    r = y - model(p)
    jac = numeric_jacobian(model, p, np.concatenate([[1e-7, 1e-7], np.abs(coef[2:]) * 1e-6, [levels[-1] * 1e-7] * 2]))
    if torque_sources is None:
        g_var = np.zeros(int(g_all.max()) + 1)
        np.maximum.at(g_var, g_all, st**2)
        jac_tau = torque_jacobian(lambda t: model(p, t), tau, g_all)
    else:
        src = np.asarray(torque_sources, float).reshape(tau.size, -1)
        jac_tau = torque_source_jacobian(lambda t: model(p, t), tau, src)
        g_var = np.ones(src.shape[1])
    try:
        cov_a, cov_t = linearised_covariance(jac, w, s_all**2, jac_tau, g_var)
    except np.linalg.LinAlgError:
        raise AnalysisError(
            "three-segment fit: the break torques are not identified (singular normal matrix)"
        ) from None
    conv = np.diag([1.0, 1.0, -1 / coef[2] ** 2, -1 / coef[3] ** 2, -1 / coef[4] ** 2, 1.0, 1.0])
    s_a, s_t = parameter_stds(_SEG_NAMES, conv @ cov_a @ conv.T, conv @ cov_t @ conv.T)
    return {
        "k1": 1 / coef[2],
        "k2": 1 / coef[3],
        "k3": 1 / coef[4],
        "t1": t1,
        "t2": t2,
        "std_angle": s_a,
        "std_torque": s_t,
        "residual_rms_rad": float(np.sqrt(np.mean(r * r))),
    }
