"""Smooth fit of a loading branch and the stiffness curve K(T) = dT/dtheta with its band.

The torque is fitted as a function of the output angle, T(theta), because the angle
comes from the motor's pulses (almost exact) and the noise is in the torque: the
regression runs in the direction of the noise. The stiffness is the derivative of
the fit, K = dT/dtheta (N·m/rad), as in the stiffness paper, which fits the forward
loading curve and differentiates it.

Two fits:

``"polynomial"`` (default)
    Least-squares polynomial of a chosen order in the Chebyshev basis on the angle
    mapped to [-1, 1] (well conditioned however small the angles are in radians).
``"spline"``
    Smoothing spline: a cubic B-spline on up to 16 equal segments (one per 20 samples at least) with a
    second-difference roughness penalty (a P-spline, Eilers & Marx 1996) whose
    weight is chosen by generalised cross-validation.

Both are linear smoothers c = H·Bᵀ·y, so the band comes from the coefficient
covariance C = s²·H·BᵀB·H (s² the residual variance over the residual degrees of
freedom): std K(theta) = sqrt(gᵀ C g), g the derivative of the basis at theta.
The band covers noise, not model bias: where the fit cannot follow the curve (noise-
free data, too low an order) it is too narrow.

The band assumes independent residuals, so fit the **unfiltered** samples of a
branch (a low-pass before a least-squares fit hardly changes the estimate, since the
smooth curve lies in the pass band, but it correlates the residuals and would make
the band too narrow).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.polynomial import chebyshev as cheb
from scipy.interpolate import BSpline

from ..errors import AnalysisError
from .combine import mean_over_cycles

__all__ = ["FIT_METHODS", "BranchFit", "StiffnessCurve", "fit_loading_branch", "stiffness_curve",
           "summarise_curves"]

FIT_METHODS = ("polynomial", "spline")


class _LinearFit:
    """Least-squares fit T = B(u)·c with u the angle mapped to [-1, 1] over the data.

    Subclasses give the basis B; the coefficient covariance is the sandwich
    C = s²·H·(BᵀB)·H with H = (BᵀB + P)⁻¹ (P the roughness penalty, 0 for the
    polynomial) and s² = RSS / (m − trace of the hat matrix).
    """

    def __init__(self, angle, torque, penalty=None):
        self.mid = 0.5 * (angle.max() + angle.min())
        self.half = 0.5 * (angle.max() - angle.min())
        b = self.basis(angle, derivative=False)
        btb, bty = b.T @ b, b.T @ torque
        if penalty is None:
            penalty = self._choose_penalty(b, btb, bty, torque)
        h = np.linalg.inv(btb + penalty)
        self.coef = h @ bty
        resid = torque - b @ self.coef
        dof = len(torque) - float(np.trace(h @ btb))
        self.residual_std = float(np.sqrt(resid @ resid / dof))
        self.cov = self.residual_std**2 * (h @ btb @ h)

    def _choose_penalty(self, b, btb, bty, torque):
        return np.zeros_like(btb)

    def u(self, angle):
        return (np.asarray(angle, dtype=float) - self.mid) / self.half

    def evaluate(self, angle, derivative=False, std=True):
        g = self.basis(np.atleast_1d(angle), derivative)
        value = g @ self.coef
        return value, (np.sqrt(np.einsum("ij,jk,ik->i", g, self.cov, g)) if std else None)


class _Polynomial(_LinearFit):
    """Polynomial of a given order in the Chebyshev basis (well conditioned on [-1, 1])."""

    def __init__(self, angle, torque, order):
        self.order = order
        self.dcoef = cheb.chebder(np.eye(order + 1), axis=0)  # coef -> derivative coef
        super().__init__(angle, torque, penalty=np.zeros((order + 1, order + 1)))

    def basis(self, angle, derivative):
        u = self.u(angle)
        if not derivative:
            return cheb.chebvander(u, self.order)
        return cheb.chebvander(u, self.order - 1) @ self.dcoef / self.half


class _PSpline(_LinearFit):
    """Penalised cubic B-spline (Eilers & Marx P-spline), a smoothing spline whose
    roughness penalty lam·|D2 c|² is chosen by generalised cross-validation."""

    def __init__(self, angle, torque):
        segments = int(np.clip(len(angle) // 20, 4, 16))
        inner = np.linspace(-1.0, 1.0, segments + 1)
        self.knots = np.concatenate([[-1.0] * 3, inner, [1.0] * 3])
        n = len(self.knots) - 4
        self.splines = (BSpline(self.knots, np.eye(n), 3), BSpline(self.knots, np.eye(n), 3).derivative())
        d2 = np.diff(np.eye(n), 2, axis=0)
        self.dtd = d2.T @ d2
        super().__init__(angle, torque)

    def _choose_penalty(self, b, btb, bty, torque):
        scale = np.trace(btb) / np.trace(self.dtd)
        best = None
        for lam in scale * np.logspace(-8, 2, 41):
            h = np.linalg.inv(btb + lam * self.dtd)
            resid = torque - b @ (h @ bty)
            edf = float(np.trace(h @ btb))
            gcv = len(torque) * float(resid @ resid) / (len(torque) - edf) ** 2
            if best is None or gcv < best[0]:
                best = (gcv, lam)
        return best[1] * self.dtd

    def basis(self, angle, derivative):
        u = np.clip(self.u(angle), -1.0, 1.0)
        return self.splines[1](u) / self.half if derivative else self.splines[0](u)


@dataclass(frozen=True)
class BranchFit:
    """A smooth fit T(theta) of one loading branch.

    Attributes
    ----------
    kind : str
        ``positive_loading`` or ``negative_loading``.
    method : str
        ``polynomial`` or ``spline``.
    order : int or None
        Polynomial order (None for the spline).
    angle_min_rad, angle_max_rad : float
        Span of the fitted samples, output rad.
    n_points : int
        Number of fitted samples.
    residual_std_nm : float
        Standard deviation of the residuals, N·m.
    cycle : int or None
        The cycle of the record the branch is of (0 = virgin loading), if known.
    """

    kind: str
    method: str
    order: int | None
    angle_min_rad: float
    angle_max_rad: float
    n_points: int
    residual_std_nm: float
    _model: object = field(repr=False)
    cycle: int | None = None

    @property
    def sign(self) -> int:
        """+1 for a positive branch, −1 for a negative one."""
        return 1 if self.kind.startswith("positive") else -1

    def torque(self, angle_rad):
        """Fitted torque (N·m) and its standard uncertainty at `angle_rad` (rad)."""
        return self._model.evaluate(angle_rad)

    def stiffness(self, angle_rad):
        """Stiffness K = dT/dtheta (N·m/rad) and its standard uncertainty at `angle_rad`."""
        return self._model.evaluate(angle_rad, derivative=True)


def fit_loading_branch(angle_rad, torque_nm, *, kind: str = "positive_loading",
                       method: str = "polynomial", order: int = 7) -> BranchFit:
    """Fit a smooth curve T(theta) to the samples of one loading branch.

    Parameters
    ----------
    angle_rad : array_like
        Output angles of the branch's samples past first contact, rad (any order;
        cycles may be pooled). Not modified.
    torque_nm : array_like
        Their torques, N·m (unfiltered, see module docstring).
    kind : {"positive_loading", "negative_loading"}
        Which branch (sets the direction of the dead-zone edge).
    method : {"polynomial", "spline"}
        Fit method (module docstring).
    order : int
        Polynomial order (``polynomial`` only).

    Returns
    -------
    BranchFit

    Raises
    ------
    AnalysisError
        Unknown method or kind, too few points for the order (at least order + 3),
        a degenerate angle span, or a fit whose stiffness is not positive over the
        data (not a loading curve; try a lower order).

    Examples
    --------
    >>> theta = np.linspace(0.0, 0.002, 400)          # rad
    >>> fit = fit_loading_branch(theta, 5000 * theta + 2e6 * theta**2, order=3)
    >>> k, k_std = fit.stiffness(0.001)
    >>> round(float(k[0]))                           # 5000 + 2 * 2e6 * 0.001
    9000
    """
    if method not in FIT_METHODS:
        raise AnalysisError(f"fit method must be one of {FIT_METHODS}, got {method!r}")
    if kind not in ("positive_loading", "negative_loading"):
        raise AnalysisError(f"kind must be positive_loading or negative_loading, got {kind!r}")
    angle = np.asarray(angle_rad, dtype=float)
    torque = np.asarray(torque_nm, dtype=float)
    if int(order) != order or order < 1:
        raise AnalysisError(f"polynomial order must be a whole number >= 1, got {order!r}")
    needed = order + 3 if method == "polynomial" else 8
    if angle.size < needed:
        what = f"a polynomial of order {order}" if method == "polynomial" else "a smoothing spline"
        raise AnalysisError(
            f"the {kind} branch has {angle.size} usable points; {what} needs at least {needed}"
        )
    if not np.ptp(angle) > 0:
        raise AnalysisError(f"the {kind} branch has no spread in angle")
    if method == "polynomial":
        model = _Polynomial(angle, torque, int(order))
    else:
        model = _PSpline(angle, torque)
    fit = BranchFit(kind=kind, method=method, order=int(order) if method == "polynomial" else None,
                    angle_min_rad=float(angle.min()), angle_max_rad=float(angle.max()),
                    n_points=int(angle.size), residual_std_nm=model.residual_std, _model=model)
    grid = np.linspace(fit.angle_min_rad, fit.angle_max_rad, 400)
    k = model.evaluate(grid, derivative=True, std=False)[0]
    if np.any(k <= 0):
        where = model.evaluate(grid[np.argmax(k <= 0)], std=False)[0][0]
        raise AnalysisError(
            f"the {method} fit of the {kind} branch is not monotonic (stiffness <= 0 near "
            f"T = {where:.3g} N·m); try a lower --order or the other method",
            reason="not_monotonic",
        )
    return fit


@dataclass(frozen=True)
class StiffnessCurve:
    """Stiffness curve of one loading branch, sampled along its fitted span.

    Attributes
    ----------
    kind : str
        The loading branch.
    angle_deg : ndarray
        Output angle, degrees.
    torque_nm : ndarray
        Fitted torque, N·m, ordered by rising |T|.
    stiffness_nm_per_rad, stiffness_std_nm_per_rad : ndarray
        K = dT/dtheta and its standard uncertainty, N·m/rad.
    cycle : int or None
        The cycle (0 = virgin loading; a camera record's loop) this curve is of;
        None for a summary over cycles (:func:`summarise_curves`).
    n_cycles : int
        Cycles behind the curve (1 for one cycle's curve).
    """

    kind: str
    angle_deg: np.ndarray
    torque_nm: np.ndarray
    stiffness_nm_per_rad: np.ndarray
    stiffness_std_nm_per_rad: np.ndarray
    cycle: int | None = None
    n_cycles: int = 1

    def at_torque(self, torque_nm):
        """K and its std (N·m/rad) interpolated at torque(s) on this branch (N·m).

        Raises
        ------
        AnalysisError
            A torque is outside the curve's range.
        """
        t = np.atleast_1d(np.asarray(torque_nm, dtype=float))
        mag = np.abs(self.torque_nm)
        lo, hi = mag.min(), mag.max()
        if np.any(np.sign(t) * np.sign(self.torque_nm[-1]) < 0) or np.any((np.abs(t) < lo) | (np.abs(t) > hi)):
            raise AnalysisError(
                f"torque(s) {t.tolist()} N·m outside the {self.kind} stiffness curve "
                f"({np.sign(self.torque_nm[-1]) * lo:.4g} to {self.torque_nm[-1]:.4g} N·m)"
            )
        return (np.interp(np.abs(t), mag, self.stiffness_nm_per_rad),
                np.interp(np.abs(t), mag, self.stiffness_std_nm_per_rad))


def stiffness_curve(fit: BranchFit, *, points: int = 200, cycle: int | None = None) -> StiffnessCurve:
    """Sample the stiffness curve of a fit over its data span.

    Parameters
    ----------
    fit : BranchFit
    points : int
        Number of samples, evenly spaced in angle.
    cycle : int, optional
        The cycle the fit is of (stored on the curve).

    Returns
    -------
    StiffnessCurve
        Ordered by rising |T| (the fit is monotonic, see :func:`fit_loading_branch`).
    """
    angle = np.linspace(fit.angle_min_rad, fit.angle_max_rad, int(points))
    if fit.sign < 0:
        angle = angle[::-1]
    torque = fit.torque(angle)[0]
    k, k_std = fit.stiffness(angle)
    return StiffnessCurve(kind=fit.kind, angle_deg=np.rad2deg(angle), torque_nm=torque,
                          stiffness_nm_per_rad=k, stiffness_std_nm_per_rad=k_std, cycle=cycle)


def summarise_curves(curves, *, points: int = 200) -> StiffnessCurve:
    """The mean stiffness curve of one loading branch over cycles, at common torques.

    Each cycle is fitted on its own (its zero offset and its contact angle stay its
    own), so the curves are compared at equal torque, never pooled in angle.

    Parameters
    ----------
    curves : sequence of StiffnessCurve
        Curves of one kind, one per cycle.
    points : int
        Torques, evenly spaced over the |T| range all curves cover.

    Returns
    -------
    StiffnessCurve
        ``cycle = None``, ``n_cycles = len(curves)``; K is the mean over cycles and
        its standard uncertainty combines the scatter between cycles (Type A,
        sd/sqrt(n)) with the fits' own (Type B, sqrt(sum std²)/n)
        (:func:`~.combine.mean_over_cycles`). With one cycle it is that cycle's
        curve and band.
        ``angle_deg`` is the mean angle of the cycles at each torque.

    Raises
    ------
    AnalysisError
        No curves, curves of different kinds, or no torque range common to all.

    Examples
    --------
    >>> t = np.linspace(1.0, 10.0, 50)
    >>> a = StiffnessCurve("positive_loading", t / 100, t, 100 * t, np.ones(50), cycle=1)
    >>> b = StiffnessCurve("positive_loading", t / 100, t, 100 * t + 2, np.ones(50), cycle=2)
    >>> s = summarise_curves([a, b], points=3)
    >>> s.stiffness_nm_per_rad.tolist(), s.n_cycles
    ([101.0, 551.0, 1001.0], 2)
    """
    curves = list(curves)
    if not curves:
        raise AnalysisError("no stiffness curves to summarise")
    kinds = {c.kind for c in curves}
    if len(kinds) != 1:
        raise AnalysisError(f"cannot summarise curves of different branches {sorted(kinds)}")
    kind = curves[0].kind
    lo = max(float(np.min(np.abs(c.torque_nm))) for c in curves)
    hi = min(float(np.max(np.abs(c.torque_nm))) for c in curves)
    if not hi > lo:
        raise AnalysisError(f"the {kind} curves of the cycles have no torque range in common")
    sign = 1.0 if kind.startswith("positive") else -1.0
    mag = np.linspace(lo, hi, int(points))
    k = np.array([np.interp(mag, np.abs(c.torque_nm), c.stiffness_nm_per_rad) for c in curves])
    k_std = np.array([np.interp(mag, np.abs(c.torque_nm), c.stiffness_std_nm_per_rad) for c in curves])
    angle = np.array([np.interp(mag, np.abs(c.torque_nm), c.angle_deg) for c in curves])
    k_mean, k_u = mean_over_cycles(k, k_std)
    return StiffnessCurve(kind=kind, angle_deg=angle.mean(axis=0), torque_nm=sign * mag,
                          stiffness_nm_per_rad=k_mean, stiffness_std_nm_per_rad=k_u,
                          cycle=None, n_cycles=len(curves))
