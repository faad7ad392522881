"""Sub-pixel edge points of a circular marker from an edge-profile model.

Pixel-level edges (Canny) quantise the edge to the pixel grid and use one pixel per
edge sample; a centre fitted to them is several times less precise than the image
allows. Here every pixel near the edge contributes, weighted by how much it says
about the edge position.

Model (per marker, in a ring of pixels around the current circle estimate: the edge
zone of ±(3s + 2.5) px plus 3 px more of background, so that the background plane is
pinned by pixels away from the edge)::

    I(p) = B(p) + (F(p) - B(p)) · Φ((R - d(p)) / s)

with d(p) the distance of pixel p from the current centre, Φ the standard normal
distribution function, s the edge width (PSF σ combined with the pixel's own
width, s² ≈ σ² + 1/12), and B, F the grey levels outside and inside the marker.
Light multiplies reflectance, so B and F share one illumination gradient across the
marker: B is a plane and F = κ·B with one ratio κ (four level parameters). Separate
planes for B and F (six parameters) would let the inside plane's tilt trade off
against a shift of the edge, which cost about 15 % of the centre's precision.

1. The levels are solved by linear least squares (κ from a first pass with free
   planes), with a second pass that drops outlying pixels (a wire or a speck
   crossing the ring).
2. The ring is cut into angular sectors about 1 px of arc wide; sectors where the
   outlier cut (grown by 2 px, for the occluder's blurred flanks) removed pixels,
   and two neighbours each side, are dropped. In sector k the
   edge's radial offset δₖ is the one-step Gauss-Newton (maximum-likelihood)
   estimate ``δₖ = Σ gᵢ eᵢ / Σ gᵢ²`` with eᵢ the model residual and gᵢ = ∂I/∂R
   = (F - B)·φ(uᵢ)/s; its variance is σ²/Σ gᵢ² with σ² the residual variance. The
   edge point lies at R + δₖ along the sector's (g²-weighted) mean direction.
3. Before the sectors, s is updated by a Gauss-Newton step on the same model and
   the levels solved again with it (and without the outliers).

Fitting a circle to these points with weights 1/var (see :mod:`.circlefit`) and
repeating until the centre stops moving is a Gauss-Newton solution of the full
maximum-likelihood fit of the model to the pixels, which is why the result comes
within a small factor of the Cramér-Rao bound.

Coordinates are image pixels (x, y), origin at the centre of the top-left pixel,
y downwards.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import FitError
from .ring import (
    INV_SQRT_2PI,
    MarkerPatch,
    bounded_edge_width,
    check_contrast,
    cut_occluders,
    in_edge_zone,
    lost_sectors,
    marker_patch,
    normal_cdf,
    occluder_group,
    sector_edge_offsets,
    sector_index,
)

__all__ = ["EdgePoints", "edge_points"]

#: Extra background ring (px) beyond the edge zone, for the background plane.
OUTER_EXTRA_PX = 3.0


@dataclass(frozen=True)
class EdgePoints:
    """Sub-pixel edge points of one marker.

    Attributes
    ----------
    x_px, y_px : numpy.ndarray
        Edge points (px).
    std_px : numpy.ndarray
        Standard uncertainty of each point along the edge normal (px).
    noise_dn : float
        Residual RMS of the pixel model (DN): the image noise where the model fits.
    edge_width_px : float
        Updated edge width s (px).
    background_dn, foreground_dn : float
        Grey levels outside and inside the marker at its centre (DN).
    n_pixels : int
        Pixels used.
    """

    x_px: np.ndarray
    y_px: np.ndarray
    std_px: np.ndarray
    noise_dn: float
    edge_width_px: float
    background_dn: float
    foreground_dn: float
    n_pixels: int


def _solve_levels(Phi, nx, ny, vals, weight, kappa=None):
    """Plane coefficients of B (outside) and F (inside) by weighted least squares.

    With `kappa` (the inside/outside reflectance ratio F/B) the two planes share one
    illumination gradient, F's slopes being kappa times B's: four parameters
    instead of six. Returned as the six plane coefficients either way.
    """
    one_m = 1.0 - Phi
    if kappa is None:
        design = np.stack([one_m, one_m * nx, one_m * ny, Phi, Phi * nx, Phi * ny], axis=1)
    else:
        lit = one_m + kappa * Phi
        design = np.stack([one_m, lit * nx, lit * ny, Phi], axis=1)
    wd = design * weight[:, None]
    try:
        coef = np.linalg.solve(wd.T @ design, wd.T @ vals)
    except np.linalg.LinAlgError as exc:
        raise FitError("the marker's grey levels cannot be separated (no edge in the ring)") from exc
    resid = vals - design @ coef
    if kappa is not None:
        coef = np.array([coef[0], coef[1], coef[2], coef[3], kappa * coef[1], kappa * coef[2]])
    return coef, resid


def _first_pass(u, s, nx, ny, vals, ring_idx, shape):
    """Pass 1 of :func:`edge_points`: the levels from every ring pixel (`u` their
    edge coordinates at the edge width `s`, px; `nx`, `ny` the lighting frame;
    `vals` their values, DN), the occluder cut (:func:`~vision_torsion.ring.cut_occluders`)
    and a Gauss-Newton step of s (dI/ds = -(F - B)·φ(u)·u/s). Returns the flags
    of the pixels kept, the levels' coefficients and the new s (px)."""
    coef, resid = _solve_levels(normal_cdf(u), nx, ny, vals, np.ones_like(vals))
    found = cut_occluders(
        resid,
        u,
        lambda k: _solve_levels(normal_cdf(u), nx, ny, vals, k.astype(np.float64))[1],
        ring_idx,
        shape,
        least=occluder_group(s),
    )
    if found is None:
        keep = np.ones(vals.size, bool)
    else:
        keep = found[0]
        coef, resid = _solve_levels(normal_cdf(u), nx, ny, vals, keep.astype(np.float64))
    pdf = np.exp(-0.5 * u * u) * INV_SQRT_2PI
    FB = (coef[3] - coef[0]) + (coef[4] - coef[1]) * nx + (coef[5] - coef[2]) * ny
    band = keep & in_edge_zone(u)
    gs = -(FB * pdf / s) * u
    den_s = float(np.sum(gs[band] ** 2))
    if den_s > 0:
        s = bounded_edge_width(s + float(np.sum(gs[band] * resid[band])) / den_s, s)
    return keep, coef, s


def edge_points(
    image, cx, cy, radius, *, edge_width=1.2, radial_shape=None, patch: MarkerPatch | None = None
) -> EdgePoints:
    """Sub-pixel edge points around a circle estimate.

    Parameters
    ----------
    image : numpy.ndarray
        2-D grey image indexed ``[y, x]`` (DN); unused when `patch` is given.
    cx, cy : float
        Current centre estimate (px).
    radius : float
        Current radius estimate (px).
    edge_width : float
        Current edge width s (px).
    radial_shape : callable, optional
        ``radial_shape(psi) -> R(psi)``: the edge's distance from the centre in
        direction psi (rad, image axes), for elliptical markers; a circle of
        `radius` when None.
    patch : MarkerPatch, optional
        Pixels around the marker from :func:`marker_patch`, reused between
        iterations; taken from `image` when None.

    Returns
    -------
    EdgePoints

    Raises
    ------
    FitError
        The ring leaves the image, the marker has no contrast, or too few sectors
        carry information.
    """
    s = float(edge_width)
    reach = 3.0 * s + 2.5
    if patch is None:
        patch = marker_patch(image, cx, cy, radius + reach + OUTER_EXTRA_PX + 1)
    dx_all, dy_all = patch.xs - cx, patch.ys - cy
    d_all = np.sqrt(dx_all * dx_all + dy_all * dy_all)
    if radial_shape is None:
        # 3 px more background than interior: the background plane's tilt is then
        # pinned by pixels away from the edge instead of trading off against its
        # position (centre scatter 1.06x -> 1.01x the Cramér-Rao bound)
        ring = (d_all > radius - reach) & (d_all < radius + reach + OUTER_EXTRA_PX)
    else:
        r_dir = radial_shape(np.linspace(0.0, np.pi, 32))
        ring = (d_all > r_dir.min() - reach) & (d_all < r_dir.max() + reach + OUTER_EXTRA_PX)
    if ring.sum() < 30:
        raise FitError("too few pixels around the marker's edge")
    ring_idx = np.flatnonzero(ring)
    dx, dy, d, vals = dx_all[ring_idx], dy_all[ring_idx], d_all[ring_idx], patch.values[ring_idx]
    psi = np.arctan2(dy, dx)
    R = radius if radial_shape is None else radial_shape(psi)
    nx, ny = dx / radius, dy / radius
    keep, coef, s = _first_pass((R - d) / s, s, nx, ny, vals, ring_idx, patch.shape)
    # pass 2: levels with the new width, without the outliers; light multiplies
    # reflectance, so one illumination gradient serves inside and outside
    u = (R - d) / s
    kappa = coef[3] / coef[0] if coef[0] != 0 else None
    coef, resid = _solve_levels(normal_cdf(u), nx, ny, vals, keep.astype(np.float64), kappa=kappa)
    FB = (coef[3] - coef[0]) + (coef[4] - coef[1]) * nx + (coef[5] - coef[2]) * ny
    g = FB * (np.exp(-0.5 * u * u) * INV_SQRT_2PI) / s  # dI/dR
    band = keep & in_edge_zone(u)
    contrast = coef[3] - coef[0]
    dof = max(int(keep.sum()) - 7, 1)
    sigma2 = float(np.sum(resid[keep] ** 2) / dof)
    check_contrast(contrast, sigma2)
    sector, n_sec = sector_index(psi, radius)
    # A sector that lost pixels to the outlier cut (a wire or speck on the edge) is
    # biased by what remains of the occluder's blurred flank: drop it and its two
    # neighbours on each side rather than let it pull the circle.
    lost = lost_sectors(sector[~keep & in_edge_zone(u)], n_sec)
    gb, pb = g[band], psi[band]
    delta, ang, info = sector_edge_offsets(
        sector[band], n_sec, gb, resid[band], gb * np.cos(pb), gb * np.sin(pb), drop=lost
    )
    Rk = radius if radial_shape is None else radial_shape(ang)
    rho = Rk + delta
    std = np.sqrt(sigma2 / info)
    return EdgePoints(
        x_px=cx + rho * np.cos(ang),
        y_px=cy + rho * np.sin(ang),
        std_px=std,
        noise_dn=float(np.sqrt(sigma2)),
        edge_width_px=s,
        background_dn=float(coef[0]),
        foreground_dn=float(coef[3]),
        n_pixels=int(keep.sum()),
    )
