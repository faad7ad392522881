"""Circle and ellipse fits to edge points, each reporting failure with a reason.

These serve ``fit="geometric"``, ``"algebraic"`` and ``"ellipse"``; the default
marker fit (``"pixels"``, :mod:`.pixelfit`) fits the image model to the pixels
instead of a circle to edge points.

Three estimators, chosen by name:

``algebraic``
    The paper's fit (Kasa): minimise Q = Σ[(xᵢ-a)² + (yᵢ-b)² - r²]². Linear and
    fast, but it minimises an algebraic, not a geometric, distance: its radius is
    biased by noise and, with weighted or uneven point coverage, so is its centre.
``geometric``
    Orthogonal-distance fit: minimise Σ wᵢ(|pᵢ - c| - r)² by Gauss-Newton from the
    algebraic start, with iterative rejection of outliers (normalised residuals
    beyond ``clip`` robust standard deviations). With wᵢ = 1/σᵢ² this is the
    maximum-likelihood circle for independent Gaussian edge errors.
``ellipse``
    For oblique views: the direct least-squares ellipse (Fitzgibbon; Halír-Flusser
    numerics) refined geometrically, centre covariance from the refinement.

Points are centred and scaled before fitting, as scikit-image does, so fits stay
well conditioned at large image coordinates. Coordinates are image pixels (x, y),
origin at the centre of the top-left pixel, y downwards.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import FitError
from .numerics import numeric_jacobian

__all__ = [
    "CircleFit", "EllipseFit", "fit_circle", "fit_circle_algebraic", "fit_circle_geometric", "fit_ellipse",
    "centred_ellipse", "centred_ellipse_and_polar", "centred_ellipse_polar",
]

#: Largest condition number accepted for the normal equations of the ellipse's centre
#: and semi-axes (normalised units). A full ellipse, even a near-circle, gives < 10²;
#: a 60° arc about 3·10⁶, a 30° arc 7·10⁷, a 20° arc 5·10¹⁷ (the points then fix no
#: ellipse: a = 6·10⁶ px was returned). Beyond ~10¹⁰ half the digits of the solve
#: are noise.
_MAX_ELLIPSE_CONDITION = 1e10


@dataclass(frozen=True)
class CircleFit:
    """A fitted circle.

    Attributes
    ----------
    x_px, y_px : float
        Centre (px).
    radius_px : float
        Radius (px).
    cov : numpy.ndarray
        3x3 covariance of (x_px, y_px, radius_px) in px².
    residual_rms_px : float
        RMS orthogonal distance of the inlier points to the circle (px).
    inliers : numpy.ndarray
        Boolean mask of the points kept.
    method : str
        Name of the estimator.
    """

    x_px: float
    y_px: float
    radius_px: float
    cov: np.ndarray
    residual_rms_px: float
    inliers: np.ndarray = field(repr=False)
    method: str = "geometric"

    @property
    def centre_std_px(self) -> tuple[float, float]:
        """Standard uncertainties of x_px and y_px (px)."""
        return float(np.sqrt(self.cov[0, 0])), float(np.sqrt(self.cov[1, 1]))


@dataclass(frozen=True)
class EllipseFit:
    """A fitted ellipse: centre ``x_px, y_px`` (px), semi-axes ``a_px ≥ b_px`` (px),
    orientation ``angle_deg`` (deg, CCW as displayed), centre covariance ``cov`` (px²),
    ``residual_rms_px`` (px)."""

    x_px: float
    y_px: float
    a_px: float
    b_px: float
    angle_deg: float
    cov: np.ndarray
    residual_rms_px: float
    inliers: np.ndarray = field(repr=False)
    method: str = "ellipse"


def _check_points(x, y, weights, minimum):
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    if x.shape != y.shape:
        raise FitError(f"x and y have different lengths ({x.size} and {y.size})")
    if weights is None:
        w = np.ones_like(x)
    else:
        w = np.asarray(weights, dtype=np.float64).ravel()
        if w.shape != x.shape:
            raise FitError(f"weights have length {w.size}, points {x.size}")
        if np.any(~np.isfinite(w)) or np.any(w < 0):
            raise FitError("weights must be finite and not negative")
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < minimum:
        raise FitError(f"need at least {minimum} finite edge points, got {int(ok.sum())}")
    return x, y, w, ok


def _normalise(x, y):
    mx, my = x.mean(), y.mean()
    scale = np.sqrt(np.mean((x - mx) ** 2 + (y - my) ** 2))
    if not scale > 0:
        raise FitError("all edge points coincide")
    return mx, my, scale


def fit_circle_algebraic(x, y, *, weights=None) -> CircleFit:
    """The paper's algebraic (Kasa) circle fit, minimising Σ wᵢ[(xᵢ-a)² + (yᵢ-b)² - r²]².

    Parameters
    ----------
    x, y : array_like
        Edge points (px).
    weights : array_like, optional
        Non-negative weights of the points.

    Returns
    -------
    CircleFit
        Covariance from the linear least-squares problem with the residual variance
        (first-order; it carries the method's bias unseen).

    Raises
    ------
    FitError
        Fewer than 3 points or collinear points.

    Examples
    --------
    >>> t = np.linspace(0, 2 * np.pi, 50, endpoint=False)
    >>> f = fit_circle_algebraic(3 + 2 * np.cos(t), 4 + 2 * np.sin(t))
    >>> round(f.x_px, 9), round(f.y_px, 9), round(f.radius_px, 9)
    (3.0, 4.0, 2.0)
    """
    x, y, w, ok = _check_points(x, y, weights, 3)
    x, y, w = x[ok], y[ok], w[ok]
    mx, my, s = _normalise(x, y)
    u, v = (x - mx) / s, (y - my) / s
    A = np.stack([u, v, np.ones_like(u)], axis=1)
    b = u * u + v * v
    sw = np.sqrt(w)
    sol, *_ = np.linalg.lstsq(A * sw[:, None], b * sw, rcond=None)
    ua, va = sol[0] / 2, sol[1] / 2
    r2 = sol[2] + ua * ua + va * va
    if not r2 > 0 or not np.all(np.isfinite(sol)):
        raise FitError("algebraic circle fit is degenerate (points collinear?)")
    r = np.sqrt(r2)
    dist = np.hypot(u - ua, v - va) - r
    dof = max(u.size - 3, 1)
    resid = A @ sol - b
    sigma2 = np.sum(w * resid**2) / dof
    try:
        cov_sol = np.linalg.inv((A * w[:, None]).T @ A) * sigma2
    except np.linalg.LinAlgError as exc:
        raise FitError("algebraic circle fit is singular (points collinear?)") from exc
    # (a, b, r) = (s0/2, s1/2, sqrt(s2 + a² + b²)) in normalised units
    J = np.array([[0.5, 0, 0], [0, 0.5, 0], [ua / (2 * r), va / (2 * r), 1 / (2 * r)]])
    cov = J @ cov_sol @ J.T * s * s
    return CircleFit(
        x_px=float(mx + ua * s),
        y_px=float(my + va * s),
        radius_px=float(r * s),
        cov=cov,
        residual_rms_px=float(np.sqrt(np.mean(dist**2)) * s),
        inliers=ok.copy(),
        method="algebraic",
    )


def fit_circle_geometric(
    x, y, *, weights=None, initial=None, clip: float = 4.0, max_iter: int = 30
) -> CircleFit:
    """Orthogonal-distance circle fit with outlier rejection.

    Parameters
    ----------
    x, y : array_like
        Edge points (px).
    weights : array_like, optional
        Weights 1/σᵢ² of the points (px⁻²). With true inverse variances the returned
        covariance is the Cramér-Rao covariance of the fit.
    initial : tuple of float, optional
        Starting (x, y, radius); the algebraic fit otherwise.
    clip : float
        Points whose weighted residual exceeds `clip` robust standard deviations
        (1.4826·MAD) are rejected, and the fit repeated until no point changes.
    max_iter : int
        Gauss-Newton iterations per pass.

    Returns
    -------
    CircleFit
        Covariance (JᵀWJ)⁻¹ scaled by the reduced χ² of the inliers when it exceeds 1
        (so unmodelled scatter widens the uncertainty; it is never narrowed).

    Raises
    ------
    FitError
        Fewer than 5 points, degenerate geometry, or no convergence.

    Notes
    -----
    Residual of point i: dᵢ = |pᵢ - c| - r. Jacobian rows: (-(xᵢ-a)/ρᵢ, -(yᵢ-b)/ρᵢ, -1).
    """
    x, y, w, ok = _check_points(x, y, weights, 5)
    mx, my, s = _normalise(x[ok], y[ok])
    u, v = (x - mx) / s, (y - my) / s
    ws = w * s * s  # weights in normalised units
    if initial is None:
        start = fit_circle_algebraic(x[ok], y[ok], weights=w[ok])
        p = np.array([(start.x_px - mx) / s, (start.y_px - my) / s, start.radius_px / s])
    else:
        p = np.array([(initial[0] - mx) / s, (initial[1] - my) / s, initial[2] / s], dtype=np.float64)
    inl = ok.copy()
    for _pass in range(6):
        uu, vv, ww = u[inl], v[inl], ws[inl]
        if uu.size < 5:
            raise FitError(f"only {uu.size} edge points left after outlier rejection")
        for _ in range(max_iter):
            du, dv = uu - p[0], vv - p[1]
            rho = np.hypot(du, dv)
            if np.any(rho == 0):
                raise FitError("an edge point coincides with the circle centre")
            res = rho - p[2]
            J = np.stack([-du / rho, -dv / rho, -np.ones_like(rho)], axis=1)
            JTW = J.T * ww
            H = JTW @ J
            try:
                step = np.linalg.solve(H, -JTW @ res)
            except np.linalg.LinAlgError as exc:
                raise FitError("geometric circle fit is singular (points on a line?)") from exc
            p = p + step
            if np.max(np.abs(step)) < 1e-10:  # normalised units: ~1e-8 px
                break
        else:
            raise FitError("geometric circle fit did not converge")
        du, dv = u - p[0], v - p[1]
        res_all = np.hypot(du, dv) - p[2]
        z = res_all * np.sqrt(ws)
        med = np.median(np.abs(z[inl]))
        scale = 1.4826 * med if med > 0 else np.inf
        new = ok & (np.abs(z) <= clip * max(scale, 1e-300))
        if np.array_equal(new, inl):
            break
        inl = new
    dof = max(int(inl.sum()) - 3, 1)
    chi2 = float(np.sum(ws[inl] * res_all[inl] ** 2)) / dof
    if weights is None:
        factor = chi2  # unit weights: the residual variance is the only scale
    else:
        factor = max(chi2, 1.0)
    try:
        cov = np.linalg.inv(H) * factor * s * s
    except np.linalg.LinAlgError as exc:  # pragma: no cover - H was solvable above
        raise FitError("geometric circle fit covariance is singular") from exc
    if not (p[2] > 0 and np.all(np.isfinite(p))):
        raise FitError("geometric circle fit gave a non-positive radius")
    return CircleFit(
        x_px=float(mx + p[0] * s),
        y_px=float(my + p[1] * s),
        radius_px=float(p[2] * s),
        cov=cov,
        residual_rms_px=float(np.sqrt(np.mean(res_all[inl] ** 2)) * s),
        inliers=inl,
        method="geometric",
    )


def fit_circle(x, y, *, method: str = "geometric", weights=None, **options) -> CircleFit:
    """Fit a circle to edge points by the named method (``"geometric"`` or ``"algebraic"``).

    Raises
    ------
    FitError
        Unknown method, or the chosen fit failed (the message says why).
    """
    if method == "geometric":
        return fit_circle_geometric(x, y, weights=weights, **options)
    if method == "algebraic":
        return fit_circle_algebraic(x, y, weights=weights)
    raise FitError(f"unknown circle-fit method {method!r}; use 'geometric' or 'algebraic'")


def _ellipse_params_from_conic(c):
    A, B, C, D, E, F = c
    den = B * B - 4 * A * C
    if den >= 0:
        raise FitError("fitted conic is not an ellipse")
    x0 = (2 * C * D - B * E) / den
    y0 = (2 * A * E - B * D) / den
    num = 2 * (A * E * E + C * D * D - B * D * E + den * F)
    root = np.sqrt((A - C) ** 2 + B * B)
    a = -np.sqrt(num * (A + C + root)) / den
    b = -np.sqrt(num * (A + C - root)) / den
    theta = 0.5 * np.arctan2(-B, C - A)
    if not (np.isfinite(a) and np.isfinite(b) and a > 0 and b > 0):
        raise FitError("fitted conic is not a real ellipse")
    if b > a:
        a, b = b, a
        theta += np.pi / 2
    return x0, y0, a, b, theta


def _direct_ellipse(u, v, w):
    """Direct least-squares ellipse (Halír-Flusser form of Fitzgibbon's method)."""
    sw = np.sqrt(w)[:, None]
    D1 = np.stack([u * u, u * v, v * v], axis=1) * sw
    D2 = np.stack([u, v, np.ones_like(u)], axis=1) * sw
    S1, S2, S3 = D1.T @ D1, D1.T @ D2, D2.T @ D2
    try:
        T = -np.linalg.solve(S3, S2.T)
    except np.linalg.LinAlgError as exc:
        raise FitError("ellipse fit is singular") from exc
    M = S1 + S2 @ T
    M = np.array([M[2] / 2, -M[1], M[0] / 2])
    vals, vecs = np.linalg.eig(M)
    vecs = np.real(vecs)
    cond = 4 * vecs[0] * vecs[2] - vecs[1] ** 2
    idx = np.where(cond > 0)[0]
    if idx.size == 0:
        raise FitError("no ellipse solution (points too few or degenerate)")
    a1 = vecs[:, idx[0]]
    return np.concatenate([a1, T @ a1])


def _ellipse_residuals(p, u, v):
    """Approximate orthogonal distances (Sampson) of points to the ellipse p = (x0, y0, a, b, θ)."""
    x0, y0, a, b, th = p
    c, s = np.cos(th), np.sin(th)
    xr = (u - x0) * c + (v - y0) * s
    yr = -(u - x0) * s + (v - y0) * c
    f = (xr / a) ** 2 + (yr / b) ** 2 - 1
    gx, gy = 2 * xr / a**2, 2 * yr / b**2
    return f / np.hypot(gx, gy)


def fit_ellipse(x, y, *, weights=None, clip: float = 4.0) -> EllipseFit:
    """Fit an ellipse to edge points: direct least squares, then geometric refinement.

    Parameters
    ----------
    x, y : array_like
        Edge points (px).
    weights : array_like, optional
        Weights 1/σᵢ² (px⁻²).
    clip : float
        Outlier threshold in robust standard deviations.

    Returns
    -------
    EllipseFit
        Centre covariance from the Gauss-Newton refinement, scaled by the reduced χ²
        when it exceeds 1.

    Raises
    ------
    FitError
        Fewer than 6 points; the direct fit finds no ellipse; a refinement step's
        solve is singular; the result is not a real ellipse (a semi-axis not
        positive and finite); or the normal equations of the centre and semi-axes
        are ill-conditioned (condition number above :data:`_MAX_ELLIPSE_CONDITION`:
        the points cover too short an arc to fix an ellipse).

    Notes
    -----
    The points are centred and scaled before fitting (as :func:`fit_circle_geometric`
    and scikit-image do), so the conditioning does not depend on where the marker
    lies in the image. For a near-circle the orientation θ is not determined by the
    points; that does not harm the centre, so θ is left out of the conditioning test
    and its iterations are not required to converge.

    Examples
    --------
    >>> t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    >>> e = fit_ellipse(10 + 5 * np.cos(t), 20 + 3 * np.sin(t))
    >>> round(e.x_px, 6), round(e.y_px, 6), round(e.a_px, 6), round(e.b_px, 6)
    (10.0, 20.0, 5.0, 3.0)
    """
    x, y, w, ok = _check_points(x, y, weights, 6)
    mx, my, s = _normalise(x[ok], y[ok])
    u, v = (x - mx) / s, (y - my) / s
    ws = w * s * s
    conic = _direct_ellipse(u[ok], v[ok], ws[ok] / ws[ok].max())
    p = np.array(_ellipse_params_from_conic(conic), dtype=np.float64)
    inl = ok.copy()
    for _pass in range(5):
        uu, vv, ww = u[inl], v[inl], ws[inl]
        for _ in range(30):
            r0 = _ellipse_residuals(p, uu, vv)
            J = numeric_jacobian(lambda q: _ellipse_residuals(q, uu, vv), p, 1e-7 * np.maximum(1.0, np.abs(p)), f0=r0)
            JTW = J.T * ww
            H = JTW @ J + 1e-12 * np.eye(5)
            try:
                step = np.linalg.solve(H, -JTW @ r0)
            except np.linalg.LinAlgError as exc:
                raise FitError("ellipse fit is singular (points on a line?)") from exc
            p = p + step
            if not np.all(np.isfinite(p)):
                raise FitError("ellipse fit diverged (the points do not determine an ellipse)")
            if np.max(np.abs(step)) < 1e-11:
                break
        res_all = _ellipse_residuals(p, u, v)
        z = res_all * np.sqrt(ws)
        scale = 1.4826 * np.median(np.abs(z[inl]))
        new = ok & (np.abs(z) <= clip * max(scale, 1e-300))
        if np.array_equal(new, inl) or new.sum() < 6:
            break
        inl = new
    condition = np.linalg.cond(H[:4, :4])
    if not condition < _MAX_ELLIPSE_CONDITION:
        raise FitError(f"ellipse fit is ill-conditioned (condition number {condition:.1e} for the centre and "
                       "semi-axes): the edge points cover too short an arc to fix an ellipse")
    if not (p[2] > 0 and p[3] > 0):
        raise FitError(f"ellipse fit did not give a real ellipse (semi-axes {p[2] * s:.3g} and {p[3] * s:.3g} px)")
    dof = max(int(inl.sum()) - 5, 1)
    chi2 = float(np.sum(ws[inl] * res_all[inl] ** 2)) / dof
    factor = chi2 if weights is None else max(chi2, 1.0)
    cov = np.linalg.inv(H)[:2, :2] * factor * s * s
    x0, y0, a, b, th = p
    if b > a:
        a, b, th = b, a, th + np.pi / 2
    return EllipseFit(
        x_px=float(mx + x0 * s),
        y_px=float(my + y0 * s),
        a_px=float(a * s),
        b_px=float(b * s),
        angle_deg=float(np.rad2deg(-th) % 180.0),
        cov=cov,
        residual_rms_px=float(np.sqrt(np.mean(res_all[inl] ** 2)) * s),
        inliers=inl,
    )


def centred_ellipse(dx, dy):
    """The ellipse centred on the origin closest to points at offsets (`dx`, `dy`) (px)
    from it: (minor/major axis ratio, RMS radial distance of the points from it in px),
    or None when the points lie on no such ellipse.

    Notes
    -----
    An ellipse centred on the origin with semi-axes a ≥ b, the major one at angle θ,
    is 1/r(ψ)² = A + B·cos 2ψ + C·sin 2ψ in polar coordinates, with
    A = (1/a² + 1/b²)/2 and √(B² + C²) = (1/b² - 1/a²)/2: linear least squares in
    (A, B, C). b/a = √((A - h)/(A + h)) with h = √(B² + C²).
    """
    return centred_ellipse_and_polar(dx, dy)[0]


def centred_ellipse_and_polar(dx, dy):
    """:func:`centred_ellipse`'s result and :func:`centred_ellipse_polar`'s coefficients
    (A, B, C) for points at offsets (`dx`, `dy`) (px) from the origin, from one
    least-squares fit: for a caller that needs both."""
    coef, design, r2 = _centred_ellipse_fit(dx, dy)
    h = float(np.hypot(coef[1], coef[2]))
    inverse_r2 = design @ coef
    if not coef[0] > h or not (inverse_r2 > 0).all():
        return None, coef
    off = np.sqrt(r2) - 1.0 / np.sqrt(inverse_r2)
    return (float(np.sqrt((coef[0] - h) / (coef[0] + h))), float(np.sqrt(np.mean(off * off)))), coef


def centred_ellipse_polar(dx, dy) -> np.ndarray:
    """The coefficients (A, B, C) of the ellipse centred on the origin closest to points
    at offsets (`dx`, `dy`) (px) from it (:func:`centred_ellipse`), in polar form
    1/r(ψ)² = A + B·cos 2ψ + C·sin 2ψ (px⁻²), ψ the direction in image axes: the
    major axis (largest r) lies at ψ = atan2(-C, -B)/2. No check that they are an
    ellipse (A > √(B² + C²)): :func:`centred_ellipse` says so."""
    return _centred_ellipse_fit(dx, dy)[0]


def _centred_ellipse_fit(dx, dy):
    """(A, B, C) of :func:`centred_ellipse_polar`, the design matrix of that linear
    least-squares fit of 1/r² (rows: 1, cos 2ψ, sin 2ψ) and the points' r² (px²)."""
    r2 = dx * dx + dy * dy
    design = np.stack([np.ones_like(r2), (dx * dx - dy * dy) / r2, 2.0 * dx * dy / r2], axis=1)
    return np.linalg.lstsq(design, 1.0 / r2, rcond=None)[0], design, r2
