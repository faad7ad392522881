"""Sub-pixel edge points of a circular marker from an edge-profile model.

Pixel-level edges (Canny) quantise the edge to the pixel grid and use one pixel per
edge sample; a centre fitted to them is several times less precise than the image
allows. Here every pixel near the edge contributes, weighted by how much it says
about the edge position.

Model (per marker, in a ring of pixels around the current circle estimate)::

    I(p) = B(p) + (F(p) - B(p)) · Φ((R - d(p)) / s)

with d(p) the distance of pixel p from the current centre, Φ the standard normal
distribution function, s the edge width (PSF σ combined with the pixel's own
width, s² ≈ σ² + 1/12), and B, F the grey levels outside and inside the marker,
each a plane across the marker so that illumination gradients do not pull the edge.

1. B and F (six plane coefficients) are solved by linear least squares, with a
   second pass that drops outlying pixels (a wire or a speck crossing the ring).
2. The ring is cut into angular sectors about 1 px of arc wide; sectors where the
   outlier cut removed pixels (and two neighbours each side) are dropped. In sector k the
   edge's radial offset δₖ is the one-step Gauss-Newton (maximum-likelihood)
   estimate ``δₖ = Σ gᵢ eᵢ / Σ gᵢ²`` with eᵢ the model residual and gᵢ = ∂I/∂R
   = (F - B)·φ(uᵢ)/s; its variance is σ²/Σ gᵢ² with σ² the residual variance. The
   edge point lies at R + δₖ along the sector's (g²-weighted) mean direction.
3. Before the sectors, s is updated by a Gauss-Newton step on the same model and
   the levels solved again with it.

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
from scipy.special import ndtr

from .errors import FitError

__all__ = ["EdgePoints", "marker_roi", "edge_points"]

_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)


@dataclass(frozen=True)
class EdgePoints:
    """Sub-pixel edge points of one marker.

    Attributes
    ----------
    x, y : numpy.ndarray
        Edge points (px).
    std : numpy.ndarray
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

    x: np.ndarray
    y: np.ndarray
    std: np.ndarray
    noise_dn: float
    edge_width_px: float
    background_dn: float
    foreground_dn: float
    n_pixels: int


def marker_roi(shape, cx, cy, extent):
    """Bounds (x0, y0, x1, y1) of the square of half-size `extent` around (cx, cy), or None if it leaves the image."""
    h, w = shape
    x0, x1 = int(np.floor(cx - extent)), int(np.ceil(cx + extent)) + 1
    y0, y1 = int(np.floor(cy - extent)), int(np.ceil(cy + extent)) + 1
    if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
        return None
    return x0, y0, x1, y1


def edge_points(image, cx, cy, radius, *, edge_width=1.2, radial_shape=None) -> EdgePoints:
    """Sub-pixel edge points around a circle estimate.

    Parameters
    ----------
    image : numpy.ndarray
        2-D grey image indexed ``[y, x]`` (DN).
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
    reach = 3.0 * s + 4.0
    roi = marker_roi(image.shape, cx, cy, radius + reach + 1)
    if roi is None:
        raise FitError("the marker's edge ring leaves the image")
    x0, y0, x1, y1 = roi
    patch = image[y0:y1, x0:x1]
    gx = np.arange(x0, x1, dtype=np.float64) - cx
    gy = np.arange(y0, y1, dtype=np.float64) - cy
    d_all = np.sqrt(gx[None, :] ** 2 + gy[:, None] ** 2)
    if radial_shape is None:
        ring = np.abs(d_all - radius) < reach
    else:
        r_dir = radial_shape(np.linspace(0.0, np.pi, 32))
        ring = (d_all > r_dir.min() - reach) & (d_all < r_dir.max() + reach)
    iy, ix = np.nonzero(ring)
    dx, dy, d = gx[ix], gy[iy], d_all[iy, ix]
    vals = patch[iy, ix].astype(np.float64)
    psi = np.arctan2(dy, dx)
    R = radius if radial_shape is None else radial_shape(psi)
    nx, ny = dx / radius, dy / radius
    keep = np.ones(vals.size, dtype=bool)
    for step in range(3):
        u = (R - d) / s
        Phi = ndtr(u)
        design = np.stack([1 - Phi, (1 - Phi) * nx, (1 - Phi) * ny, Phi, Phi * nx, Phi * ny], axis=1)
        dk = design[keep]
        try:
            coef = np.linalg.solve(dk.T @ dk, dk.T @ vals[keep])
        except np.linalg.LinAlgError as exc:
            raise FitError("the marker's grey levels cannot be separated (no edge in the ring)") from exc
        resid = vals - design @ coef
        sig = float(np.sqrt(np.mean(resid[keep] ** 2))) or 1e-6
        if step == 0:
            # drop pixels beyond 4.5 sigma (a wire or a speck in the ring)
            keep = np.abs(resid) < 4.5 * sig
            continue
        B = coef[0] + coef[1] * nx + coef[2] * ny
        F = coef[3] + coef[4] * nx + coef[5] * ny
        pdf = np.exp(-0.5 * u * u) * _INV_SQRT_2PI
        g = (F - B) * pdf / s  # dI/dR
        band = keep & (np.abs(u) < 3.0)
        if step == 2:
            break
        # one Gauss-Newton step for the edge width s (dI/ds = -(F - B)·φ(u)·u/s)
        gs = -g * u
        den_s = float(np.sum(gs[band] ** 2))
        if den_s > 0:
            # an imaged edge is never sharper than the pixel's own width (s >= sqrt(1/12))
            s = float(np.clip(s + float(np.sum(gs[band] * resid[band])) / den_s, max(0.5 * s, 0.3), 2.0 * s))
    contrast = coef[3] - coef[0]
    dof = max(int(keep.sum()) - 7, 1)
    sigma2 = float(np.sum(resid[keep] ** 2) / dof)
    if not abs(contrast) > 3.0 * np.sqrt(sigma2):
        raise FitError(f"marker edge has too little contrast ({contrast:.1f} DN against noise {np.sqrt(sigma2):.1f} DN)")
    n_sec = max(24, int(round(2 * np.pi * radius)))
    sector = ((psi + np.pi) * (n_sec / (2 * np.pi))).astype(np.int64) % n_sec
    # A sector that lost pixels to the outlier cut (a wire or speck on the edge) is
    # biased by what remains of the occluder's blurred flank: drop it and its two
    # neighbours on each side rather than let it pull the circle.
    lost = np.bincount(sector[~keep & (np.abs(u) < 3.0)], minlength=n_sec) > 0
    if lost.mean() > 0.25:
        # that many is the model not fitting the edge yet (a first iteration, a
        # sharp or odd edge profile), not occlusion: keep the sectors, the circle
        # fit's own outlier rejection still applies
        lost[:] = False
    elif lost.any():
        lost = np.convolve(np.concatenate([lost[-2:], lost, lost[:2]]).astype(int), np.ones(5, int), "valid") > 0
    k = sector[band]
    gb, eb, pb = g[band], resid[band], psi[band]
    g2 = gb * gb
    den = np.bincount(k, g2, minlength=n_sec)
    num = np.bincount(k, gb * eb, minlength=n_sec)
    cs = np.bincount(k, g2 * np.cos(pb), minlength=n_sec)
    sn = np.bincount(k, g2 * np.sin(pb), minlength=n_sec)
    good = (den > 0.1 * np.median(den[den > 0]) if np.any(den > 0) else den > 0) & ~lost
    if good.sum() < 12:
        raise FitError(f"only {int(good.sum())} edge sectors carry information (need 12)")
    delta = num[good] / den[good]
    ang = np.arctan2(sn[good], cs[good])
    Rk = radius if radial_shape is None else radial_shape(ang)
    rho = Rk + delta
    std = np.sqrt(sigma2 / den[good])
    return EdgePoints(
        x=cx + rho * np.cos(ang),
        y=cy + rho * np.sin(ang),
        std=std,
        noise_dn=float(np.sqrt(sigma2)),
        edge_width_px=s,
        background_dn=float(coef[0]),
        foreground_dn=float(coef[3]),
        n_pixels=int(keep.sum()),
    )
