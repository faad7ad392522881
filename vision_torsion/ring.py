"""Helpers of the ring-of-pixels marker fits, shared by :mod:`.pixelfit` (the default
fit of the blurred-disc model to the pixels) and :mod:`.edges` (sub-pixel edge points
for the circle and ellipse fits).

The patch of pixels around a marker and its coordinates, the edge profile's normal
distribution, the robust occluder cut, the ~1 px sectors of arc, the small
Levenberg-Marquardt solve, and the checks both fits make (contrast, edge width, lost
arc, circularity). Neither fit module imports the other's internals; both import
these, and a new way to fit a marker starts from them (ARCHITECTURE.md).

Coordinates are image pixels (x, y), origin at the centre of the top-left pixel,
y downwards.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import cv2
import numpy as np

from .errors import FitError

__all__ = [
    "INV_SQRT_2PI",
    "EDGE_ZONE",
    "OCCLUDER_SIGMAS",
    "normal_cdf",
    "marker_roi",
    "MarkerPatch",
    "marker_patch",
    "grow_cut",
    "robust_sigma",
    "robust_sigma_rows",
    "in_edge_zone",
    "occluder_group",
    "occluder_groups",
    "cut_occluders",
    "sector_count",
    "sector_index",
    "sector_edge_offsets",
    "sectors_needed",
    "fast_median",
    "harmonic_circularity",
    "points_circularity",
    "check_contrast",
    "check_radius",
    "bounded_edge_width",
    "lost_sectors",
    "nothing_to_cut",
    "damped_normal_matrix",
    "solve_lu",
]

#: 1/√(2π): the standard normal density's factor (the edge profile's derivative).
INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)


#: Abramowitz & Stegun 7.1.26's p for erf, scaled to Φ's argument (u/√2).
_CDF_P = 0.3275911 / np.sqrt(2.0)


def normal_cdf(u, gauss=None):
    """Standard normal distribution function Φ(u), to 1e-7 (Abramowitz & Stegun 7.1.26).

    ``gauss`` is ``exp(-u²/2)`` when the caller has it already (the edge model's
    derivative needs it): ``scipy.special.ndtr`` is exact but was half the cost of
    a model evaluation, and importing scipy.special costs every worker process
    0.4 s. An error of 1e-7 of the contrast is far below the noise of any image
    (8-bit: 4e-3).
    """
    u = np.asarray(u, dtype=np.float64)
    if u.ndim == 0:
        return normal_cdf(u[None], None if gauss is None else np.atleast_1d(gauss))[0]
    if gauss is None:
        gauss = np.exp(-0.5 * u * u)
    # in place: on a few thousand values each numpy call costs about as much as
    # its arithmetic
    t = np.abs(u)
    t *= _CDF_P
    t += 1.0
    np.reciprocal(t, out=t)
    tail = t * 0.5307027145
    for c in (-0.7265760135, 0.7107068705, -0.142248368, 0.127414796):
        tail += c
        tail *= t
    tail *= gauss  # = Φ(-|u|)
    # Φ(u) = 1/2 + sign(u)·(1/2 - Φ(-|u|))
    np.subtract(0.5, tail, out=tail)
    np.copysign(tail, u, out=tail)
    tail += 0.5
    return tail


def marker_roi(shape, cx, cy, extent):
    """Bounds (x0, y0, x1, y1) of the square of half-size `extent` around (cx, cy), or None if it leaves the image."""
    h, w = shape
    x0, x1 = int(np.floor(cx - extent)), int(np.ceil(cx + extent)) + 1
    y0, y1 = int(np.floor(cy - extent)), int(np.ceil(cy + extent)) + 1
    if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
        return None
    return x0, y0, x1, y1


@dataclass(frozen=True)
class MarkerPatch:
    """The pixels around a marker, flattened once for repeated edge extraction.

    Attributes
    ----------
    values : numpy.ndarray
        Grey levels (DN), float64, row by row.
    shape : tuple of int
        (rows, columns) of the square the flat array came from.
    x0, y0 : int
        Column and row of its top-left pixel in the image.
    xs, ys : numpy.ndarray
        Pixel-centre coordinates (px), float64, flat like `values` (made when
        first asked for: the pixel-model fit works from indices).
    excluded : numpy.ndarray or None
        Flags (flat like `values`) of pixels the fits must not use: those of a
        neighbouring marker reaching into the ring.
    """

    values: np.ndarray
    shape: tuple
    x0: int = 0
    y0: int = 0
    excluded: np.ndarray | None = None

    @cached_property
    def xs(self) -> np.ndarray:
        return _grid(*self.shape)[0] + self.x0

    @cached_property
    def ys(self) -> np.ndarray:
        return _grid(*self.shape)[1] + self.y0

    def coordinates(self, index) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) in px of the pixels at flat positions `index`."""
        # taken from the block's cached grid: an integer divmod of the indices
        # cost four times as much (the same values: whole numbers in float64)
        gx, gy = _grid(*self.shape)
        return gx.take(index) + float(self.x0), gy.take(index) + float(self.y0)

    def squared_distance(self, cx, cy) -> np.ndarray:
        """Squared distance (px²) of every pixel centre from (cx, cy), flat like
        `values`: by broadcasting a row and a column, one pass over the patch."""
        rows, cols = self.shape
        dx = np.arange(self.x0 - cx, self.x0 - cx + cols - 0.5)
        dy = np.arange(self.y0 - cy, self.y0 - cy + rows - 0.5)
        return np.add.outer(dy * dy, dx * dx).ravel()

    def centroid(self, weights) -> tuple[float, float, float]:
        """Sum of `weights` (flat like `values`, not negative) and their weighted mean
        (x, y) in px; (0, 0, 0) when they sum to 0."""
        rows, cols = self.shape
        w = weights.reshape(rows, cols)
        total = float(w.sum())
        if not total > 0:
            return 0.0, 0.0, 0.0
        x = self.x0 + float(w.sum(axis=0) @ np.arange(cols)) / total
        y = self.y0 + float(w.sum(axis=1) @ np.arange(rows)) / total
        return total, x, y


def marker_patch(image, cx, cy, extent, *, clip: bool = False) -> MarkerPatch:
    """Pixels within the square of half-size `extent` (px) around (cx, cy).

    With `clip`, a square that leaves the image is cut to it (a marker near the
    border keeps the pixels there are; the fits model only the pixels they get).

    Raises
    ------
    FitError
        The square leaves the image (without `clip`), or nothing of it is inside.
    """
    if clip:
        h, w = image.shape
        x0, x1 = max(int(np.floor(cx - extent)), 0), min(int(np.ceil(cx + extent)) + 1, w)
        y0, y1 = max(int(np.floor(cy - extent)), 0), min(int(np.ceil(cy + extent)) + 1, h)
        roi = (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None
    else:
        roi = marker_roi(image.shape, cx, cy, extent)
    if roi is None:
        raise FitError("the marker's edge ring leaves the image")
    x0, y0, x1, y1 = roi
    return MarkerPatch(
        values=np.asarray(image[y0:y1, x0:x1], dtype=np.float64).ravel(),
        shape=(y1 - y0, x1 - x0),
        x0=x0,
        y0=y0,
    )


@lru_cache(maxsize=16)
def _grid(rows, cols):
    """Flat column and row indices (float64) of a rows x cols block, read-only: a
    session's markers keep their size, so each block shape is built once."""
    ys, xs = np.mgrid[0:rows, 0:cols]
    gx, gy = xs.ravel().astype(np.float64), ys.ravel().astype(np.float64)
    gx.flags.writeable = gy.flags.writeable = False
    return gx, gy


def grow_cut(keep, ring_idx, shape):
    """Widen the outlier cut by 2 px: an occluder's blurred flanks stay below the
    threshold but still pull the grey levels and the edge next to it.

    `keep` flags the ring pixels ``patch.values[ring_idx]`` of a patch of `shape`
    (rows, columns) that survived the cut; returns the flags with the cut grown."""
    cut = np.zeros(shape, np.uint8)
    cut.reshape(-1)[ring_idx[~keep]] = 1  # a view: .flat indexing is several times slower
    cut = cv2.dilate(cut, np.ones((5, 5), np.uint8))
    return keep & (cut.reshape(-1)[ring_idx] == 0)


def robust_sigma(resid) -> float:
    """Noise σ of model residuals, robust to an occluder's pixels (same unit as `resid`).

    1.4826·MAD (of every fourth residual: the median is the costly part), then
    sigma clipping from there: the RMS of the residuals within 3σ, corrected for the
    truncation of a normal distribution at 3σ (factor 0.98658), until it changes by
    less than 1 %. The MAD alone underestimates σ of quantised data (8-bit images
    at ~2 DN noise by 15 %), which made a 4.5σ cut remove ordinary noise pixels;
    clipping from the plain RMS instead can settle on a σ inflated by a wire lying
    along the edge.
    """
    a2 = np.square(resid)
    sample = a2[::4] if a2.size >= 400 else a2
    k = sample.size // 2  # the upper median: a partition, without np.median's copies
    sig = 1.4826 * float(np.sqrt(np.partition(sample, k)[k]))
    largest = float(a2.max()) if a2.size else 0.0
    for _ in range(12):
        limit = 9.0 * sig * sig
        if largest < limit:
            inner_n, inner_sum = a2.size, float(a2.sum())
        else:
            inside = a2 < limit
            inner_n = int(np.count_nonzero(inside))
            inner_sum = float(np.dot(a2, inside))
        if inner_n < 8:
            break
        new = np.sqrt(inner_sum / inner_n) / 0.98658
        done = abs(new - sig) < 0.01 * sig
        sig = new
        if done:
            break
    return sig or 1e-6


def robust_sigma_rows(resid, n):
    """:func:`robust_sigma` of each row of `resid` (M x N, padded), over its first
    `n` (M) values, in one set of array operations (the same sample, start and
    clipping; the order of summation may differ in the last bits)."""
    if not len(n):
        return np.zeros(0)
    a2 = np.square(resid)
    col = np.arange(a2.shape[1])
    valid = col < n[:, None]
    if (n >= 400).all():  # every fourth value of every row: only those columns
        sample, values = valid[:, ::4], a2[:, ::4]
    else:
        sample, values = valid & (col % np.where(n >= 400, 4, 1)[:, None] == 0), a2
    size = sample.sum(axis=1)
    # the upper median of each row's sample, by one partition at the rows' middles
    middle = size // 2
    ordered = np.partition(np.where(sample, values, np.inf), sorted(set(middle.tolist())), axis=1)
    sig = 1.4826 * np.sqrt(ordered[np.arange(len(n)), middle])
    a2 = np.where(valid, a2, np.inf)  # the padding is never inside a limit
    going = np.ones(len(n), bool)
    for _ in range(12):
        inside = a2 < 9.0 * (sig * sig)[:, None]
        inner_n = inside.sum(axis=1)
        going &= inner_n >= 8
        if not going.any():
            break
        new = np.sqrt(np.where(inside, a2, 0.0).sum(axis=1) / np.maximum(inner_n, 1)) / 0.98658
        done = np.abs(new - sig) < 0.01 * sig
        sig = np.where(going, new, sig)
        going &= ~done
        if not going.any():
            break
    return np.where(sig > 0, sig, 1e-6)


#: Half-width of a marker's edge zone, in edge widths s: the pixels whose edge
#: coordinate u = (R - d)/s lies within ±3, where the blurred edge carries the
#: centre's and radius' information (Φ(u) is 0.13 % from its levels beyond it).
EDGE_ZONE = 3.0


def in_edge_zone(u):
    """Flags of the pixels (edge coordinates `u` = (R - d)/s) in the edge zone, |u| < :data:`EDGE_ZONE`."""
    return np.abs(u) < EDGE_ZONE


#: Pixels this many robust σ (:func:`robust_sigma`) off the model are an occluder's
#: (a wire or a speck in the ring), by :func:`cut_occluders` and the fits' quick
#: "nothing to cut" tests before it.
OCCLUDER_SIGMAS = 4.5


def occluder_group(edge_width) -> float:
    """Fewest pixels (a float) of a connected group of outlying pixels that
    :func:`cut_occluders` takes for an occluder, at edge width `edge_width` (px): the
    area of a disc of one edge width's radius, π·s², and at least 3 pixels.

    Anything in front of the target is seen through the same optics as the marker,
    so its outlying pixels form a patch at least about as wide as the blur. A
    smaller group is the tail of the pixel noise: JPEG's blocks and ringing put
    single pixels and pairs beyond 4.5 robust σ in most rings of a compressed
    photo (on the full discorpy 06 frame, s ≈ 2.3 px: 1000 lone pixels and 230
    pairs over its 1900 rings), and cutting one, grown by 2 px with its sectors'
    edge pixels dropped, took a quarter of a 5 px dot's edge away: the fit then
    walked off by up to 1.8 px (60 dots moved over 0.3 px). The rendered dust specks
    (radius 1.2-2.8 px, blur σ 1 px) leave groups of 10 pixels and more."""
    return max(np.pi * float(edge_width) ** 2, 3.0)


def occluder_groups(keep, resid, sigma, u, ring_idx, shape, least):
    """`keep` with the outlying pixels (False) of connected groups (8-connected, on
    the patch of `shape`) of fewer than `least` pixels kept after all (the noise's
    tail), and, of the groups left, those the edge itself accounts for, moved and
    widened there (:func:`_edge_misfit`): (occluders, groups), flags to keep of
    the ring's pixels. `resid` are the ring's residuals, `sigma` their noise σ, `u`
    the ring pixels' edge coordinate (R - d)/s."""
    out = np.zeros(shape, np.uint8)
    outlying = np.flatnonzero(~keep)
    out.reshape(-1)[ring_idx[outlying]] = 1  # a view
    n, labels = cv2.connectedComponents(out, connectivity=8)
    label = labels.reshape(-1)[ring_idx[outlying]]
    # a group's area is the count of its pixels, every one of them an outlying ring
    # pixel (connectedComponentsWithStats' statistics cost three times the labelling)
    small = np.bincount(label, minlength=n) < least
    small[0] = False  # the background label
    groups = keep.copy()
    groups[outlying[small[label]]] = True
    misfit = small | _edge_misfit(label, resid[outlying], u[outlying], sigma, n)
    misfit[0] = False
    occluders = keep.copy()
    occluders[outlying[misfit[label]]] = True
    return occluders, groups


def _edge_misfit(label, resid, u, sigma, n):
    """Flags of the `n` groups (`label` of each outlying pixel, its residual `resid`
    and edge coordinate `u`) that are the edge's own misfit, not an occluder: all
    their pixels in the edge zone (|u| < 3), and none of them more than 4.5σ
    (`sigma`) off once the edge is moved and widened there, by the least-squares
    combination of the model's derivatives in the edge's position and width,
    φ(u) and u·φ(u) (their common factor, the contrast over the edge width, is a
    constant of the fit).

    An interlaced field, a sharpening halo or JPEG's ringing along the edge leaves
    bands of outlying pixels the size of an occluder (π·s² and more) just where
    the edge is; the edge a little off or sharper there accounts for them (the
    streaks the cut took on the UCL laparoscope photos: to within 0.6-3.9σ).
    Anything in front of the disc or its background is another object: a speck, a
    neighbouring dot, a displaced block leave 11-43σ once the edge is moved
    (rendered scenes, UCL). Cut, the bands took a wedge of edge where the profile
    was merely off, and the centres moved by up to 1 px either way."""
    zone = in_edge_zone(u)
    wholly = np.ones(n, bool)  # groups with all their pixels in the edge zone
    wholly[label[~zone]] = False
    wholly[0] = False  # the background label, which has no pixels
    if not wholly.any():
        # a pixel beyond the zone leaves its group's worst at inf below: no group is
        # the edge's misfit, and the least-squares fit is not needed (a dense grid's
        # occluders are neighbouring dots' flanks, which reach past the zone)
        return wholly
    phi = np.exp(-0.5 * u * u)
    phu = phi * u
    sums = [np.bincount(label, w, minlength=n) for w in (phi * phi, phi * phu, phu * phu, phi * resid, phu * resid)]
    aa, ab, bb, ar, br = sums
    det = aa * bb - ab * ab
    solvable = det > 1e-9 * aa * bb
    det[~solvable] = 1.0
    move, widen = np.where(solvable, (bb * ar - ab * br) / det, 0.0), np.where(solvable, (aa * br - ab * ar) / det, 0.0)
    left = np.abs(resid - move[label] * phi - widen[label] * phu)
    worst = np.zeros(n)
    np.maximum.at(worst, label, np.where(zone, left, np.inf))
    return solvable & (worst < OCCLUDER_SIGMAS * sigma)


def cut_occluders(resid, u, resolve, ring_idx, shape, *, least=3.0):
    """The ring pixels to keep and those an occluder or the edge's misfit leaves,
    (keep, seen), flags of the ring's pixels; or None when nothing is to be cut.

    Pixels more than 4.5 robust σ off the model, in connected groups of at least
    `least` pixels (:func:`occluder_group`: smaller groups are the noise's tail) that
    the edge moved or widened there does not account for (:func:`_edge_misfit`:
    that is the edge's own shape), are a wire or a speck in the ring. `u` is the
    ring pixels' edge coordinate (R - d)/s. The levels behind `resid` were pulled by
    the occluder, so that first cut also chose ordinary pixels by their values (a
    truncation bias): ``resolve(keep)`` gives the residuals with the levels solved
    without it, the cut is made again against them (groups as before) and grown by
    2 px (:func:`grow_cut`): `keep`. `seen` leaves out every group of `least`
    pixels, the edge's misfit too, grown likewise: what the caller judges the
    edge's own misfit by (along much of the edge, an unexplained group among them
    is more of it). A quarter of the edge zone (|u| < 3) cut at first is the model
    not fitting the edge yet (a first iteration, a sharp or odd edge profile), not
    an occluder: None; so is half of it in `seen` (a wire lying along the edge for
    60° of arc loses ~30 %), and no occluder among the groups.
    """
    sigma = robust_sigma(resid)
    keep = np.abs(resid) < OCCLUDER_SIGMAS * sigma
    if not keep.all():
        keep = occluder_groups(keep, resid, sigma, u, ring_idx, shape, least)[0]
    edge_zone = in_edge_zone(u)
    # shares of the edge zone kept by counts (ndarray.mean's Python overhead was a
    # tenth of an examination; the same value: whole numbers over whole numbers)
    zone_n = max(np.count_nonzero(edge_zone), 1)  # none: nothing kept in it, None as before
    if keep.all() or np.count_nonzero(keep & edge_zone) / zone_n <= 0.75:
        return None
    resid = resolve(keep)
    sigma = robust_sigma(resid[keep])
    keep, seen = occluder_groups(np.abs(resid) < OCCLUDER_SIGMAS * sigma, resid, sigma, u, ring_idx, shape, least)
    if keep.all():
        return None
    seen = grow_cut(seen, ring_idx, shape)
    if not np.count_nonzero(seen & edge_zone) / zone_n > 0.5:
        return None
    return grow_cut(keep, ring_idx, shape), seen



def nothing_to_cut(resid) -> bool:
    """True when no residual (DN) lies beyond :data:`OCCLUDER_SIGMAS` robust σ
    (:func:`robust_sigma`): the test :func:`cut_occluders` begins with, by which
    nothing is to be cut."""
    return bool((np.abs(resid) < OCCLUDER_SIGMAS * robust_sigma(resid)).all())


def damped_normal_matrix(A, lam):
    """A + lam·diag(A): the Levenberg-Marquardt normal matrix (a copy; the same
    values as adding the diagonal matrix, without its two 8x8 temporaries)."""
    damped = A.copy()
    diagonal = damped.reshape(-1)[:: A.shape[0] + 1]  # a view
    diagonal += lam * A.reshape(-1)[:: A.shape[0] + 1]
    return damped


def solve_lu(A, b):
    """x of A·x = b for one marker's small system (8x8), by OpenCV's LU with partial
    pivoting: LAPACK's answer to rounding (1e-16 relative), without numpy.linalg's
    per-call checks.

    Raises
    ------
    FitError
        `A` is singular: the marker's edge model is degenerate.
    """
    ok, x = cv2.solve(A, b.reshape(-1, 1), flags=cv2.DECOMP_LU)
    if not ok:
        raise FitError("the marker's edge model is degenerate (no edge in the ring)")
    return x.reshape(-1)

def sector_count(radius) -> int:
    """Number of angular sectors of a marker's edge at `radius` px: ~1 px of arc each,
    at least 16. (At least 16, not more: the edge of a 3 px marker crosses ~19 pixels,
    and sectors narrower than a pixel are left without edge pixels.)"""
    return max(16, int(round(2 * np.pi * float(radius))))


def sector_index(psi, radius):
    """Angular sector (:func:`sector_count` of them at `radius` px) of each direction
    `psi` (rad, image axes), and the number of sectors."""
    n_sec = sector_count(radius)
    return ((psi + np.pi) * (n_sec / (2 * np.pi))).astype(np.int64) % n_sec, n_sec


def sector_edge_offsets(sector, n_sec, g, resid, g_cos, g_sin, *, drop=None):
    """The edge's radial offset in each sector of arc, from that sector's pixels alone.

    One Gauss-Newton step of the edge model, δₖ = Σ gᵢeᵢ / Σ gᵢ² over the sector's
    pixels (g = ∂I/∂R, e the residual, both per pixel), placed along the sector's
    g²-weighted mean direction (`g_cos`, `g_sin`: g·cos ψ and g·sin ψ per pixel).
    Sectors with less than a tenth of the median information Σg², or flagged in
    `drop`, are left out.

    Returns
    -------
    delta, angle, information : numpy.ndarray
        Per kept sector: the offset (px), the direction (rad) and Σg² (DN²/px²).

    Raises
    ------
    FitError
        Fewer than 12 sectors are kept.
    """
    den = np.bincount(sector, g * g, minlength=n_sec)
    num = np.bincount(sector, g * resid, minlength=n_sec)
    cs = np.bincount(sector, g * g_cos, minlength=n_sec)
    sn = np.bincount(sector, g * g_sin, minlength=n_sec)
    positive = den[den > 0]
    good = den > 0.1 * fast_median(positive) if positive.size else den > 0
    if drop is not None:
        good &= ~drop
    need = sectors_needed(n_sec)
    if good.sum() < need:
        raise FitError(f"only {int(good.sum())} edge sectors carry information (need {need})")
    return num[good] / den[good], np.arctan2(sn[good], cs[good]), den[good]


def sectors_needed(n_sec):
    """Edge sectors (of `n_sec`, an int or an integer array) that must carry
    information for a fit's edge to count as seen: a third of them, and at least 12,
    or half of them on a marker under 4 px (16-24 sectors of ~1 px of arc, where a
    blurred JPEG edge leaves a few without information): still enough for the second
    harmonic of the circularity.

    A third: a fit to a short arc can be far off and look fine. On a full UCL
    laparoscope frame a dot inside the coarse disc of the card's dark surround (a
    neighbour candidate whose pixels are left out) was fitted on 23 of its 94
    sectors, 4 px from its centre with a round edge and status ok. Whole markers, a
    wire's cut and the photos' dense grids keep more than half (the rendered
    distractor scene's least 0.51, the photos' 0.57)."""
    return np.maximum(np.minimum(12, np.maximum(8, n_sec // 2)), -(-n_sec // 3))


def fast_median(values) -> float:
    """np.median of a 1-D array by one sort (np.median's checks and copies cost
    more than the sort itself on a few thousand values).

    A sort, not a partition: the grey levels and pixel differences this is asked
    for hold few distinct values (a reduced 8-bit image's row differences), where
    numpy's introselect degrades and the SIMD sort does not. The median is the same
    value either way.

    Whole numbers within the int16 range (an integer image's grey levels and their
    differences, held as floats) are sorted as int16 by numpy's radix sort: a third
    to a fifth of the float sort's time on a few thousand values, and the same
    median (a zero's sign aside)."""
    k = values.size // 2
    ordered = _sorted(values)
    if values.size % 2:
        return float(ordered[k])
    return 0.5 * (float(ordered[k - 1]) + float(ordered[k]))


#: Fewest values :func:`fast_median` tries to sort as int16: below it the float
#: sort is as quick as the test.
_INT_SORT_FROM = 256


def _sorted(values) -> np.ndarray:
    """`values` (1-D) sorted: as int16 (numpy's radix sort) when every one of them is
    a whole number in its range, else as they are."""
    if values.dtype.kind == "f" and values.size >= _INT_SORT_FROM:
        with np.errstate(invalid="ignore"):  # NaN, inf or out of range: caught by the comparison
            whole = values.astype(np.int16)
        if (whole == values).all():
            return np.sort(whole, kind="stable")
    return np.sort(values)


def harmonic_circularity(deviation, cos_psi, sin_psi, radius) -> float:
    """1 - 2·|second harmonic of the radial deviation|/R: the minor/major axis ratio
    of a near-circle, from edge points' radial deviations (px) from a circle of
    `radius` (px) in directions ψ given by their cosines and sines.

    Deviations, not radii: with sectors missing (an occluder) the radius itself
    would leak into the harmonic and fake an ellipse.
    """
    scale = 2.0 / max(deviation.size, 1)
    a2 = scale * np.dot(deviation, cos_psi * cos_psi - sin_psi * sin_psi)  # cos 2ψ
    b2 = scale * np.dot(deviation, 2.0 * cos_psi * sin_psi)  # sin 2ψ
    return float(1.0 - 2.0 * np.hypot(a2, b2) / radius)



def points_circularity(ex, ey, cx, cy, radius) -> float:
    """:func:`harmonic_circularity` of edge points (`ex`, `ey`, px) around a circle
    centred on (`cx`, `cy`) of `radius` (px): 1 for points on it."""
    dx, dy = ex - cx, ey - cy
    dist = np.maximum(np.hypot(dx, dy), 1e-12)
    return harmonic_circularity(dist - radius, dx / dist, dy / dist, radius)

def check_contrast(contrast, sigma2) -> None:
    """Raise FitError unless the marker's contrast (DN) exceeds 3x the noise σ (σ² in DN²)."""
    if not abs(contrast) > 3.0 * np.sqrt(sigma2):
        raise FitError(
            f"marker edge has too little contrast ({contrast:.1f} DN against noise {np.sqrt(sigma2):.1f} DN)",
            reason="low_contrast",
        )


def check_radius(radius, var_radius) -> None:
    """Raise FitError unless the fitted radius (px) is positive and determined: at least
    twice its standard deviation (``var_radius`` in px²).

    The disc model takes a negative radius as well as a positive one (its edge term
    depends on the distance from the edge), and a candidate with no disc in it (a
    speck of noise on a faint background) can end there, with a radius of 0.05-13 px
    of either sign and a standard deviation of 3-6000 px: a marker no one can place.
    A real marker's radius is known to a small fraction of it (0.01 px of 10 px)."""
    if not (radius > 0.0 and 4.0 * var_radius < radius * radius):
        raise FitError(
            f"the marker's fitted radius ({radius:.2f} ± {np.sqrt(max(var_radius, 0.0)):.2f} px) "
            "is not a disc's (no marker edge in the ring)"
        )


def bounded_edge_width(new, old):
    """An updated edge width s (px) kept within [old/2, 2·old] and never below 0.3 px:
    an imaged edge is never sharper than the pixel's own width (s >= sqrt(1/12)).

    A float for floats (one marker's fit, where numpy calls on scalars would cost
    more than the rule), element-wise for arrays (many markers' rows)."""
    if isinstance(new, np.ndarray):
        return np.minimum(np.maximum(np.maximum(new, 0.3), 0.5 * old), 2.0 * old)
    return float(min(max(new, 0.3, 0.5 * old), 2.0 * old))


def lost_sectors(cut_sectors, n_sec, *, most=0.25):
    """Edge sectors to drop: those holding cut edge pixels, and two neighbours each side.

    `cut_sectors` are the sector indices (0 … n_sec - 1) of the edge-zone pixels the
    outlier cut removed. When more than the fraction `most` of the sectors lost
    pixels, that is the model not fitting the edge yet (a first iteration, a sharp
    or odd edge profile), not occlusion: no sector is dropped, and the fit's own
    outlier handling still applies.
    """
    lost = np.bincount(cut_sectors, minlength=n_sec) > 0
    n_lost = np.count_nonzero(lost)
    if n_lost / n_sec > most:
        lost[:] = False
    elif n_lost:
        # each lost sector and two neighbours each side, round the circle
        lost[(np.flatnonzero(lost)[:, None] + np.arange(-2, 3)) % n_sec] = True
    return lost
