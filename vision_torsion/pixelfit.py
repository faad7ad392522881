"""Maximum-likelihood fit of the imaged-disc model to a marker's pixels (the default fit).

The paper fits a circle to edge points. Edge points are a summary of the pixels, and
every summary loses something: the coupling between the centre, the radius, the
edge width and the grey levels, and the binning of the edge into sectors. Here the
model of the image itself is fitted to the pixels, which is the maximum-likelihood
estimate under Gaussian pixel noise and reaches the Cramér-Rao bound of the model.

Model, for every pixel p of a ring around the edge::

    I(p) = L(p) · [B + (F - B) · Φ((R - d(p)) / s)],    L(p) = 1 + gx·nx + gy·ny

with d(p) the distance of the pixel centre from the marker centre (cx, cy), Φ the
standard normal distribution function, s the edge width (PSF σ combined with the
pixel's own width, s² ≈ σ² + 1/12), B and F the grey levels outside and inside the
marker, and L an illumination gradient over the marker: light multiplies
reflectance, so one gradient serves inside and outside. (nx, ny) is the pixel's
offset from the starting centre divided by the starting radius: a fixed frame, so
the lighting plane does not move with the centre.

The eight parameters (cx, cy, R, s, B, F, gx, gy) are fitted jointly by
Levenberg-Marquardt with the analytic Jacobian; their covariance is σ²(JᵀJ)⁻¹ with
σ² the residual variance. That assumes the pixels' errors independent. A JPEG's
are not: each 8x8 block of pixels is quantised as a whole (its high spatial
frequencies, where much of the white sensor noise lies, set to zero), so the error
left is smooth within a block and independent between blocks, and σ²(JᵀJ)⁻¹ is too
small for the smooth weights a centre gives its ring (the centres' scatter was
1.3x the reported σ at quality 90, 1.75x at 75, on a 130 px marker). Given the
block size (``block_px``: the decoder knows it), the covariance is the
cluster-robust (sandwich) one over the blocks the ring covers,
(JᵀJ)⁻¹ (Σ_blocks g gᵀ) (JᵀJ)⁻¹ with g = Σ_block J·r, times the small-sample factor
G/(G-1)·(n-1)/(n-8) (G blocks, n pixels); it is σ²(JᵀJ)⁻¹ in expectation when the
errors are white (scatter/σ 1.04, 1.03 and 0.99 without JPEG, at quality 90 and
75 on the marker above). A ring whose centre is informed by fewer than
:data:`MIN_BLOCKS` blocks (counted by their shares of the information, (Σw)²/Σw²:
the blocks along the edge; markers under ~30 px radius), whose few g gᵀ would
give a covariance as uncertain as the correction, takes the sandwich
(JᵀJ)⁻¹ JΩJᵀ (JᵀJ)⁻¹ of a noise model instead: independent between blocks, and
within one a covariance Ω that depends on the lag between two pixels only, its
values the residuals' mean products at each lag over all the blocks along the
edge, corrected for what the fit absorbs of them (:func:`_lag_covariance`).
On rendered rings of markers of 5-30 px radius at quality 75-95 the centres'
scatter is then 0.9-1.1x their σ (1.2-1.7x with σ²(JᵀJ)⁻¹;
``benchmarks/bench_jpeg_sigma.py``).
The fit converges once a step moves the centre by less than 1e-3 px and the edge
width by less than 0.01 px. The ring of pixels is the edge zone ±3s, 0.5 px more
inside and 7.5 px more of background, which pins the lighting plane away from the
edge. It is chosen once, around the start, 0.5 px wider each side for the start's
error.

Robustness: once the centre has settled (a step under 0.05 px), pixels more than
4.5 robust σ off the model in connected groups as wide as the blur (π·s² pixels: a
wire or a speck crossing the ring; lone pixels are the noise's tail) that the edge
moved or widened there does not account for (a band along the edge is the edge's
own shape: interlace, sharpening, ringing) are cut. As in
:mod:`.edges`, the cut is made twice (the second time against grey levels solved
without the first cut, so that the occluder's pull does not select ordinary pixels
by their values), grown by 2 px over the occluder's blurred flanks, and the edge
pixels of the affected angular sectors (~1 px of arc, and two neighbours each side)
are dropped. The fit then continues on the rest, and once it has converged the
whole ring is examined again (three times at most): a fit pulled by an occluder
hides part of it. Under a steep lighting gradient (more than 4 % of the light per
radius; markers' own light varies far less) the gradient may have taken up a region
as dark as the marker within a few px of its edge, spreading its misfit over the
ring so that nothing looks outlying: the ring is then examined against levels
solved robustly, that region is cut, and the fit is flagged (``steep_cut``).

Coordinates are image pixels (x, y), origin at the centre of the top-left pixel,
y downwards.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from itertools import accumulate

import cv2
import numpy as np

from .errors import FitError
from .ring import (
    EDGE_ZONE,
    INV_SQRT_2PI,
    OCCLUDER_SIGMAS,
    MarkerPatch,
    bounded_edge_width,
    check_contrast,
    check_radius,
    cut_occluders,
    damped_normal_matrix,
    fast_median,
    in_edge_zone,
    lost_sectors,
    marker_patch,
    normal_cdf,
    nothing_to_cut,
    occluder_group,
    occluder_groups,
    robust_sigma,
    robust_sigma_rows,
    sector_count,
    sector_index,
    sectors_needed,
    solve_lu,
)

__all__ = ["DiscFit", "fit_disc", "fit_discs", "MIN_BLOCKS", "BACKGROUND_SECTORS", "UNEVEN_BACKGROUND"]

#: Centre step (px) below which the fit counts as settled and outliers are first looked for.
_SETTLED_PX = 0.05
#: Ring beyond the edge zone ±3s (px). Inside, the marker's pixels only inform its
#: level, which is not correlated with the centre. Outside, they also pin the
#: lighting gradient, which is (a tilt of the levels mimics a shift): 7.5 px puts the
#: centre's RMS within 4 % of the maximum-likelihood reference of
#: ``benchmarks/bench_peers.py``, each 2 px more costing ~15 % more pixels.
_INNER_PX = 0.5
_OUTER_PX = 7.5
#: Extra ring width (px) each side for the start's error (the intensity centroid
#: of :func:`vision_torsion.markers.fit_marker` is good to ~0.1 px).
_START_MARGIN_PX = 0.5
#: A cut whose pixels lie (this share of them) in the edge zone and along more than
#: this fraction of the edge's sectors is the edge itself not being the model's
#: profile there (interlaced fields, motion smear, a sharpening halo on one side),
#: not an occluder, and is not made. An occluder is another object in the ring: a
#: wire crosses the whole ring (about half its cut pixels in the edge zone), a
#: speck covers a short arc.
_MISFIT_EDGE_SHARE = 0.9
_MISFIT_ARC = 0.25
#: Lighting gradient |(gx, gy)| (relative change of the light per starting radius)
#: above which a ring is examined for an occluder with robustly solved levels
#: (:func:`_robust_level_residuals`) even when no pixel is beyond 4.5 robust σ. A
#: darker surround (a card's edge, a shadow) within a few px of a marker's edge is
#: taken up by the gradient, which spreads its misfit over the whole ring so that
#: nothing looks outlying while the centre moves by tenths of a pixel. A marker's
#: own light varies far less over it (at most 0.02 on the rendered scenes, 0.05 on
#: the photographed dots of ``benchmarks/bench_photos.py``).
_STEEP_LIGHT = 0.04
#: Iterations of the Tukey-weighted (c = 4.685 robust σ) solution of the levels.
_ROBUST_LEVEL_ITER = 6
#: Markers fitted together by :func:`fit_discs` at most (more are fitted in groups).
_BATCH = 64
#: Elements (float64) of one block of rows :func:`_evaluate_rows` evaluates at a
#: time: its temporaries stay under 64 kB, which glibc's malloc serves from its
#: free lists and never hands back to the system (larger ones are mapped afresh
#: or trimmed off the heap top, and each page touched again is a page fault).
_BLOCK = 6000
#: Largest scratch array (bytes) :class:`_Scratch` keeps for the next call.
_KEEP_BYTES = 64 << 20
#: Centre step (px) that ends the fit, once the edge width's step is below
#: :data:`_WIDTH_CONVERGED_PX` too. Levenberg-Marquardt converges about
#: quadratically here, so what remains after such a step is far below it.
_CONVERGED_PX = 1e-3
#: Edge-width step (px) below which the width counts as settled. The centre hardly
#: depends on the width, so it may settle first (from a start at the right centre
#: it does at once), and a fit that ended there left widths 0.07-0.55 px off and
#: edge residuals 1.7-2.3x the right ones. 0.01 px: on the standard scene it
#: adds a model evaluation to one marker in twenty (1e-3 px, to every other one)
#: and leaves the width within 0.012 px of a start at the right width on 130 px
#: JPEG'd markers.
_WIDTH_CONVERGED_PX = 0.01
#: Fewest compression blocks that must inform a marker's centre for its covariance
#: to be the block-robust one (``block_px`` of :func:`fit_disc`): the sandwich
#: estimate's relative spread is about sqrt(2/G) (G blocks), 26 % in variance at
#: 30. A marker has about as many along its edge as its radius in px.
MIN_BLOCKS = 30
#: Sectors of direction whose background residuals :attr:`DiscFit.background_step_dn`
#: compares: the eight octants, so that a step through or beside the centre, at any
#: direction, leaves whole sectors on each side of it.
BACKGROUND_SECTORS = 8
#: Fewest background pixels a sector needs for that figure (the mean of 10 noisy
#: pixels scatters by 0.3 of their σ).
_MIN_SECTOR_PX = 10
#: Pixels of a ring (about) that :attr:`DiscFit.background_step_dn` samples at most
#: (some 40 background pixels an octant: their mean scatters by 0.16 of their σ).
_BACKGROUND_SAMPLE = 600
#: Share of the marker's contrast |F - B| that :attr:`DiscFit.background_step_dn` must
#: exceed for :attr:`DiscFit.lighting_shift_px` to be computed: the background under
#: lighting the model follows leaves under 0.023 of the contrast on rendered grids
#: (even, falloff, vignetting, blur) and a median of 0.009-0.031 on the eleven
#: photographs of ``benchmarks/bench_photos.py``; the shadow edges that moved
#: rendered centres by over 0.1 px left 0.09-0.85 (``benchmarks/bench_light_edge.py``),
#: the GoPro dot 0.57 px off 0.19. Below 0.1 the curved lighting's terms, odd about
#: the centre, take up an uneven print or optics around a photographed dot instead
#: (a move of 0.3-0.6 px on UCL right 0's dots of 15 px radius at 0.05-0.09).
UNEVEN_BACKGROUND = 0.1


def patch_extent(radius, edge_width) -> float:
    """Half-size (px) of the square of pixels a fit around a circle of `radius` (px)
    needs: its ring, at an edge width up to 1.5 px (or `edge_width`), with 3 px to
    spare."""
    return radius + 3.0 * max(edge_width, 1.5) + _OUTER_PX + _START_MARGIN_PX + 3.0


@dataclass(frozen=True)
class DiscFit:
    """The fitted disc model of one marker.

    Attributes
    ----------
    x_px, y_px : float
        Centre (px).
    radius_px : float
        Radius of the edge (px).
    edge_width_px : float
        Edge width s (px).
    cov : numpy.ndarray
        3x3 covariance of (x_px, y_px, radius_px) (px²).
    noise_dn : float
        Residual RMS of the pixel model (DN).
    background_dn, foreground_dn : float
        Grey levels outside and inside the marker at the starting centre (DN).
    n_pixels : int
        Pixels used by the final fit.
    edge_x_px, edge_y_px : numpy.ndarray
        Edge points per angular sector (~1 px of arc): where the pixels of that
        sector alone put the edge, given the fitted model (px). A diagnostic of the
        edge's shape, not used by the fit.
    residual_rms_px : float
        RMS radial distance of those edge points from the fitted circle (px).
    circularity : float
        1 - 2·|second radial harmonic of those edge points|/R: the minor/major axis
        ratio of a near-circle.
    edge_noise_px : float
        RMS standard deviation of those edge points from the pixel noise alone (px):
        √(mean σ²/Σg²) over the sectors, Σg² a sector's information and σ² the
        residual variance of the ring's pixels away from the edge (more than 3s from
        it), which a marker's shape leaves alone (all the ring's, if fewer than 30).
        About what `residual_rms_px` would be for an edge the model fits exactly
        (1.2-1.8 times it on the round dots of the discorpy photos: JPEG, printing);
        the rest is the edge's shape.
    steep_cut : bool
        Pixels were cut from the ring under a steep lighting gradient
        (:data:`_STEEP_LIGHT`): a surround as dark as the marker (a card's edge, a
        shadow) within a few px of its edge. The centre is then good to 0.4 px
        (:data:`vision_torsion.quality.STEEP_CUT_PX`), not to its covariance.
    background_step_dn : float
        How uneven the background around the marker is beyond the fitted lighting
        gradient (DN): the spread (largest minus smallest) of the mean residuals of
        the ring's background pixels (beyond the edge zone, neighbours' and cut pixels
        left out) in the :data:`BACKGROUND_SECTORS` octants of direction about the
        centre.
        A light or shadow edge across the marker, which the linear gradient cannot
        follow, leaves a band of residuals along it. Sectors with fewer than
        :data:`_MIN_SECTOR_PX` such pixels are left out; NaN when half of them are.
    lighting_shift_px, lighting_shift_std_px : float
        When that spread exceeds :data:`UNEVEN_BACKGROUND` of the contrast |F - B|:
        how far (px) the centre moves under the lighting the ring's pixels away
        from the edge zone show when it may also curve, quadratically and with a
        gradient that changes with the distance from the centre
        (:func:`_lighting_shift`), and that move's standard deviation from the
        pixel noise (px); else NaN. A lighting the model follows leaves it at the
        noise's level; a shadow's or a light's edge across the marker leaves the
        centre 0.5-2.2 times that move off (5-95 %; rendered markers of 8-35 px
        radius, edges 0-30 px wide 0-45 px from the centre,
        ``benchmarks/bench_light_edge.py``), a hard edge near the marker's rim
        a quarter of it (0.13 px for a move of 0.57 px).
    """

    x_px: float
    y_px: float
    radius_px: float
    edge_width_px: float
    cov: np.ndarray
    noise_dn: float
    background_dn: float
    foreground_dn: float
    n_pixels: int
    edge_x_px: np.ndarray
    edge_y_px: np.ndarray
    residual_rms_px: float
    circularity: float
    edge_noise_px: float = float("nan")
    steep_cut: bool = False
    background_step_dn: float = float("nan")
    lighting_shift_px: float = float("nan")
    lighting_shift_std_px: float = float("nan")


class _Pixels:
    """The ring's pixels as flat float64 arrays (a subset of a :class:`MarkerPatch`)."""

    def __init__(self, patch: MarkerPatch, index, x0, y0, r0):
        self.index = index
        self.xs, self.ys = patch.coordinates(index)
        self.vals = patch.values.take(index)
        # in place: the same values as (xs - x0) / r0, one array less each
        self.nx = np.subtract(self.xs, x0)
        self.nx /= r0
        self.ny = np.subtract(self.ys, y0)
        self.ny /= r0

    def subset(self, keep):
        out = object.__new__(_Pixels)
        for name in ("index", "xs", "ys", "vals", "nx", "ny"):
            setattr(out, name, getattr(self, name)[keep])
        return out


def _evaluate(p, px, J=None):
    """Residuals, Jacobian (8 x N) and the edge coordinate u = (R - d)/s at `p`.

    Written with few array passes and in place: a marker's ring has a few thousand
    pixels, where each numpy call costs about as much as its arithmetic.

    `px` holds one marker's pixels (flat arrays of N) or many markers' (rows of N,
    padded; then `p` holds (M, 1) columns, and the Jacobian is 8 x M x N, written
    into `J` when given).
    """
    cx, cy, R, s, B, F, gx, gy = p
    J = np.empty((8,) + px.xs.shape) if J is None else J
    dx, dy = J[0], J[1]  # filled with the centre derivatives at the end
    np.subtract(px.xs, cx, out=dx)
    np.subtract(px.ys, cy, out=dy)
    d = cv2.magnitude(dx, dy).reshape(dx.shape)
    u = d * (-1.0 / s)
    u += R / s
    gauss = np.square(u, out=J[3])
    gauss *= -0.5
    # OpenCV's vectorised exp: numpy's to an ulp (4e-16), in a sixth of the time
    # (it was a fifth of a model evaluation)
    cv2.exp(gauss, gauss)
    Phi = normal_cdf(u, gauss)
    M = Phi * (F - B)
    M += B
    if not isinstance(gx, np.ndarray) and gx == 0.0 and gy == 0.0:
        # flat lighting (a fit's start): L = nx·0 + ny·0 + 1 is exactly 1
        L = 1.0
        resid = px.vals - M
    else:
        L = px.nx * gx
        L += px.ny * gy
        L += 1.0
        resid = px.vals - L * M
    g = np.multiply(L, gauss, out=J[2])  # dI/dR
    g *= (F - B) * INV_SQRT_2PI / s
    np.maximum(d, 1e-9, out=d)
    np.divide(g, d, out=d)  # d is not needed any more: g/d
    dx *= d  # dI/dcx
    dy *= d  # dI/dcy
    np.multiply(g, u, out=J[3])
    np.negative(J[3], out=J[3])  # dI/ds
    np.multiply(L, Phi, out=J[5])  # dI/dF
    np.subtract(L, J[5], out=J[4])  # dI/dB
    np.multiply(px.nx, M, out=J[6])  # dI/dgx
    np.multiply(px.ny, M, out=J[7])  # dI/dgy
    return resid, J, u


def _ring(patch: MarkerPatch, cx, cy, R, s, margin=0.0):
    """Indices of the patch pixels of the ring: from 3s + 0.5 px inside the edge to
    3s + 7.5 px outside it (the edge zone ±3s, and background pixels that pin the
    lighting gradient), `margin` px wider each side."""
    d2 = patch.squared_distance(cx, cy)
    inner = max(R - 3.0 * s - _INNER_PX - margin, 0.0)
    outer = R + 3.0 * s + _OUTER_PX + margin
    inside = (d2 > inner * inner) & (d2 < outer * outer)
    if patch.excluded is not None:
        inside &= ~patch.excluded  # a neighbouring marker's pixels
    index = np.flatnonzero(inside)
    if index.size < 30:
        raise FitError("too few pixels around the marker's edge")
    return index


def _start_levels(px: _Pixels, cx, cy, R, s):
    """B, F and the lighting gradient by linear least squares at a fixed circle."""
    Phi = normal_cdf((R - np.hypot(px.xs - cx, px.ys - cy)) / s)
    design = np.stack([1.0 - Phi, Phi, px.nx, px.ny])
    try:
        B, F, ax, ay = np.linalg.solve(design @ design.T, design @ px.vals)
    except np.linalg.LinAlgError as exc:
        raise FitError("the marker's grey levels cannot be separated (no edge in the ring)") from exc
    level = 0.5 * (B + F) if B + F != 0 else 1.0
    return B, F, ax / level, ay / level


def _sectors(xs, ys, cx, cy, R):
    """Angular sector (~1 px of arc) of each pixel, and the number of sectors."""
    return sector_index(np.arctan2(ys - cy, xs - cx), R)


def _steep(p):
    """True when the lighting gradient of the parameters `p` (8, or rows of them:
    flags per row) exceeds :data:`_STEEP_LIGHT`."""
    return np.hypot(p[..., 6], p[..., 7]) > _STEEP_LIGHT


def _robust_level_residuals(p, resid, J, u):
    """The residuals (DN) with the levels (B, F, gx, gy) solved robustly at the
    geometry of `p`: from no lighting gradient and B, F at the medians of the
    background and the inside (`u`: the pixels' edge coordinates), Tukey's
    biweight (c = 4.685 robust σ, :data:`_ROBUST_LEVEL_ITER` reweightings) on the
    model linearised in the levels (`J`'s rows 4-7, `resid` the least-squares
    residuals). A darker surround that the gradient took up then stands out as the
    outlying group it is (:data:`_STEEP_LIGHT`)."""
    lev = J[4:8]
    r = resid + p[6] * J[6] + p[7] * J[7]  # the gradient taken out
    # the levels moved to the medians of the background beyond the edge zone and of
    # the inside (a surround may hold a quarter of the background: a mean would
    # follow it)
    outside, inside = u <= -EDGE_ZONE, u >= EDGE_ZONE
    if np.count_nonzero(outside) >= 8:
        r -= fast_median(r[outside]) * J[4]
    if np.count_nonzero(inside) >= 8:
        r -= fast_median(r[inside]) * J[5]
    for _ in range(_ROBUST_LEVEL_ITER):
        t = r / (4.685 * robust_sigma(r))
        w = np.square(np.maximum(1.0 - t * t, 0.0))
        lw = lev * w
        try:
            r = r - np.linalg.solve(lw @ lev.T, lw @ r) @ lev
        except np.linalg.LinAlgError:
            break
    return r


def _steep_surround(p, px: _Pixels, patch: MarkerPatch, resid, J, u):
    """Flags of the ring's pixels to keep, or None: under a steep lighting gradient
    (:func:`_steep`), the pixels away from the edge zone that lie beyond 4.5 robust σ
    of robustly solved levels (:func:`_robust_level_residuals`) in connected groups
    of an occluder's size (:func:`~vision_torsion.ring.occluder_group`): a darker
    surround the gradient took up. Only those are cut here; with them gone the
    gradient no longer hides the rest, which the next examination cuts as any
    occluder (:func:`~vision_torsion.ring.cut_occluders`) from a fit no longer
    pulled by it."""
    r = _robust_level_residuals(p, resid, J, u)
    sigma = robust_sigma(r)
    keep = (np.abs(r) < OCCLUDER_SIGMAS * sigma) | in_edge_zone(u)
    if keep.all():
        return None
    keep = occluder_groups(keep, r, sigma, u, px.index, patch.shape, occluder_group(p[3]))[0]
    return None if keep.all() else keep


def _cut_outliers(p, px: _Pixels, patch: MarkerPatch, resid, J, u):
    """Flags of the pixels to keep, or None: the occluder cut of
    :func:`~vision_torsion.ring.cut_occluders`, and the edge pixels of the sectors
    it touched; None when the outlying pixels it saw lie along much of the edge
    (the edge's own misfit). `resid`, `J`, `u` are the model at `p`; under a steep
    lighting gradient (:func:`_steep`) a darker surround is cut first
    (:func:`_steep_surround`)."""

    def resolve(keep):
        # a Gauss-Newton step of the levels alone, without the cut pixels
        lev = J[4:8, keep]
        return resid - np.linalg.solve(lev @ lev.T, lev @ resid[keep]) @ J[4:8]

    if _steep(p):
        surround = _steep_surround(p, px, patch, resid, J, u)
        if surround is not None:
            return surround
    try:
        found = cut_occluders(resid, u, resolve, px.index, patch.shape, least=occluder_group(p[3]))
    except np.linalg.LinAlgError:
        return None
    if found is None:
        return None
    keep, seen = found
    # sectors of the edge zone's pixels only: the rest of the ring has none
    zone = np.flatnonzero(in_edge_zone(u))
    sector, n_sec = _sectors(px.xs[zone], px.ys[zone], p[0], p[1], p[2])
    seen_edge = ~seen[zone]
    # distinct sectors counted with bincount: np.unique imports numpy.ma (0.1-0.2 s) on first use
    if (
        np.count_nonzero(seen_edge) >= _MISFIT_EDGE_SHARE * np.count_nonzero(~seen)
        and np.count_nonzero(np.bincount(sector[seen_edge], minlength=n_sec)) > _MISFIT_ARC * n_sec
    ):
        # the edge's own misfit along much of its length (judged on every group it
        # showed, those the edge moved there accounts for too), not an occluder:
        # keep all
        return None
    cut_edge = ~keep[zone]
    # the cut was made against a settled fit, so even a wire lying along the edge
    # for 90° of arc (~40 % of the sectors with their neighbours) is occlusion
    lost = lost_sectors(sector[cut_edge], n_sec, most=0.5)
    keep[zone[lost[sector]]] = False  # keep is cut_occluders' own array
    if np.count_nonzero(np.bincount(sector[keep[zone]], minlength=n_sec)) < max(16, n_sec // 2):
        # a cut grown by 2 px each side takes much of a small marker's edge: on a
        # 3-5 px disc (16-31 sectors) that is JPEG ringing or pixelation, not an
        # occluder to cut (the diagnostics need 12 sectors with edge pixels)
        return None
    return keep


def _examine(p, ring: _Pixels, patch: MarkerPatch, resid, J, u):
    """One examination of the whole ring for an occluder, at the parameters `p`
    (`resid`, `J`, `u`: the model there on all of `ring`'s pixels): the flags of
    the pixels to keep (:func:`_cut_outliers`; None: all), and whether they were
    cut under a steep lighting gradient (:attr:`DiscFit.steep_cut`). A ring with
    nothing beyond 4.5 robust σ (most) is not examined further."""
    steep = bool(_steep(p))
    keep = None if not steep and nothing_to_cut(resid) else _cut_outliers(p, ring, patch, resid, J, u)
    return keep, keep is not None and steep


def _last_examination(cuts, keep, new_keep) -> bool:
    """True when the examination number `cuts` (1, 2, ...) ends the examining: the
    third, or one that changed nothing (`keep`, `new_keep`: the flags of the pixels
    kept before and after it, None for all)."""
    if keep is None or new_keep is None:
        return cuts == 3 or (keep is None and new_keep is None)
    return cuts == 3 or np.array_equal(keep, new_keep)


def _background_steps(P, xs, ys, resid, u, valid=None) -> np.ndarray:
    """:attr:`DiscFit.background_step_dn` of each row of fits `P` (M x 8) from their
    pixels' image coordinates `xs`, `ys` (px), residuals `resid` (DN) and edge
    coordinates `u` (rows of N; `valid`: flags of a row's pixels, not its padding):
    the spread of the mean residual of the background pixels (u <= -3, beyond the
    edge zone) over the eight octants of direction about the centre, of the
    octants with :data:`_MIN_SECTOR_PX` of them at least (NaN when fewer than half
    have: a neighbour or a cut took the rest); rings wider than about
    :data:`_BACKGROUND_SAMPLE` pixels sampled evenly. All rows at once, in a few
    array passes: a photograph's grid has hundreds of small markers."""
    # a large marker's ring (thousands of pixels) is sampled: every k-th pixel,
    # spread over the ring in raster order, leaves each octant some hundreds
    step = max(1, xs.shape[1] // _BACKGROUND_SAMPLE)
    if step > 1:
        xs, ys, resid, u = xs[:, ::step], ys[:, ::step], resid[:, ::step], u[:, ::step]
        valid = None if valid is None else valid[:, ::step]
    m = xs.shape[0]
    # the octant of each pixel's direction (OpenCV's vectorised atan2, to 0.3°;
    # its 2π is the last octant's); the pixels that are no background go to a
    # ninth bin of their row
    octant = cv2.phase(xs - P[:, :1], ys - P[:, 1:2]).reshape(xs.shape)
    octant *= (8.0 - 1e-9) / (2.0 * np.pi)
    octant = octant.astype(np.int64)
    other = u > -EDGE_ZONE
    if valid is not None:
        other |= ~valid
    np.putmask(octant, other, 8)
    if m > 1:
        octant += np.arange(0, 9 * m, 9)[:, None]
    counts = np.bincount(octant.ravel(), minlength=9 * m)
    means = np.bincount(octant.ravel(), resid.ravel(), minlength=9 * m)
    if m == 1:
        # one fit's eight octants as floats: the same divisions, max and min, without
        # the rows' small array passes
        full = [t / c for t, c in zip(means.tolist()[:8], counts.tolist()[:8]) if c >= _MIN_SECTOR_PX]
        return np.array([max(full) - min(full) if len(full) >= BACKGROUND_SECTORS // 2 else np.nan])
    counts, means = counts.reshape(m, 9)[:, :8], means.reshape(m, 9)[:, :8]
    full = counts >= _MIN_SECTOR_PX
    means /= np.maximum(counts, 1)
    means[~full] = np.nan
    # fmax/fmin pass over NaN
    spread = np.fmax.reduce(means, axis=1) - np.fmin.reduce(means, axis=1)
    spread[full.sum(axis=1) < BACKGROUND_SECTORS // 2] = np.nan
    return spread


def _lighting_shift(nx, ny, resid, J, u, M, inv) -> tuple:
    """(:attr:`DiscFit.lighting_shift_px`, :attr:`DiscFit.lighting_shift_std_px`) of a
    converged fit: how far (px) the centre moves when the lighting may also
    curve, L = 1 + gx·nx + gy·ny + a·nx² + b·nx·ny + c·ny² + (dx·nx + dy·ny)·(ρ - 1)
    with ρ = √(nx² + ny²) (`nx`, `ny`: the pixels' lighting frame; `resid`, `J`,
    `u`: the fitted model, `M` its unlit image B + (F - B)·Φ(u), `inv` the fit's
    (JᵀJ)⁻¹), the added terms'
    coefficients taken from the residuals of the pixels away from the edge zone
    only; and that move's standard deviation (px) from the pixel noise alone; NaNs
    when those terms are degenerate.

    The quadratic terms are even about the centre, the centre's derivatives odd:
    they cannot see a shadow's edge through the centre, whose first harmonic about
    the centre rises to its full size within a few px of the edge's line and then
    stays, unlike a gradient's, which grows with the radius. The gradient fitted
    to the ring misses it at the marker's edge, which moves the centre; the
    (ρ - 1) terms, fitted to the background beyond the edge zone and the inside,
    measure that miss, and the centre's linear response to it is the move (an
    edge through the centre: 0.1-1.1 px off, the quadratic move under 0.06 px;
    rendered). The edge zone gives no evidence: an edge that is not the model's
    (sharpening, an asymmetric blur) leaves misfits there that these terms,
    collinear with the centre, would take up. The noise is σ² g (Qᵀ Q)⁻¹ gᵀ along
    the move, g the centre's response to the terms and Q their part the fit's own
    parameters leave, on those pixels (σ² their residual variance)."""
    rho = np.hypot(nx, ny) - 1.0
    curved = np.stack([nx * nx, nx * ny, ny * ny, nx * rho, ny * rho]) * M
    try:
        # the curved terms as the residuals hold them (what the fit's own
        # parameters leave of them), on the pixels away from the edge zone: an
        # edge that is not the model's (sharpening, an asymmetric blur) leaves
        # misfits there that these terms, collinear with the centre, would take up
        left = curved - (curved @ J.T) @ inv @ J
        off = ~in_edge_zone(u)
        lo = left[:, off]
        weights = np.linalg.inv(lo @ lo.T)
    except np.linalg.LinAlgError:
        return float("nan"), float("nan")
    # the centre's response to the lighting those pixels show
    gain = (inv @ (J @ curved.T))[:2]
    move = gain @ (weights @ (lo @ resid[off]))
    shift = math.hypot(move[0], move[1])
    if not shift > 0:
        return shift, float("nan")
    along = move / shift
    sigma2 = float(resid[off] @ resid[off]) / max(int(np.count_nonzero(off)) - 13, 1)
    var = sigma2 * float(along @ gain @ weights @ gain.T @ along)
    return float(shift), math.sqrt(max(var, 0.0))


def _background_check(p, step, resid, J, u, nx, ny, inv) -> tuple:
    """(:attr:`DiscFit.background_step_dn`, :attr:`DiscFit.lighting_shift_px`,
    :attr:`DiscFit.lighting_shift_std_px`) of the
    fit `p` whose background step is `step` (DN, :func:`_background_steps`), from
    its pixels' lighting frame `nx`, `ny` and the model there (`resid`, `J`, `u`,
    and `inv` = (JᵀJ)⁻¹):
    the shifts only when the step exceeds :data:`UNEVEN_BACKGROUND` of the contrast
    (else NaNs)."""
    if not step > UNEVEN_BACKGROUND * abs(p[5] - p[4]):
        return step, float("nan"), float("nan")
    M = normal_cdf(u)
    M *= p[5] - p[4]
    M += p[4]
    return (step, *_lighting_shift(nx, ny, resid, J, u, M, inv))


def _disc_fit(p, sigma2, inverse, diagnostics, *, n, steep_cut, block_cov=None, background=None) -> DiscFit:
    """The :class:`DiscFit` of the converged parameters `p` (8) of `n` pixels of
    residual variance `sigma2` (DN²), after the checks every fit makes, in this
    order: the contrast against the noise (:func:`~vision_torsion.ring.check_contrast`),
    the covariance (``inverse()``: (JᵀJ)⁻¹; the block-robust one when
    ``block_cov(inverse())`` gives :func:`_block_covariance`'s, else σ²(JᵀJ)⁻¹), the
    radius against its σ
    (:func:`~vision_torsion.ring.check_radius`) and the edge diagnostics
    (``diagnostics()``: :func:`_edge_diagnostics`' tuple, or its FitError);
    ``background(inverse())`` gives :func:`_background_check`.

    Raises
    ------
    FitError
        The first check that fails.
    """
    check_contrast(p[5] - p[4], sigma2)
    inv = inverse()
    cov = None if block_cov is None else block_cov(inv)
    if cov is None:
        cov = sigma2 * inv
    check_radius(p[2], cov[2, 2])
    found = diagnostics()
    if isinstance(found, FitError):
        raise found
    ex, ey, rms, circularity, noise = found
    step, shift, shift_std = (float("nan"),) * 3 if background is None else background(inv)
    return DiscFit(
        x_px=float(p[0]),
        y_px=float(p[1]),
        radius_px=float(p[2]),
        edge_width_px=float(p[3]),
        cov=cov[:3, :3].copy(),
        noise_dn=float(np.sqrt(sigma2)),
        background_dn=float(p[4]),
        foreground_dn=float(p[5]),
        n_pixels=int(n),
        edge_x_px=ex,
        edge_y_px=ey,
        residual_rms_px=rms,
        circularity=circularity,
        edge_noise_px=noise,
        steep_cut=bool(steep_cut),
        background_step_dn=step,
        lighting_shift_px=shift,
        lighting_shift_std_px=shift_std,
    )


def _inverse(A, *, lapack=False):
    """(`A`)⁻¹ of one marker's 8x8 normal matrix by OpenCV's LU (numpy's LAPACK
    with `lapack`, as the batched fit inverts its rows).

    Raises
    ------
    FitError
        `A` is singular: the edge model is degenerate.
    """
    if lapack:
        try:
            return np.linalg.inv(A)
        except np.linalg.LinAlgError:
            ok = False
    else:
        ok, inverse = cv2.invert(A, flags=cv2.DECOMP_LU)
    if not ok:
        raise FitError("the marker's edge model is degenerate (no edge in the ring)")
    return inverse


def _block_covariance(xs, ys, resid, J, block_px: int, inv):
    """The covariance (px², and the other parameters' units) of a fit whose pixels'
    errors are independent between the `block_px` x `block_px` blocks of the image's
    grid (block edges at multiples of `block_px` from its top-left pixel), from the
    pixels at (`xs`, `ys`) (image px, N), their residuals `resid` (N), the Jacobian
    `J` (8 x N) and `inv` = (JᵀJ)⁻¹: the sandwich ``inv @ meat @ inv``, the meat
    Σ g gᵀ over the blocks (g = Σ_block J·r) times G/(G-1)·(n-1)/(n-8) (G blocks, n
    pixels) when :data:`MIN_BLOCKS` blocks or more inform the centre, else
    :func:`_lag_covariance` (its 3 x 3 of x, y, R); None for 8 pixels or fewer
    (see the module docstring)."""
    n = resid.size
    if n <= 8:
        return None
    bx = np.floor_divide(xs, block_px).astype(np.int64)
    by = np.floor_divide(ys, block_px).astype(np.int64)
    bx -= bx.min()
    by -= by.min()
    ids = by * (int(bx.max()) + 1) + bx
    # the blocks that inform the centre: those along the edge, each counted by its
    # share of the centre's information, (Σ w)² / Σ w²
    info = np.bincount(ids, weights=J[0] * J[0] + J[1] * J[1])
    informing = info.sum() ** 2 / max(float(info @ info), 1e-300)
    if informing < MIN_BLOCKS:
        return _lag_covariance(xs, ys, resid, J, block_px, inv)
    blocks = int(np.count_nonzero(np.bincount(ids)))
    g = np.stack([np.bincount(ids, weights=J[j] * resid) for j in range(J.shape[0])])
    return inv @ ((g @ g.T) * (blocks / (blocks - 1) * (n - 1) / (n - 8))) @ inv


def _lag_index(block_px: int) -> np.ndarray:
    """(b², b²) index |dy|·b + |dx| of the lag (dx, dy) between the pixels of one
    b x b block (in raster order), b = `block_px`."""
    y, x = np.divmod(np.arange(block_px * block_px), block_px)
    return np.abs(y[None, :] - y[:, None]) * block_px + np.abs(x[None, :] - x[:, None])


def _psd(matrix):
    """The symmetric `matrix` with its negative eigenvalues set to 0: the nearest
    covariance matrix (in the Frobenius norm)."""
    values, vectors = np.linalg.eigh(matrix)
    return (vectors * np.maximum(values, 0.0)) @ vectors.T


#: Rounds of :func:`_lag_covariance`'s correction of the lag covariances for the
#: residuals' loss to the fit; each leaves about the share of the error the fit
#: absorbs of the previous one's (~0.4 on a 5 px disc blurred 2.5 px, less on
#: larger or sharper ones).
_LAG_ROUNDS = 3


def _lag_covariance(xs, ys, resid, J, block_px: int, inv, *, project=False):
    """The 3 x 3 covariance (px²) of (x, y, R) of a fit on the pixels at (`xs`, `ys`)
    (image px, N), with residuals `resid` (N), Jacobian `J` (8 x N) and
    `inv` = (JᵀJ)⁻¹, when the pixels' errors are independent between the
    `block_px` x `block_px` blocks of the image's grid and, within one, have a
    covariance Ω that depends on the lag between two pixels only: the sandwich
    (JᵀJ)⁻¹ JΩJᵀ (JᵀJ)⁻¹. None when that is not positive.

    The noise model of a JPEG: each block is quantised alone, its DCT coefficients'
    errors independent, so that within a block the covariance of two pixels,
    averaged over their places, depends on |dx| and |dy| only. γ(|dx|, |dy|) is
    the mean of r_p·r_q over the pairs of pixels at that lag within one block, each
    block's pairs weighted by the block's share of the centre's information
    (Σ ∂I/∂cx² + ∂I/∂cy² over its pixels): the blocks along the edge carry the
    centre, and their error (the edge's own quantisation) is larger than a flat
    block's, whose fine detail the quantiser sets to zero. Pooled over the blocks
    and the pairs at each lag, γ is as steady on a ring of a few blocks as σ²,
    where the sum of g gᵀ over those blocks (:func:`_block_covariance`) is not.

    Residuals are not errors: r = (I - H)e (H = Jᵀ(JᵀJ)⁻¹J), and on a small marker
    the fit absorbs much of an error smooth over a block (a third, on a 5 px disc
    blurred 2.5 px). The lag means are corrected for that (the expectation of
    r_p·r_q is that of (I - H)Ω(I - H), linear in γ): :data:`_LAG_ROUNDS` rounds of
    γ ← (observed + its expected loss under the last γ) / pairs. Ω is the lag
    covariances as they come, whose noise the sandwich averages; when that gives a
    variance of x, y or R that is not positive (a γ of a few blocks need not be a
    covariance), each round's Ω is projected on the covariance matrices
    (:func:`_psd`, `project`), which biases it up a little."""
    b = int(block_px)
    nb = b * b
    bx = np.floor_divide(xs, b).astype(np.int64)
    by = np.floor_divide(ys, b).astype(np.int64)
    ids = (by - by.min()) * (int(bx.max() - bx.min()) + 1) + (bx - bx.min())
    ids = (np.cumsum(np.bincount(ids) > 0) - 1)[ids]  # the blocks the ring touches, numbered 0 … G-1
    g = int(ids.max()) + 1
    at = ids * nb + ((ys - by * b) * b + (xs - bx * b)).astype(np.int64)  # block, then its pixel
    rows = np.zeros((2 + J.shape[0], g * nb))  # residual, presence, Jacobian: block-major rows
    rows[0, at], rows[1, at], rows[2:, at] = resid, 1.0, J
    rows = rows.reshape(rows.shape[0], g, nb)
    r, present, jb = rows[0], rows[1], rows[2:]
    weight = np.bincount(ids, weights=J[0] * J[0] + J[1] * J[1], minlength=g)
    lag = _lag_index(b)
    flat = lag.ravel()
    observed = np.bincount(flat, ((r * weight[:, None]).T @ r).ravel(), minlength=nb)
    pairs = np.bincount(flat, ((present * weight[:, None]).T @ present).ravel(), minlength=nb)
    # a lag no pair of a weighted block has takes no covariance
    some = pairs > 1e-12 * pairs.max()
    pairs = np.where(some, pairs, 1.0)
    gamma = np.where(some, observed / pairs, 0.0)
    k = jb.shape[0]
    jflat = jb.reshape(k, g * nb)
    # the blocks of the residual products that count (the centre's information's),
    # their Jacobian and that times their weight
    edge = np.flatnonzero(weight > 1e-9 * weight.max())
    j_edge = jb[:, edge].reshape(k, edge.size * nb)
    weighted_t = (jb[:, edge] * weight[None, edge, None]).transpose(0, 2, 1)  # (k, nb, edge blocks)
    for done in range(_LAG_ROUNDS + 1):
        omega = _psd(gamma[lag]) if project else gamma[lag]
        # JΩ within each block, on the ring's pixels: one product per parameter, each
        # small enough that OpenBLAS keeps it in this thread (one product of all the
        # rows ran in its threads, which cost more than the product)
        j_omega = (jb @ omega) * present
        cov = inv @ (j_omega.reshape(k, g * nb) @ jflat.T) @ inv
        if done == _LAG_ROUNDS:
            break
        # the weighted lag sums of HΩ + ΩH - HΩH (H = Jᵀ inv J; HΩH = Jᵀ cov J),
        # what the residual products lose: h + hᵀ with h = Σ w Jᵀ(inv JΩ - cov J / 2)
        # (summed over the parameters, one product each: see JΩ above)
        loss = (inv @ j_omega[:, edge].reshape(k, -1) - 0.5 * (cov @ j_edge)).reshape(k, edge.size, nb)
        h = (weighted_t @ loss).sum(axis=0)
        lost = np.bincount(flat, (h + h.T).ravel(), minlength=nb)
        gamma = np.where(some, (observed + lost) / pairs, 0.0)
    cov = cov[:3, :3]
    if np.all(np.diag(cov) > 0):
        return cov
    return None if project else _lag_covariance(xs, ys, resid, J, block_px, inv, project=True)


def fit_disc(
    image, cx, cy, radius, *, edge_width=1.2, levels=None, max_iter=30, patch: MarkerPatch | None = None,
    block_px: int | None = None,
) -> DiscFit:
    """Fit the blurred-disc model to the pixels around a marker.

    Parameters
    ----------
    image : numpy.ndarray
        2-D grey image indexed ``[y, x]`` (DN); unused when `patch` is given.
    cx, cy : float
        Starting centre (px), good to about a pixel.
    radius : float
        Starting radius (px), good to about a pixel.
    edge_width : float
        Starting edge width s (px).
    levels : tuple of float, optional
        Starting (outside, inside) grey levels (DN); solved from the pixels when None.
    max_iter : int
        Levenberg-Marquardt iterations at most.
    patch : MarkerPatch, optional
        Pixels around the marker from :func:`~vision_torsion.ring.marker_patch`;
        taken from `image` when None. It must reach past the edge by the ring's
        width (3s + 7.5 px, and 0.5 px more for the start's error).
    block_px : int, optional
        The side (px) of the blocks the image was compressed in (8 for a JPEG's
        grey levels, 16 when converted from its subsampled colour): the
        covariance is then the block-robust one (module docstring). None: the
        pixels' errors are independent (a lossless file).

    Returns
    -------
    DiscFit

    Raises
    ------
    FitError
        The ring leaves the image, the marker has too little contrast against the
        noise, the fit does not converge, or too few edge sectors carry information.

    Notes
    -----
    The model and the outlier handling are described in the module docstring. The
    covariance is the inverse Fisher information of the model at the solution,
    scaled by the residual variance, so it includes the correlations of the centre
    with the radius, the edge width and the levels.

    Examples
    --------
    >>> from vision_torsion.synthetic import Scene, render
    >>> r = render(Scene(), 0.0, seed=3)
    >>> x, y = r.centres[0]
    >>> f = fit_disc(r.image, x + 0.6, y - 0.4, 34.0)
    >>> bool(abs(f.x_px - x) < 0.02 and abs(f.y_px - y) < 0.02)
    True
    """
    s = float(edge_width)
    if patch is None:
        patch = marker_patch(image, cx, cy, patch_extent(radius, s))
    x0, y0, r0 = float(cx), float(cy), float(radius)
    # one ring for the whole fit, a little wider than the edge zone needs as the
    # start may be off (the fit stays unbiased whatever the ring: every pixel in it
    # is modelled)
    ring = _Pixels(patch, _ring(patch, cx, cy, radius, s, margin=_START_MARGIN_PX), x0, y0, r0)
    px = ring
    start = _start_levels(px, cx, cy, radius, s) if levels is None else (*levels, 0.0, 0.0)
    p = np.array([cx, cy, radius, s, *start], dtype=np.float64)
    return _fit_from(p, ring, patch, *_evaluate(p, px), max_iter=max_iter, block_px=block_px)








def _fit_from(p, ring: _Pixels, patch: MarkerPatch, resid, J, u, *, max_iter, block_px=None) -> DiscFit:
    """:func:`fit_disc`'s Levenberg-Marquardt loop and result from the starting
    parameters `p` and the model's residuals, Jacobian and u there on all of
    `ring`'s pixels: :func:`fit_discs`' rules (:class:`_RowsFit`) for one marker,
    in scalar steps."""
    px, keep, lam, cuts = ring, None, 1e-3, 0  # keep: flags of the ring's pixels in use, None: all
    ssr = float(resid @ resid)
    final = False  # the last examination changed nothing
    steep_cut = False  # pixels cut under a steep lighting gradient (DiscFit.steep_cut)
    for _ in range(max_iter):
        A = J @ J.T
        b = J @ resid
        step = solve_lu(damped_normal_matrix(A, lam), b)
        trial = p + step
        trial[3] = bounded_edge_width(trial[3], p[3])
        if final and max(abs(step[0]), abs(step[1])) < _CONVERGED_PX and abs(trial[3] - p[3]) < _WIDTH_CONVERGED_PX:
            # Converged: take this last step without evaluating the model there.
            # Gauss-Newton converges quadratically here, so what it leaves is far
            # below 1e-3 px; the noise, covariance and diagnostics of the model at
            # p differ from those at the step's end by as little. This saves a
            # third of the model evaluations.
            p = trial
            break
        r_t, J_t, u_t = _evaluate(trial, px)
        ssr_t = float(r_t @ r_t)
        if not ssr_t <= ssr:
            lam *= 10.0
            if lam > 1e8:
                raise FitError("the marker's edge model does not converge")
            continue
        moved = max(abs(trial[0] - p[0]), abs(trial[1] - p[1]))
        widened = abs(trial[3] - p[3])
        p, resid, J, u, ssr = trial, r_t, J_t, u_t, ssr_t
        lam = max(0.3 * lam, 1e-9)
        if not final and moved < (_SETTLED_PX if cuts == 0 else _CONVERGED_PX):
            # Examine the whole ring for an occluder: first once the centre has
            # settled, then after each refit without what was cut, as a fit pulled
            # by an occluder hides part of it (at most three times).
            full = (resid, J, u) if keep is None else _evaluate(p, ring)
            new_keep, steep = _examine(p, ring, patch, *full)
            steep_cut = steep_cut or steep
            cuts += 1
            final = _last_examination(cuts, keep, new_keep)
            if not (keep is None and new_keep is None):
                keep = new_keep
                resid, J, u = full
                px = ring
                if keep is not None:
                    px, resid, J, u = ring.subset(keep), resid[keep], J[:, keep], u[keep]
                ssr = float(resid @ resid)
                if not final:
                    continue
        if final and moved < _CONVERGED_PX and widened < _WIDTH_CONVERGED_PX:
            A = J @ J.T
            break
    else:
        raise FitError(f"the marker's edge model did not converge in {max_iter} iterations")
    n = resid.size
    sigma2 = ssr / max(n - 8, 1)
    return _disc_fit(p, sigma2, lambda: _inverse(A), lambda: _edge_diagnostics(
        p[None], resid[None], J[None], u[None], [n], [ssr])[0], n=n, steep_cut=steep_cut,
        block_cov=(lambda inv: _block_covariance(px.xs, px.ys, resid, J, block_px, inv)) if block_px else None,
        background=lambda inv: _background_check(p, float(_background_steps(p[None], px.xs[None], px.ys[None],
                                                                               resid[None], u[None])[0]),
                                                 resid, J, u, px.nx, px.ny, inv))


class _Scratch(threading.local):
    """The batched fit's large arrays, kept from one call to the next (one set per
    thread): a fit's rings, Jacobians and residuals are a few MB, and each page of
    freshly allocated memory costs a page fault when first touched. Each array is
    asked for by name; a later call's arrays overwrite an earlier call's, so
    nothing returned to a caller may be one of them."""

    def __init__(self):
        self.arrays: dict = {}

    def get(self, name, shape, dtype=np.float64) -> np.ndarray:
        """An uninitialised array of `shape` (a view of the buffer `name`)."""
        size = math.prod(shape)
        buf = self.arrays.get(name)
        if buf is None or buf.size < size or buf.dtype != dtype:
            buf = np.empty(max(size, int(1.25 * buf.size) if buf is not None else 0), dtype)
            if buf.nbytes <= _KEEP_BYTES:
                self.arrays[name] = buf
        return buf[:size].reshape(shape)


_SCRATCH = _Scratch()


class _Batch:
    """The rings of many markers as rows of padded arrays (M x N), for the
    vectorised fit: pixel coordinates, values and the lighting frame as in
    :class:`_Pixels`; `mask` is 1 on a ring's pixels and 0 on the padding (whose
    coordinates lie far outside every marker, so the model there is flat).
    The arrays are :class:`_Scratch` buffers."""

    _NAMES = ("xs", "ys", "vals", "nx", "ny", "mask")

    def __init__(self, rings: list[_Pixels], starts: np.ndarray):
        self.n = np.array([r.xs.size for r in rings])
        m, width = len(rings), int(self.n.max())
        self.pad = starts[:, :2] + (1e4, 0.0)  # where a row's padding lies
        self.mask = _SCRATCH.get("batch mask", (m, width), bool)
        np.less(np.arange(width), self.n[:, None], out=self.mask)
        for name in ("xs", "ys", "vals", "nx", "ny"):
            setattr(self, name, _SCRATCH.get("batch " + name, (m, width)))
        self.xs[:] = self.pad[:, :1]
        self.ys[:] = self.pad[:, 1:2]
        self.vals[:] = self.nx[:] = self.ny[:] = 0.0
        for k, ring in enumerate(rings):
            for name in ("xs", "ys", "vals", "nx", "ny"):
                getattr(self, name)[k, : self.n[k]] = getattr(ring, name)

    def set_row(self, k, ring: _Pixels):
        """Row `k` holds `ring`'s pixels (no more than it had: a subset after an
        occluder cut, or its whole ring again), padded as before."""
        n = ring.xs.size
        self.n[k] = n
        self.mask[k] = np.arange(self.mask.shape[1]) < n
        for name in ("xs", "ys", "vals", "nx", "ny"):
            getattr(self, name)[k, :n] = getattr(ring, name)
        self.xs[k, n:], self.ys[k, n:] = self.pad[k]
        self.vals[k, n:] = self.nx[k, n:] = self.ny[k, n:] = 0.0

    def rows(self, index):
        """The rows `index` (into :class:`_Scratch` buffers of their own)."""
        out = object.__new__(_Batch)
        for name in self._NAMES:
            a = getattr(self, name)
            buf = _SCRATCH.get("rows " + name, (len(index),) + a.shape[1:], a.dtype)
            setattr(out, name, np.take(a, index, axis=0, out=buf))
        return out

    def block(self, lo, hi):
        """Rows lo … hi-1 (views)."""
        out = object.__new__(_Batch)
        for name in self._NAMES:
            setattr(out, name, getattr(self, name)[lo:hi])
        return out


def _evaluate_rows(P, px: _Batch, slot=0):
    """:func:`_evaluate` for rows of markers (parameters `P`, M x 8): residuals (M x N),
    Jacobian (M x 8 x N) and u (M x N), zero on the padding, in the
    :class:`_Scratch` buffers of `slot` (0 or 1: the fit's current state and a trial).

    The padding lies 1e4 px from every marker with no lighting offset, where the
    edge terms (exp(-u²/2), Φ) are exactly 0 and L is 1: only the residual and
    ∂I/∂B (= L) are not 0 there and need the mask. Evaluated in blocks of rows
    (:data:`_BLOCK`) whose temporaries malloc reuses: element-wise, the same values."""
    m, width = px.xs.shape
    Jm = _SCRATCH.get(f"J{slot}", (m, 8, width))
    resid = _SCRATCH.get(f"resid{slot}", (m, width))
    u = _SCRATCH.get(f"u{slot}", (m, width))
    step = max(1, _BLOCK // width)
    for lo in range(0, m, step):
        hi = min(lo + step, m)
        block = px.block(lo, hi)
        r, _, uu = _evaluate(P[lo:hi].T[:, :, None], block, J=Jm[lo:hi].transpose(1, 0, 2))
        np.multiply(r, block.mask, out=resid[lo:hi])
        Jm[lo:hi, 4] *= block.mask
        u[lo:hi] = uu
    return resid, Jm, u


def _normal_equations(Jm, resid):
    """JᵀJ (M x 8 x 8) and Jᵀr (M x 8) of each row."""
    return Jm @ Jm.transpose(0, 2, 1), (Jm @ resid[:, :, None])[:, :, 0]


def _edge_diagnostics(P, resid, Jm, u, n, ssr) -> list:
    """Per row of markers (parameters `P`, M x 8; the model's residuals (M x N),
    Jacobian (M x 8 x N) and u (M x N) on the first `n` (M ints) pixels of each row
    and padding after, far outside the edge zone; `ssr` (M floats) the rows' sums of
    squared residuals, DN²): the edge points of the angular sectors (x, y in px;
    :func:`~vision_torsion.ring.sector_edge_offsets`' rule), their RMS distance from
    the circle (px), the circularity they give
    (:func:`~vision_torsion.ring.harmonic_circularity`) and their RMS standard
    deviation from the pixel noise alone (px), or the FitError of too few sectors.

    The noise is the residual variance of the pixels more than 3s from the edge
    (|u| >= 3), or the ring's when fewer than 30: without the misfit of an edge that
    is not the model's circle (an ellipse's, which inflates the ring's whole
    variance by 2-15x on rendered ones). :func:`fit_disc` asks for one row,
    :func:`fit_discs` for all of its rows at once; one row takes no per-row sums."""
    m, size = resid.shape
    if not m:
        return []
    # sector_index's sectors (~1 px of arc) of each row, laid out in spans of `width`
    radii = P[:, 2].tolist()
    n_sec = [sector_count(R) for R in radii]
    width = max(n_sec, default=0)
    # the edge zone's pixels, as flat indices into the rows (`at`) and into the
    # Jacobian's rows of ∂I/∂cx (`jat`), and their rows (`zr`, 0 for one marker)
    at = np.flatnonzero(in_edge_zone(u))
    if m == 1:
        zr, jat, per_row = 0, at, n_sec[0]
    else:
        zr = at // size
        jat = at + zr * (7 * size)
        per_row = np.array(n_sec)[zr]
    # J[0] = g·cos ψ and J[1] = g·sin ψ, with g = J[2] = ∂I/∂R: the pixels'
    # directions need no coordinates (half a turn off when g < 0, a dark marker)
    flat = Jm.reshape(-1)
    g_cos, g_sin, g = flat.take(jat), flat.take(jat + size), flat.take(jat + 2 * size)
    rz = resid.reshape(-1).take(at)
    psi = np.arctan2(g_sin, g_cos)
    if m == 1:
        if P[0, 5] < P[0, 4]:
            psi += np.pi
    else:
        dark = P[:, 5] < P[:, 4]
        if dark.any():
            psi += np.pi * dark[zr]
    psi += np.pi
    psi *= per_row / (2 * np.pi)
    where = psi.astype(np.int64) % per_row
    if m > 1:
        where += zr * width
    den, num, cs, sn = (np.bincount(where, w, minlength=m * width) for w in (g * g, g * rz, g * g_cos, g * g_sin))
    # the sectors with more than a tenth of their row's median information (of those with any)
    cut = np.empty(m)
    for k, row in enumerate(den.reshape(m, width)):
        positive = row[row > 0]
        cut[k] = 0.1 * fast_median(positive) if positive.size else 0.0
    sel = np.flatnonzero(den > (cut[0] if m == 1 else np.repeat(cut, width)))
    info = den[sel]
    delta = num[sel] / info
    ang = np.arctan2(sn[sel], cs[sel])
    c, s = np.cos(ang), np.sin(ang)
    sr = 0 if m == 1 else sel // width  # the sectors' rows
    at_row = P[0] if m == 1 else P[sr].T
    r = at_row[2] + delta
    ex, ey = at_row[0] + r * c, at_row[1] + r * s
    d2, cos2, sin2, inv = (_row_sums(sr, v, m) for v in (delta * delta, delta * (c * c - s * s),
                                                           delta * (2.0 * c * s), 1.0 / info))
    zone_ss = _row_sums(zr, rz * rz, m)
    zone_n = [at.size] if m == 1 else np.bincount(zr, minlength=m).tolist()
    ends = list(accumulate([sel.size] if m == 1 else np.bincount(sr, minlength=m).tolist()))
    starts = [0] + ends[:-1]
    need = [sectors_needed(n_sec[0])] if m == 1 else sectors_needed(np.array(n_sec)).tolist()
    out = []
    for k, (lo, hi, R, n_k, ssr_k) in enumerate(zip(starts, ends, radii, n, ssr)):
        kept = hi - lo
        if kept < need[k]:
            out.append(FitError(f"only {kept} edge sectors carry information (need {need[k]})"))
            continue
        away_n = n_k - zone_n[k]
        var_away = (ssr_k - zone_ss[k]) / away_n if away_n >= 30 else ssr_k / max(n_k - 8, 1)
        circularity = 1.0 - 2.0 * math.hypot(2.0 / kept * cos2[k], 2.0 / kept * sin2[k]) / R
        out.append((ex[lo:hi], ey[lo:hi], math.sqrt(d2[k] / kept), circularity, math.sqrt(var_away * inv[k] / kept)))
    return out


def _row_sums(rows, values, m) -> list:
    """The sums (floats) of `values` over each of `m` rows (`rows`: each value's
    row; 0 when `m` is 1)."""
    if m == 1:
        return [float(values.sum())]
    return np.bincount(rows, values, minlength=m).tolist()


#: Diagonal indices of an 8x8 matrix.
_DIAG = np.arange(8)


class _RowsFit:
    """The state of :func:`fit_discs`' Levenberg-Marquardt fit of M markers as rows,
    and its steps: the parameters `P` (M x 8); the model's residuals, Jacobian and
    u on the pixels each row uses (:func:`_evaluate_rows`, in the :class:`_Scratch`
    slot `cur`) with their sums of squares `ssr` and normal equations `A`, `b`; per
    row the damping `lam`, the examinations for an occluder made (`cuts`), whether
    the last one changed nothing (`final`), whether pixels were cut under a steep
    gradient (`steep_cut`) and the flags of the ring's pixels kept (`keeps`, rows
    with a cut only); `active` rows are still iterating, `failed` ones hold their
    FitError. Every rule is :func:`fit_disc`'s, taken for all rows at once."""

    def __init__(self, patches, rings: list[_Pixels], live: np.ndarray, starts: np.ndarray, s: float):
        self.patches, self.rings, self.live = patches, rings, live
        self.px = _Batch(rings, starts[live])
        m = self.m = live.size
        self.P = np.zeros((m, 8))
        self.P[:, :3], self.P[:, 3], self.P[:, 4:6] = starts[live, :3], s, starts[live, 3:5]
        self.cur = 0  # the scratch slot of the current state; the other takes trials
        self.resid, self.Jm, self.u = _evaluate_rows(self.P, self.px, self.cur)
        self.ssr = np.einsum("ij,ij->i", self.resid, self.resid)
        self.A, self.b = _normal_equations(self.Jm, self.resid)
        self.lam = np.full(m, 1e-3)
        self.final = np.zeros(m, bool)
        self.active = np.ones(m, bool)
        self.failed: dict[int, FitError] = {}
        self.cuts = np.zeros(m, np.int64)
        self.steep_cut = np.zeros(m, bool)
        self.keeps: dict[int, np.ndarray] = {}

    def iterate(self) -> bool:
        """One Levenberg-Marquardt iteration of the active rows; False when none is."""
        act = np.flatnonzero(self.active)
        if not act.size:
            return False
        act, step = self._steps(act)
        P, final = self.P, self.final
        trial = P[act] + step
        trial[:, 3] = bounded_edge_width(trial[:, 3], P[act, 3])
        small = ((np.maximum(np.abs(step[:, 0]), np.abs(step[:, 1])) < _CONVERGED_PX)
                 & (np.abs(trial[:, 3] - P[act, 3]) < _WIDTH_CONVERGED_PX))
        last = final[act] & small
        # converged: the last step taken without evaluating the model (as fit_disc)
        P[act[last]] = trial[last]
        self.active[act[last]] = False
        act, trial = act[~last], trial[~last]
        if not act.size:
            return True
        m = self.m
        r_t, J_t, u_t = _evaluate_rows(trial, self.px if act.size == m else self.px.rows(act), 1 - self.cur)
        ssr_t = np.einsum("ij,ij->i", r_t, r_t)
        better = ssr_t <= self.ssr[act]
        worse = act[~better]
        self.lam[worse] *= 10.0
        for k in worse[self.lam[worse] > 1e8]:
            self.failed[k] = FitError("the marker's edge model does not converge")
            self.active[k] = False
        acc, trial = act[better], trial[better]
        if not acc.size:
            return True
        moved = np.maximum(np.abs(trial[:, 0] - P[acc, 0]), np.abs(trial[:, 1] - P[acc, 1]))
        widened = np.abs(trial[:, 3] - P[acc, 3])
        if acc.size == m:  # every marker stepped: the new arrays as they are
            self.P, self.resid, self.Jm, self.u, self.ssr = trial, r_t, J_t, u_t, ssr_t
            self.cur = 1 - self.cur
            self.A, self.b = _normal_equations(self.Jm, self.resid)
        else:
            P[acc], self.ssr[acc] = trial, ssr_t[better]
            # row by row into the current state's buffers: copies of the accepted
            # rows (r_t[better]) would be fresh memory each iteration
            for j, k in zip(np.flatnonzero(better), acc):
                self.resid[k], self.Jm[k], self.u[k] = r_t[j], J_t[j], u_t[j]
            A_t, b_t = _normal_equations(J_t, r_t)
            self.A[acc], self.b[acc] = A_t[better], b_t[better]
        self.lam[acc] = np.maximum(0.3 * self.lam[acc], 1e-9)
        going_on = self._examinations(acc, moved)
        settled = (moved < _CONVERGED_PX) & (widened < _WIDTH_CONVERGED_PX)
        self.active[acc[self.final[acc] & settled & ~going_on[acc]]] = False
        return True

    def _steps(self, act):
        """The damped steps (len(act) x 8) of rows `act`, and those rows; a row whose
        system is singular fails and is left out."""
        Aa = self.A[act]
        Aa[:, _DIAG, _DIAG] += self.lam[act, None] * Aa[:, _DIAG, _DIAG]
        try:
            return act, np.linalg.solve(Aa, self.b[act][:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            step = np.zeros((act.size, 8))
            for j, k in enumerate(act):
                try:
                    step[j] = np.linalg.solve(Aa[j], self.b[k])
                except np.linalg.LinAlgError:
                    self.failed[k] = FitError("the marker's edge model is degenerate (no edge in the ring)")
                    self.active[k] = False
            keep = self.active[act]
            return act[keep], step[keep]

    def _examinations(self, acc, moved) -> np.ndarray:
        """fit_disc's examinations for an occluder of the rows `acc` just stepped
        (`moved`: their centres' moves, px) that are due: first once the centre has
        settled, then once it has converged after each change of the pixels used.
        Flags (M) of the rows whose pixels changed, which go on."""
        cuts, final = self.cuts, self.final
        due = acc[~final[acc] & (moved < np.where(cuts[acc] == 0, _SETTLED_PX, _CONVERGED_PX))]
        going_on = np.zeros(self.m, bool)
        if not due.size:
            return going_on
        # Most rings have no pixel beyond 4.5 robust σ at their first examination:
        # that is settled for all at once (nothing to cut makes the fit final).
        first = due[cuts[due] == 0]
        clean = np.zeros(self.m, bool)
        if first.size:
            rows = self.resid if first.size == self.m else self.resid[first]  # no copy when all are due
            sig = robust_sigma_rows(rows, self.px.n[first])
            quiet = (np.abs(rows) < OCCLUDER_SIGMAS * sig[:, None]).all(axis=1)
            quiet &= ~_steep(self.P[first])
            clean[first[quiet]] = True
        final[clean] = True
        cuts[clean] = 1
        for k in due[~clean[due]]:
            going_on[k] = self._examine(k)
        return going_on

    def _examine(self, k) -> bool:
        """fit_disc's examination of row `k`'s whole ring for an occluder; its row
        then holds the pixels kept. True when they changed and the fit goes on."""
        P, px, ring = self.P, self.px, self.rings[k]
        keep, n = self.keeps.get(k), px.n[k]
        full = (self.resid[k, :n], self.Jm[k, :, :n], self.u[k, :n]) if keep is None else _evaluate(P[k], ring)
        new_keep, steep = _examine(P[k], ring, self.patches[self.live[k]], *full)
        self.steep_cut[k] |= steep
        self.cuts[k] += 1
        self.final[k] = self.final[k] or _last_examination(self.cuts[k], keep, new_keep)
        if keep is None and new_keep is None:
            return False
        if new_keep is None:
            self.keeps.pop(k)
            r_k, J_k, u_k = full
        else:
            self.keeps[k] = new_keep
            ring, r_k, J_k, u_k = ring.subset(new_keep), full[0][new_keep], full[1][:, new_keep], full[2][new_keep]
        n = r_k.size
        px.set_row(k, ring)
        self.resid[k, :n], self.resid[k, n:] = r_k, 0.0
        self.Jm[k, :, :n], self.Jm[k, :, n:] = J_k, 0.0
        self.u[k, :n], self.u[k, n:] = u_k, np.inf
        self.ssr[k] = r_k @ r_k
        self.A[k], self.b[k] = J_k @ J_k.T, J_k @ r_k
        return not self.final[k]

    def results(self, out: list, max_iter: int, block_px: int | None = None) -> None:
        """Each row's :class:`DiscFit` (:func:`_disc_fit`) or FitError, into `out`
        at the marker's index (`live`); the covariance block-robust with `block_px`
        (:func:`fit_disc`)."""
        P, px, A, m = self.P, self.px, self.A, self.m
        failed = self.failed
        for k in np.flatnonzero(self.active):
            failed[k] = FitError(f"the marker's edge model did not converge in {max_iter} iterations")
        unfit = np.zeros(m, bool)
        unfit[list(failed)] = True
        good = np.flatnonzero(~unfit)
        sigma2 = self.ssr / np.maximum(px.n - 8, 1)
        resid, Jm, u = self.resid, self.Jm, self.u
        if good.size == m:  # no copies of the rows (most fits: none failed)
            diagnostics = _edge_diagnostics(P, resid, Jm, u, px.n.tolist(), self.ssr.tolist())
        else:
            diagnostics = _edge_diagnostics(P[good], resid[good], Jm[good], u[good], px.n[good].tolist(),
                                            self.ssr[good].tolist())
        steps = _background_steps(P, px.xs, px.ys, resid, u, px.mask)
        try:
            inverses = np.linalg.inv(A[good])
        except np.linalg.LinAlgError:
            inverses = None  # one of them singular: inverted one by one
        for j, k in enumerate(good):
            inverse = (lambda: _inverse(A[k], lapack=True)) if inverses is None else (lambda: inverses[j])
            nk = px.n[k]
            block_cov = (lambda inv: _block_covariance(px.xs[k, :nk], px.ys[k, :nk], resid[k, :nk],
                                                       Jm[k, :, :nk], block_px, inv)) if block_px else None
            try:
                out[self.live[k]] = _disc_fit(
                    P[k], sigma2[k], inverse, lambda: diagnostics[j], n=nk, steep_cut=self.steep_cut[k],
                    block_cov=block_cov,
                    background=lambda inv: _background_check(P[k], float(steps[k]), resid[k, :nk], Jm[k, :, :nk],
                                                             u[k, :nk], px.nx[k, :nk], px.ny[k, :nk], inv))
            except FitError as exc:
                failed[k] = exc
        for k, exc in failed.items():
            out[self.live[k]] = exc


def fit_discs(patches, starts, *, edge_width=1.2, max_iter=30, block_px: int | None = None) -> list:
    """:func:`fit_disc` of many markers at once, vectorised across them.

    The same model, ring, Levenberg-Marquardt steps, outlier examination and
    convergence rule as :func:`fit_disc`, with every marker's step taken in one set
    of array operations (a photograph of a dot grid has hundreds of small markers,
    where per-marker calls cost more than their arithmetic). A marker whose ring
    holds an occluder to cut stays in the rows: its row then holds the pixels kept
    (padded like the rest), and its whole ring is examined again as fit_disc's is,
    each examination (the cut itself) made for that marker alone. The result is
    fit_disc's to rounding.

    Parameters
    ----------
    patches : list of MarkerPatch
        Pixels around each marker (neighbours' pixels flagged in ``excluded``).
    starts : array_like
        (M, 5) rows of the starting centre (x, y), radius (px) and the (outside,
        inside) grey levels (DN).
    edge_width : float
        Starting edge width s (px), the same for all.
    max_iter : int
        Levenberg-Marquardt iterations at most.
    block_px : int, optional
        As for :func:`fit_disc`.

    Returns
    -------
    list
        Per marker, a :class:`DiscFit`, or the :class:`~vision_torsion.errors.FitError`
        saying why it failed.
    """
    starts = np.asarray(starts, dtype=np.float64).reshape(-1, 5)
    if len(patches) > _BATCH:
        # markers are independent rows: in groups whose arrays stay in the cache
        return [
            fit
            for k in range(0, len(patches), _BATCH)
            for fit in fit_discs(patches[k : k + _BATCH], starts[k : k + _BATCH], edge_width=edge_width,
                                 max_iter=max_iter, block_px=block_px)
        ]
    out: list = [None] * len(patches)
    s = float(edge_width)
    rings, live = [], []
    for k, (patch, (cx, cy, r, _, _)) in enumerate(zip(patches, starts)):
        try:
            rings.append(_Pixels(patch, _ring(patch, cx, cy, r, s, margin=_START_MARGIN_PX), cx, cy, r))
            live.append(k)
        except FitError as exc:
            out[k] = exc
    if not live:
        return out
    fit = _RowsFit(patches, rings, np.array(live), starts, s)
    for _ in range(max_iter):
        if not fit.iterate():
            break
    fit.results(out, max_iter, block_px)
    return out
