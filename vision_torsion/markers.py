"""Finding and fitting circular markers: ``find_markers``.

The paper's chain is edge points, a least-squares circle, its centre. Here:

1. coarse candidates, robust to uneven lighting (:mod:`.detect`);
2. each candidate judged: cut by the border, too small or large, or not round are
   reported with that status, not fitted;
3. a start from the thresholded intensity centroid in full resolution;
4. by default (``fit="pixels"``), the maximum-likelihood fit of the blurred-disc
   model to the pixels around the edge (:mod:`.pixelfit`), which reaches the
   Cramér-Rao bound; or the paper's chain done carefully: sub-pixel edge points
   from the edge-profile model (:mod:`.edges`) alternated with a circle fit
   (:mod:`.circlefit`: ``geometric``, the paper's ``algebraic``, or an ``ellipse``
   for oblique views) until the centre moves less than 1e-3 px.

Coordinates are image pixels (x, y), origin at the centre of the top-left pixel,
x to the right, y downwards.

Failure modes (reported per marker in the ``status`` column, with a ``message``):
``border`` (cut by the image border), ``too_small``, ``too_large``, ``not_round``,
``occluded`` (the fitted edge is asymmetric about its centre, or an arc of it lies
off the outline the rest follows: part of the marker hidden or cut by an edge),
``near_edge`` (a candidate beside it that is no marker lay over its edge, and fitted
with those pixels it is not ``ok``; or a shadow's or a light's edge crosses it, which
the fit's lighting gradient cannot follow; or its outline is stretched towards a dark
region left out of its fit; or, fitted as an ellipse, its ``ok`` neighbours are rounder
and sharper),
``low_contrast`` and ``fit_failed``; ``ok`` otherwise.
"""

from __future__ import annotations

import logging
import math
import sys
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from .detect import (
    COARSE_MIN_AXIS_RATIO,
    Blob,
    default_radius_range,
    detect_blobs,
    disc_inside,
    is_coarse_disc,
)
from .errors import FitError, VisionTorsionError
from .images import grey_array_and_blocks
from .pixelfit import DiscFit, fit_disc, fit_discs, patch_extent
from .quality import STEEP_CUT_PX
from .ring import MarkerPatch, fast_median, marker_patch, normal_cdf, points_circularity
from .settings import MeasureSettings

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "Marker",
    "find_markers",
    "find_marker_list",
    "find_candidates",
    "fit_marker",
    "markers_to_frame",
    "MARKER_COLUMNS",
    "candidate_extent",
    "candidate_patch",
    "crowded_patch",
    "CROWDED_MESSAGE",
    "UNEVEN_LIGHT_MESSAGE",
    "BLURRED_NEIGHBOUR_MESSAGE",
    "MERGED_END_MESSAGE",
    "UNLIKE_NEIGHBOURS_MESSAGE",
    "UNEVEN_SHIFT_PX",
    "UNEVEN_SHIFT_SIGMAS",
    "STEEP_CUT_PX",
    "STEEP_EDGE_NOISE_TIMES",
    "STEEP_EDGE_MESSAGE",
    "edge_asymmetry_px",
    "excluding_neighbours",
    "near_candidates",
    "neighbour_reach",
    "neighbours_of",
]

logger = logging.getLogger(__name__)

#: Columns of the table :func:`find_markers` returns, in order.
MARKER_COLUMNS = [
    "x_px",
    "y_px",
    "radius_px",
    "x_std_px",
    "y_std_px",
    "xy_cov_px2",
    "radius_std_px",
    "residual_rms_px",
    "n_edge_points",
    "contrast_dn",
    "circularity",
    "edge_width_px",
    "steep_cut",
    "status",
    "message",
]


@dataclass(frozen=True)
class Marker:
    """One marker: fitted centre with its uncertainty, or a status saying why not.

    Attributes
    ----------
    x_px, y_px : float
        Sub-pixel centre (px); NaN when not fitted.
    radius_px : float
        Radius (px); for an ellipse fit, the geometric mean of the semi-axes.
    x_std_px, y_std_px, xy_cov_px2 : float
        Standard uncertainties of the centre (px) and their covariance (px²).
    radius_std_px : float
        Standard uncertainty of the radius (px).
    residual_rms_px : float
        RMS distance of the inlier edge points from the fitted curve (px).
    n_edge_points : int
        Edge points kept by the fit.
    contrast_dn : float
        Inside minus outside grey level at the centre (DN; negative for dark markers).
    circularity : float
        Minor over major axis of the edge (1 for a perfect circle).
    edge_width_px : float
        Fitted edge width s (px): blur and pixel size combined.
    steep_cut : bool
        A region as dark (bright) as the marker, such as an edge or a shadow, lay
        within its ring and was cut (:attr:`~vision_torsion.pixelfit.DiscFit.steep_cut`):
        the centre is good to :data:`STEEP_CUT_PX`, not to its std. An image with such a
        target marker is ``suspect`` (:mod:`vision_torsion.quality`).
    status : str
        ``ok`` or the failure mode.
    message : str
        Why, when status is not ``ok``; for an ``ok`` marker seen obliquely (its
        edge an ellipse), that and the ellipse's axis ratio; for one whose ring held
        a region as dark (bright) as itself, :data:`STEEP_CUT_MESSAGE`.
    """

    x_px: float
    y_px: float
    radius_px: float
    x_std_px: float = np.nan
    y_std_px: float = np.nan
    xy_cov_px2: float = np.nan
    radius_std_px: float = np.nan
    residual_rms_px: float = np.nan
    n_edge_points: int = 0
    contrast_dn: float = np.nan
    circularity: float = np.nan
    edge_width_px: float = np.nan
    steep_cut: bool = False
    status: str = "ok"
    message: str = ""

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def cov(self) -> np.ndarray:
        """2x2 covariance of the centre (px²)."""
        return np.array([[self.x_std_px**2, self.xy_cov_px2], [self.xy_cov_px2, self.y_std_px**2]])


def markers_to_frame(markers) -> pd.DataFrame:
    """Markers as a pandas DataFrame with :data:`MARKER_COLUMNS`."""
    import pandas as pd  # here: measuring alone (a session worker) never needs it

    # flat fields: plain tuples, not dataclasses.asdict's recursive copies (a photo of
    # a dot grid has hundreds of markers)
    return pd.DataFrame.from_records(
        [tuple(getattr(m, c) for c in MARKER_COLUMNS) for m in markers], columns=MARKER_COLUMNS
    )


def is_frame(obj) -> bool:
    """True for a pandas DataFrame, without importing pandas (if it is not loaded,
    `obj` cannot be one)."""
    pd = sys.modules.get("pandas")
    return pd is not None and isinstance(obj, pd.DataFrame)


def _rejected(blob: Blob, status: str, message: str) -> Marker:
    return Marker(x_px=blob.x, y_px=blob.y, radius_px=blob.radius, status=status, message=message)


#: Coarse axis ratio a candidate needs with the ellipse fit (oblique views); the
#: others need :data:`~vision_torsion.detect.COARSE_MIN_AXIS_RATIO` (with the fill,
#: :func:`~vision_torsion.detect.is_coarse_disc`): only gross non-discs are rejected
#: here, roundness is judged on the fitted edge (:func:`min_circularity`).
_MIN_AXIS_RATIO = {"ellipse": 0.4}


def min_circularity(radius: float) -> float:
    """Smallest edge axis ratio (minor/major, :attr:`Marker.circularity`) of a marker
    judged round, for a fitted `radius` (px): 1 - max(0.2, 1 px / radius).

    0.8 passes a disc seen 35° off-axis and rejects anything visibly oval. Below
    5 px the limit is an absolute 0.5 px of second-harmonic edge deviation: on
    small discs pixelation, blur and JPEG blocks move sector edge points by a
    few tenths of a pixel whatever the radius, which a relative limit would
    call "not round".
    """
    return 1.0 - max(0.2, 1.0 / max(float(radius), 1e-9))


def _judge(blob: Blob, shape, r_min, r_max, fit) -> Marker | None:
    if blob.touches_border or not disc_inside(shape, blob.x, blob.y, blob.radius):
        return _rejected(blob, "border", "cut by the image border")
    if blob.radius < 0.8 * r_min:
        return _rejected(blob, "too_small", f"radius {blob.radius:.1f} px is below the smallest {r_min:g} px")
    if blob.radius > 1.2 * r_max:
        return _rejected(blob, "too_large", f"radius {blob.radius:.1f} px is above the largest {r_max:g} px")
    if not is_coarse_disc(blob, min_axis_ratio=_MIN_AXIS_RATIO.get(fit, COARSE_MIN_AXIS_RATIO)):
        return _rejected(
            blob,
            "not_round",
            f"not round (axis ratio {blob.elongation:.2f}, fill {blob.fill:.2f})",
        )
    return None


def candidate_extent(r0, edge_width):
    """Half-size (px) of the square around a blob (coarse radius `r0`) holding the
    start's outer ring (to 1.15·r0 + 7 px) and the fit's ring, with 1 px more for
    the coarse centre's error."""
    return np.maximum(1.15 * r0 + 8.0, patch_extent(r0, edge_width) + 1.0)


def _start(patch: MarkerPatch, blob: Blob, *, crowded: bool = False):
    """Centre, radius and the two grey levels from a thresholded intensity centroid
    in full resolution: (x, y, r) in px and (outside, inside) in DN. `crowded` (a
    :func:`crowded_patch`): the outside level from the pixels of the marker's side of
    the gaps, from 1 px beyond its coarse edge on (the outer ring lies on the
    neighbours' sides)."""
    r0 = blob.radius
    d2 = patch.squared_distance(blob.x, blob.y)
    r_in = 1.15 * r0 + 3  # generous: the coarse radius is good to about a pixel
    beyond = d2 > r_in**2
    if crowded and patch.excluded is not None:
        outside = patch.values[~patch.excluded & (d2 > (r0 + 1.0) ** 2) & (d2 < (r_in + 4.0) ** 2)]
        beyond |= patch.excluded
    elif patch.excluded is not None:
        beyond |= patch.excluded  # a neighbour's pixels: left out like the background
        outside = patch.values[beyond & ~patch.excluded & (d2 < (r_in + 4.0) ** 2)]
    else:
        outside = patch.values[beyond & (d2 < (r_in + 4.0) ** 2)]
    inside = patch.values[d2 < (0.6 * r0) ** 2]
    if outside.size < 8 or inside.size < 4:
        raise FitError("too few pixels around the marker to start the fit")
    B, F = fast_median(outside), fast_median(inside)
    if B == F:
        raise FitError("the marker has no contrast", reason="low_contrast")
    w = patch.values - B
    w *= 1.0 / (F - B)
    # np.clip's values by two ufuncs, the zeros put by `where`, and no separate
    # w.any() (centroid checks the sum): on a few thousand pixels each call's
    # overhead is what counts
    np.minimum(np.maximum(w, 0.0, out=w), 1.0, out=w)
    np.copyto(w, 0.0, where=beyond)
    area, x, y = patch.centroid(w)
    if not area > 0:
        raise FitError("the marker has no contrast", reason="low_contrast")
    return x, y, np.sqrt(area / np.pi), (B, F)


def neighbour_reach(radius, edge_width):
    """How far (px) from a neighbouring candidate's centre its pixels are left out of
    a marker's fit: 1.15 times its coarse radius (good to ~10 %) plus its blurred
    edge (3s + 1 px). Floats or arrays of `radius`."""
    return 1.15 * radius + 3.0 * max(float(edge_width), 1.0) + 1.0


#: Elements of the (pairs x box x box) arrays :func:`_neighbour_cover` makes at a
#: time: a few hundred kB, which stay in the cache.
_COVER_BLOCK = 1 << 15


def _neighbour_cover(patches, owner, nb, edge_width) -> np.ndarray:
    """Flags of the pixel centres within reach of a neighbour (:func:`neighbour_reach`
    of its coarse radius: d² < reach²), for many patches at once.

    Parameters
    ----------
    patches : list of MarkerPatch
        The patches (only their shape and origin are used).
    owner : numpy.ndarray
        (k,) int: the patch of each (patch, neighbour) pair.
    nb : numpy.ndarray
        (k, 3) coarse circle (x, y, r in px) of each pair's neighbour.
    edge_width : float
        Edge width s (px) of :func:`neighbour_reach`.

    Returns
    -------
    numpy.ndarray
        Flags (bool) of every patch's pixels, flat like its values, the patches one
        after another.

    Notes
    -----
    Each pair is tested on the square box of pixels its reach can touch (2·reach + 4
    px a side: a quarter of a dense grid's patch) instead of the whole patch, and all
    pairs of a box size at once: on a photo of a dot grid each marker has eight
    neighbours, and one broadcast over the whole patch per marker would cost as
    much as the marker's start. The
    distances are the same floating-point operations as over the whole patch (the
    pixel's index plus the patch origin's offset from the neighbour, squared and
    summed), so the same pixels are flagged; a pixel outside the box is farther than
    the reach (d² >= dy², dx² whatever the rounding).
    """
    rows = np.array([p.shape[0] for p in patches], dtype=np.int64)
    cols = np.array([p.shape[1] for p in patches], dtype=np.int64)
    base = np.concatenate([[0], np.cumsum(rows * cols)])
    flags = np.zeros(int(base[-1]), bool)
    x0 = np.array([p.x0 for p in patches], dtype=np.int64)[owner]
    y0 = np.array([p.y0 for p in patches], dtype=np.int64)[owner]
    reach = neighbour_reach(nb[:, 2], edge_width)
    side = (2.0 * reach).astype(np.int64) + 4
    for size in np.unique(side).tolist():
        pairs = np.flatnonzero(side == size)
        for lo in range(0, pairs.size, max(1, _COVER_BLOCK // size**2)):
            p = pairs[lo : lo + max(1, _COVER_BLOCK // size**2)]
            k = owner[p]
            at_rows, dy2 = _box_axis(y0[p] - nb[p, 1], reach[p], rows[k], size)
            at_cols, dx2 = _box_axis(x0[p] - nb[p, 0], reach[p], cols[k], size)
            inside = dy2[:, :, None] + dx2[:, None, :] < (reach[p] ** 2)[:, None, None]
            at = (base[k, None] + at_rows * cols[k, None])[:, :, None] + at_cols[:, None, :]
            flags[at[inside]] = True
    return flags


def _box_axis(offset, reach, length, size):
    """One axis of :func:`_neighbour_cover`'s boxes: the pixel indices along it
    (pairs x `size`) and their squared distances (px²) from the neighbour, inf off
    the patch (`length` pixels along the axis; `offset` (px) the patch origin's
    coordinate minus the neighbour's)."""
    index = np.floor(-offset - reach).astype(np.int64)[:, None] - 1 + np.arange(size)
    d = index + offset[:, None]  # as np.arange(length) + offset: the same sums
    return index, np.where((index >= 0) & (index < length[:, None]), d**2, np.inf)


def _large_neighbour_cover(patch: MarkerPatch, nb, edge_width, own) -> np.ndarray:
    """Flags (flat like the patch) of the pixels left out for neighbours `nb` ((k, 3)
    coarse circles, px, none holding the marker's centre) more than 1.5 times the
    marker's `own` radius: those within reach (:func:`neighbour_reach`) and nearer
    to that neighbour's coarse edge than to the marker's own (see
    :func:`excluding_neighbours`)."""
    rows, cols = patch.shape
    reach = neighbour_reach(nb[:, 2], edge_width)
    dx = np.arange(cols) + (patch.x0 - nb[:, :1])
    dy = np.arange(rows) + (patch.y0 - nb[:, 1:2])
    d2 = dy[:, :, None] ** 2 + dx[:, None, :] ** 2
    inside = d2 < (reach**2)[:, None, None]
    # of a large neighbour's flagged pixels, those nearer this marker's coarse edge stay
    k, y, x = np.nonzero(inside)
    ox, oy, r_own = own
    ours = np.hypot(x + (patch.x0 - ox), y + (patch.y0 - oy)) - r_own <= np.sqrt(d2[k, y, x]) - nb[k, 2]
    inside[k[ours], y[ours], x[ours]] = False
    return inside.any(axis=0).ravel()


def excluding_neighbours(patches, owner, nb, edge_width, owns=None) -> list[MarkerPatch]:
    """`patches` with the pixels of neighbouring candidates flagged as excluded: within
    1.15 times their coarse radius (good to ~10 %) plus their blurred edge (3s + 1 px).

    Pair p is patch ``owner[p]`` and the coarse circle ``nb[p]`` (x, y, r in px) of a
    candidate near it. Given each marker's own coarse circle (rows of `owns`), of a
    neighbour more than 1.5 times its radius only the pixels nearer to that
    neighbour's coarse edge than to the marker's own: the 15 % margin of a large
    neighbour (9 px on a 60 px disc, 25 px on a dark surround of radius 165 px) would
    take the marker's own edge on that side, which moves the fit of a marker seen at
    an angle (an ellipse) by up to several px. Between alike markers of a dense grid
    the whole margin stays left out (the pixels between carry both blurred edges).
    A candidate whose coarse circle holds the marker's centre is no neighbour: it is
    the region the marker was found in (:func:`~vision_torsion.detect.detect_blobs`)."""
    nb = np.asarray(nb, dtype=np.float64).reshape(-1, 3)
    large = np.zeros(len(nb), bool)
    plain = np.ones(len(nb), bool)
    if owns is not None:
        own = np.asarray(owns)[owner]
        # a candidate whose coarse circle holds this marker's centre is the region
        # the marker was found inside, not a neighbour (detect looks into regions
        # that are no disc: a dot and the dark surround it merged with; a card's
        # dark surround cut by the border, whose circle covered dots of the card):
        # none of its pixels
        held = np.hypot(nb[:, 0] - own[:, 0], nb[:, 1] - own[:, 1]) < nb[:, 2]
        large = (nb[:, 2] > 1.5 * own[:, 2]) & ~held
        plain = ~large & ~held
    flags = _neighbour_cover(patches, owner[plain], nb[plain], edge_width)
    large_of: dict[int, list[int]] = {}
    for p in np.flatnonzero(large).tolist():
        large_of.setdefault(int(owner[p]), []).append(p)
    out, start = [], 0
    for k, patch in enumerate(patches):
        size = patch.values.size
        excluded = flags[start : start + size]  # a view: the flags are this call's own
        start += size
        if k in large_of:
            excluded |= _large_neighbour_cover(patch, nb[large_of[k]], edge_width, owns[k])
        out.append(
            MarkerPatch(patch.values, patch.shape, patch.x0, patch.y0, excluded) if excluded.any() else patch
        )
    return out


def _exclude_neighbours(patch: MarkerPatch, neighbours, edge_width, own=None) -> MarkerPatch:
    """`patch` with the pixels of `neighbours` ((k, 3) coarse circles x, y, r in px)
    flagged as excluded, given the marker's `own` coarse circle: one patch of
    :func:`excluding_neighbours`."""
    if neighbours is None or len(neighbours) == 0:
        return patch
    nb = np.asarray(neighbours, dtype=np.float64).reshape(-1, 3)
    owns = None if own is None else np.asarray([own], dtype=np.float64)
    return excluding_neighbours([patch], np.zeros(len(nb), np.int64), nb, edge_width, owns)[0]


def crowded_patch(patch: MarkerPatch, neighbours, edge_width, own) -> MarkerPatch:
    """`patch` with the pixels of `neighbours` ((k, 3) coarse circles x, y, r in px)
    flagged as excluded, each neighbour on its own side only: of the pixels within
    its reach (:func:`neighbour_reach`), those nearer to its coarse edge than to the
    marker's `own` (x, y, r in px).

    The mask of a dense grid: where the gap between dots is narrower than the
    neighbours' margins (a hexagonal grid of 8 px dots 3 px apart), the whole-margin
    mask of :func:`excluding_neighbours` covers the marker's own edge and every
    background pixel, and its fit has nothing to start from. Here the gap is split
    along its middle. The neighbours' blurred edges reach into the marker's half of
    the gap; in a regular grid they do so alike on every side, and the centre, by
    symmetry, stays where it is. Used only where the whole-margin mask left too
    little to fit (:func:`find_marker_list`), so a marker with room around it is
    fitted as before. A candidate whose coarse circle holds the marker's centre is
    no neighbour (the region the marker was found in)."""
    nb = np.asarray(neighbours, dtype=np.float64).reshape(-1, 3)
    nb = nb[np.hypot(nb[:, 0] - own[0], nb[:, 1] - own[1]) >= nb[:, 2]]
    if len(nb) == 0:
        return MarkerPatch(patch.values, patch.shape, patch.x0, patch.y0)
    excluded = _large_neighbour_cover(patch, nb, edge_width, own)
    return MarkerPatch(patch.values, patch.shape, patch.x0, patch.y0, excluded if excluded.any() else None)


def _prepared(image, blob: Blob, edge_width, neighbours):
    """The patch of pixels a marker's fit uses (neighbours' pixels flagged) and the
    fit's start from it (:func:`_start`).

    One patch for the start and every iteration: wide enough for the start's outer
    ring and for the edge ring at the widest edge, cut to the image near its border
    (the fits model the pixels there are).

    Raises
    ------
    FitError
        Too few pixels or no contrast to start from.
    """
    own = (blob.x, blob.y, blob.radius)
    patch = _exclude_neighbours(candidate_patch(image, blob, edge_width), neighbours, edge_width, own=own)
    return patch, _start(patch, blob)


def candidate_patch(image, blob: Blob, edge_width) -> MarkerPatch:
    """The square of pixels around `blob` a fit uses (:func:`candidate_extent`), cut to the image."""
    return marker_patch(image, blob.x, blob.y, candidate_extent(blob.radius, edge_width), clip=True)


def _prepared_all(image, blobs: list[Blob], circles: np.ndarray, rows, edge_width) -> list:
    """:func:`_prepared` of the candidates `rows` of `circles` (coarse circles x, y, r
    in px of all candidates; `blobs` those of `rows`), their neighbours those of
    :func:`near_candidates`: per candidate its (patch, start), or the FitError that stopped it.
    The neighbours' pixels are flagged for all patches at once
    (:func:`excluding_neighbours`)."""
    out: list = [None] * len(blobs)
    patches, which = [], []
    for j, blob in enumerate(blobs):
        try:
            patches.append(candidate_patch(image, blob, edge_width))
            which.append(j)
        except FitError as exc:
            out[j] = exc
    rows = np.asarray(rows, dtype=np.int64)[np.asarray(which, dtype=np.int64)]
    owner, near = [], []
    for k in range(0, rows.size, 256):  # neighbours of 256 markers at a time: a few MB at most
        mine, theirs = np.nonzero(near_candidates(circles, rows[k : k + 256], edge_width))
        owner.append(mine + k)
        near.append(theirs)
    owner = np.concatenate(owner) if owner else np.zeros(0, np.int64)
    near = np.concatenate(near) if near else np.zeros(0, np.int64)
    patches = excluding_neighbours(patches, owner, circles[near], edge_width, circles[rows])
    for j, patch in zip(which, patches):
        try:
            out[j] = patch, _start(patch, blobs[j])
        except FitError as exc:
            out[j] = exc
    return out


def fit_marker(
    image, blob: Blob, *, fit: str = "pixels", max_iter: int = 10, edge_width: float = 1.2, neighbours=None,
    block_px: int | None = None,
) -> Marker:
    """Fit one marker candidate to sub-pixel accuracy.

    Parameters
    ----------
    image : numpy.ndarray
        2-D grey image indexed ``[y, x]``.
    blob : Blob
        Coarse candidate from :func:`~vision_torsion.detect.detect_blobs`.
    fit : {"pixels", "geometric", "algebraic", "ellipse"}
        Marker-fit method (:data:`~vision_torsion.settings.FIT_METHODS`).
        (Polarity needs no option here: the models' two levels take either sign of
        contrast.)
    max_iter : int
        Edge/fit alternations at most (fits to edge points).
    edge_width : float
        Starting edge width s (px); a neighbouring marker's fitted width saves
        iterations.
    neighbours : array_like, optional
        (k, 3) coarse circles (x, y, radius in px) of other candidates close enough
        to reach into this marker's ring: their pixels are left out of the
        default fit (``fit="pixels"``; dense dot grids). The edge-point fits use
        a narrower band and ignore it. A default fit that fails among them is made
        once more with the gaps to them split (:func:`crowded_patch`).
    block_px : int, optional
        The compression blocks' side (px) of a JPEG's grey levels
        (:attr:`GreyImage.jpeg_block_px <vision_torsion.images.GreyImage.jpeg_block_px>`):
        the default fit's covariance is then taken from them
        (:func:`~vision_torsion.pixelfit.fit_disc`).

    Returns
    -------
    Marker
        Status ``ok`` with the centre and its covariance, or ``fit_failed`` /
        ``low_contrast`` / ``not_round`` / ``occluded`` with the reason.
    """
    if fit == "pixels":
        marker = _fit_pixels(image, blob, edge_width, neighbours, block_px=block_px)
        if marker.status == "fit_failed" and neighbours is not None and len(neighbours):
            # a dense grid: the neighbours' whole margins left too little; split the gaps
            crowded = _fit_pixels(image, blob, edge_width, neighbours, crowded=True, block_px=block_px)
            if crowded.ok:
                return crowded
        return marker
    try:
        patch, (cx, cy, r, levels) = _prepared(image, blob, edge_width, None)
        # the edge-point fits' modules only when asked for: the default fit (and the
        # start-up of every command that measures) does without them (~6 ms)
        from .circlefit import fit_circle_algebraic, fit_circle_geometric, fit_ellipse
        from .edges import edge_points

        s = float(edge_width)
        shape = None
        for _ in range(max_iter):
            ep = edge_points(image, cx, cy, r, edge_width=s, radial_shape=shape, patch=patch)
            w = 1.0 / ep.std_px**2
            if fit == "ellipse":
                ef = fit_ellipse(ep.x_px, ep.y_px, weights=w)
                nx_, ny_ = ef.x_px, ef.y_px
                nr = float(np.sqrt(ef.a_px * ef.b_px))
                cov = np.zeros((3, 3))
                cov[:2, :2] = ef.cov
                cov[2, 2] = np.nan
                rms, n_in = ef.residual_rms_px, int(ef.inliers.sum())
                shape = _ellipse_radial(ef)
            else:
                cf = (fit_circle_algebraic(ep.x_px, ep.y_px) if fit == "algebraic"
                      else fit_circle_geometric(ep.x_px, ep.y_px, weights=w, initial=(cx, cy, r)))
                nx_, ny_, nr, cov = cf.x_px, cf.y_px, cf.radius_px, cf.cov
                rms, n_in = cf.residual_rms_px, int(cf.inliers.sum())
            # the centre converges faster than radius and edge width, and is what counts
            moved = max(abs(nx_ - cx), abs(ny_ - cy))
            cx, cy, r, s = nx_, ny_, nr, ep.edge_width_px
            # linear convergence (ratio ~0.3): a last move of 1e-3 px leaves ~4e-4 px,
            # a sixth of the centre's noise on a good image (adds ~1.5 % in quadrature)
            if moved < 1e-3:
                break
    except FitError as exc:
        return _failed(blob, exc)
    circ = points_circularity(ep.x_px, ep.y_px, cx, cy, r)
    if fit != "ellipse" and circ < min_circularity(r):
        return _not_round(cx, cy, r, circ)
    return _whole(
        Marker(
            x_px=float(cx),
            y_px=float(cy),
            radius_px=float(r),
            x_std_px=float(np.sqrt(cov[0, 0])),
            y_std_px=float(np.sqrt(cov[1, 1])),
            xy_cov_px2=float(cov[0, 1]),
            radius_std_px=float(np.sqrt(cov[2, 2])) if np.isfinite(cov[2, 2]) else np.nan,
            residual_rms_px=float(rms),
            n_edge_points=n_in,
            contrast_dn=float(ep.foreground_dn - ep.background_dn),
            circularity=circ,
            edge_width_px=float(s),
        ),
        image.shape,
    )


def _fit_pixels(image, blob: Blob, edge_width, neighbours, *, crowded=False, block_px=None) -> Marker:
    """The pixel-model fit of one candidate, its neighbours' pixels left out with
    their whole margins (:func:`excluding_neighbours`) or, `crowded`, each on its
    own side of the gap (:func:`crowded_patch`)."""
    try:
        if crowded:
            patch = crowded_patch(candidate_patch(image, blob, edge_width), neighbours, edge_width,
                                  (blob.x, blob.y, blob.radius))
            cx, cy, r, levels = _start(patch, blob, crowded=True)
        else:
            patch, (cx, cy, r, levels) = _prepared(image, blob, edge_width, neighbours)
        fitted = fit_disc(image, cx, cy, r, edge_width=edge_width, levels=levels, patch=patch, block_px=block_px)
    except FitError as exc:
        return _failed(blob, exc)
    return _whole(_pixels_marker(fitted, crowded=crowded, patch=patch), image.shape)


def _whole(marker: Marker, shape) -> Marker:
    """`marker`, or status ``border`` when its fitted disc is not whole in the image."""
    if marker.ok and not disc_inside(shape, marker.x_px, marker.y_px, marker.radius_px):
        return Marker(
            x_px=marker.x_px,
            y_px=marker.y_px,
            radius_px=marker.radius_px,
            status="border",
            message="cut by the image border",
        )
    return marker


def _failed(blob: Blob, exc: FitError) -> Marker:
    status = "low_contrast" if exc.reason == "low_contrast" else "fit_failed"
    return _rejected(blob, status, str(exc))


def _not_round(cx, cy, r, circ) -> Marker:
    return Marker(
        x_px=cx,
        y_px=cy,
        radius_px=r,
        status="not_round",
        message=f"edge is not circular (axis ratio {circ:.3f}, below {min_circularity(r):.3f})",
    )


#: A pixel fit judged not round is a disc seen obliquely when an ellipse centred on
#: the fit's centre describes its per-sector edge points: their RMS distance from it
#: is at most this share of their RMS distance from the circle (:func:`_oblique`).
#: Discs seen obliquely leave well under it (rendered ellipses about 0.1, the tilted
#: card of the photos about 0.3, their edge points' own scatter); shapes that are no
#: such ellipse leave more (a teardrop about 0.6, a rectangle 0.8).
_OBLIQUE_RESIDUAL_SHARE = 0.4
#: Smallest axis ratio of such an ellipse (a disc seen 60° off-axis): beyond it the
#: circle's ring of pixels no longer holds the whole edge (a 0.6 ellipse of 25 px did
#: not converge).
_OBLIQUE_MIN_AXIS_RATIO = 0.5
#: ... and its RMS distance may hold, besides that share, this many times the edge
#: points' scatter from the pixel noise alone (:attr:`DiscFit.edge_noise_px`, added in
#: quadrature): the share alone asks a small dot's noisy edge points to lie on the
#: ellipse closer than their noise allows. Round dots' edge points lie within about
#: twice their noise figure of their circle (photographed grids: 95th percentile
#: 2.0-2.6), and so do small, blurred ellipses of their ellipse; a teardrop or a
#: rectangle leaves 12-47 times it. The figure counts the pixels' noise as
#: independent; a JPEG's 8x8 blocks and a colour camera's demosaicing make it
#: correlated over several pixels along the edge, which its sectors do not average
#: away: the GoPro fisheye's small, blurred dots (r 5-8 px, edge width 3-4 px,
#: foreshortened to 0.65-0.8 near the frame's border) lie 2.5-4 times their figure
#: from their ellipse. Hence four times; a small noisy teardrop that passes is
#: caught by its asymmetry (:func:`_occluded`).
_OBLIQUE_NOISE_TIMES = 4.0


def _oblique(f: DiscFit):
    """(axis ratio, RMS distance in px, its polar coefficients (A, B, C) of
    :func:`~vision_torsion.circlefit.centred_ellipse_polar`) of the ellipse centred on
    the pixel fit's centre through its per-sector edge points when it describes them
    (their RMS distance from it at most √((0.4·their RMS from the circle)² +
    (4·their noise figure)²): :data:`_OBLIQUE_RESIDUAL_SHARE`,
    :data:`_OBLIQUE_NOISE_TIMES`), else None.

    The centre stays the disc model's: an ellipse is symmetric about its centre, and
    so is the least-squares fit of the (symmetric) disc model to it, which lands on
    that centre (0.01 px on rendered ellipses of axis ratio 0.7). An edge-point
    ellipse fit's own centre gave no straighter rows (0.393 against 0.380 px on the
    UCL frame's 668 triples). A shape whose centre the disc model misses (a
    teardrop) is off any ellipse centred there."""
    from .circlefit import centred_ellipse_and_polar  # only for the few markers that need it

    found, polar = centred_ellipse_and_polar(f.edge_x_px - f.x_px, f.edge_y_px - f.y_px)
    if found is None:
        return None
    ratio, rms = found
    allowed = np.hypot(_OBLIQUE_RESIDUAL_SHARE * f.residual_rms_px, _OBLIQUE_NOISE_TIMES * f.edge_noise_px)
    if ratio < _OBLIQUE_MIN_AXIS_RATIO or not rms <= allowed:
        return None
    return ratio, rms, polar


#: Semi-axes' difference (px) of a fit's outline (its edge points' centred ellipse)
#: from which :func:`_merged_end` looks for a dark region at the ends of its major
#: axis: a region that stretched the outline by less moves the centre by less than
#: the issue's bound on an ``ok`` centre (0.5 px; rendered: moves of 0.58-0.62 px for
#: a difference of 0.77-0.79 px, 0.29-0.30 px for 0.48 px).
_MERGED_MIN_STRETCH_PX = 0.5
#: The band beyond that outline where a dark region left out of the fit shows:
#: directions within this angle (degrees) of either end of the major axis ...
_MERGED_WEDGE_DEG = 30.0
#: ... and distances from the outline of 1.5 to 3 edge widths s plus 1 px (a disc's
#: blurred edge there keeps 7 % of its contrast at most; the fit's edge zone ends
#: there); the band is a region's when at least this share of its pixels were left
#: out of the fit for a neighbouring candidate ...
_MERGED_LEFT_OUT_SHARE = 0.5
#: ... and their mean grey level is at least this share of the marker's contrast
#: from the background towards the marker's level.
_MERGED_DARK_SHARE = 0.5

#: The message of a marker whose outline is stretched towards a dark region left out
#: of its fit (:func:`_merged_end`).
MERGED_END_MESSAGE = (
    "its outline is an ellipse of axis ratio {ratio:.2f} whose major axis ends at a region left out of the fit "
    "(another candidate's), {dark:.0%} as dark as the marker within {reach:.1f} px of the outline: the region's "
    "blurred edge merges with the marker's and stretches the outline towards it, and the centre may be off by "
    "about {off:.1f} px (the semi-axes' difference)"
)


def _merged_end(f: DiscFit, patch: MarkerPatch | None, polar=None) -> Marker | None:
    """Status ``near_edge`` for a pixel fit whose outline is stretched towards a dark
    region left out of its fit, else None; `polar`, the outline's coefficients
    (:func:`~vision_torsion.circlefit.centred_ellipse_polar`) if :func:`_oblique`
    has fitted them.

    A disc, seen straight or obliquely, has background beyond its outline all round.
    A dark region whose blurred edge reaches the marker's (a dark rectangle 2-4 px
    from a 6 px dot, both blurred 3.5 px) merges with it: the fit's outline follows
    the region's edge on that side, an ellipse whose major axis points at the region,
    and the centre moves towards it by about the semi-axes' difference (3.0 px for an
    ellipse of 10.6 x 7.3 px at a 2 px gap, 1.35 px for 8.0 x 6.4 px at 3 px, 0.6 px
    for 6.6 x 5.8 px at 4 px). The region is a candidate of its own, left out of the
    fit (`patch`'s excluded pixels), so the fit's own checks never see it.

    Judged for fits whose outline's semi-axes differ by over
    :data:`_MERGED_MIN_STRETCH_PX` (first from the fit's circularity, free): at either
    end of the major axis, the pixels within :data:`_MERGED_WEDGE_DEG` of it, 1.5 s to
    3 s + 1 px beyond the outline (s the fitted edge width), at least
    :data:`_MERGED_LEFT_OUT_SHARE` left out and their mean level at least
    :data:`_MERGED_DARK_SHARE` of the contrast F - B from the background B towards the
    marker's level F. A neighbouring dot of a grid whose mask reaches that band lies
    beyond its own blurred edge there: on the photographed targets no ``ok`` fit with
    pixels left out had such a band (ellipses whose band a neighbour's mask covered by
    41-65 % had it at 0.02-0.04 of the contrast). Costs one pass over the patch, for
    those fits only."""
    if patch is None or patch.excluded is None:
        return None
    # 1 - circularity is twice the second harmonic over R: about (a - b)/R
    if not f.radius_px * (1.0 - f.circularity) > _MERGED_MIN_STRETCH_PX:
        return None
    if polar is None:
        from .circlefit import centred_ellipse_polar  # only for the few markers that need it

        polar = centred_ellipse_polar(f.edge_x_px - f.x_px, f.edge_y_px - f.y_px)
    A, B, C = polar
    h = float(np.hypot(B, C))
    if not A > h:
        return None  # no ellipse: the fit's own checks judged its shape
    semi_major, semi_minor = 1.0 / np.sqrt(A - h), 1.0 / np.sqrt(A + h)
    if not semi_major - semi_minor > _MERGED_MIN_STRETCH_PX:
        return None
    s = f.edge_width_px
    # the pixels of the annulus that can hold the band, then their offsets along the
    # major axis and 1/r² of the outline in their direction (no angles: products of
    # the offsets)
    d2 = patch.squared_distance(f.x_px, f.y_px)
    near = np.flatnonzero((d2 > (semi_minor + 1.5 * s) ** 2) & (d2 < (semi_major + 3.0 * s + 1.0) ** 2))
    xs, ys = patch.coordinates(near)
    dx, dy = xs - f.x_px, ys - f.y_px
    d2 = d2.take(near)
    major = 0.5 * np.arctan2(-C, -B)
    along = (dx * np.cos(major) + dy * np.sin(major)) / np.sqrt(d2)  # cosine of the angle to the major axis
    beyond = np.sqrt(d2) - 1.0 / np.sqrt(A + (B * (dx * dx - dy * dy) + 2.0 * C * dx * dy) / d2)
    band = (beyond > 1.5 * s) & (beyond < 3.0 * s + 1.0)
    wedge = np.cos(np.radians(_MERGED_WEDGE_DEG))
    contrast = f.foreground_dn - f.background_dn
    for at_end in (along > wedge, along < -wedge):
        pixels = near[band & at_end]
        if not pixels.size:
            continue
        left_out = float(np.mean(patch.excluded.take(pixels)))
        dark = float(np.mean(patch.values.take(pixels)) - f.background_dn) / contrast
        if left_out >= _MERGED_LEFT_OUT_SHARE and dark >= _MERGED_DARK_SHARE:
            return _near_edge(f, MERGED_END_MESSAGE.format(ratio=semi_minor / semi_major, dark=dark,
                                                           reach=3.0 * s + 1.0, off=semi_major - semi_minor))
    return None


#: A marker's edge is asymmetric about its centre (part of it hidden behind an
#: occluder, or cut by an edge) when the third radial harmonic of its per-sector edge
#: points about the fitted centre exceeds this share of the radius plus
#: :data:`_ASYMMETRY_NOISE_TIMES` times their noise figure. Any ellipse (a disc seen
#: at any angle, blurred) has no odd harmonic about its centre; a disc with a chord
#: cut off has, and the disc model's centre moves by about twice its amplitude
#: (rendered: 1.7-2.1 times; 0.5-1.5 px for an occluder over 2-4 px of a 10 px dot's
#: edge). The photographed dots of the benchmark's sets lie within 1 % of R
#: (discorpy), within the limit with its noise term on the UCL laparoscope frames
#: (2.8 % of R = 15 px) and above it on 2 of 400 of the GoPro fisheye's small,
#: blurred JPEG dots.
_ASYMMETRY_SHARE = 0.02
_ASYMMETRY_NOISE_TIMES = 3.0


def edge_asymmetry_px(f: DiscFit) -> float:
    """Amplitude (px) of the third radial harmonic of the pixel fit's per-sector edge
    points about its centre: their radial distances fitted by a Fourier series to
    the third harmonic in their direction (sectors an occluder took are missing, so
    the harmonics are fitted together, not read off one by one). Zero for a circle
    or any ellipse centred there; 0 for fewer than 7 edge points."""
    dx, dy = f.edge_x_px - f.x_px, f.edge_y_px - f.y_px
    if dx.size < 7:
        return 0.0
    r = np.hypot(dx, dy)
    z = (dx + 1j * dy) / np.where(r > 0, r, 1.0)
    z2 = z * z
    z3 = z2 * z
    design = np.stack([np.ones_like(r), z.real, z.imag, z2.real, z2.imag, z3.real, z3.imag], axis=1)
    coef = np.linalg.lstsq(design, r, rcond=None)[0]
    return float(np.hypot(coef[5], coef[6]))


def _neighbour_at_edge(f: DiscFit, patch: MarkerPatch | None) -> bool:
    """True when pixels of a neighbour left out of `patch` lie within the fit's edge
    zone (3s + 1 px beyond its radius): the edge points on that side sense the
    neighbour's blurred edge (two dots 1 px apart: 0.3 px of third harmonic, each
    fitted to 0.05 px)."""
    if patch is None or patch.excluded is None:
        return False
    reach = f.radius_px + 3.0 * f.edge_width_px + 1.0
    d2 = patch.squared_distance(f.x_px, f.y_px)
    return bool(np.any(patch.excluded & (d2 < reach * reach)))


#: A ``steep_cut`` fit is judged for asymmetry only when its edge points leave no
#: gap wider than this (degrees): a cut surround takes the sectors facing it (gaps of
#: 130-175 degrees on rendered dots beside a dark card edge), and a harmonic fitted to
#: the rest of the circle says nothing of a hidden part.
_STEEP_MAX_GAP_DEG = 90.0

#: The median absolute deviation of a normal variable in units of its σ.
_MAD_TO_SIGMA = 0.6745


def _edge_profile(f: DiscFit):
    """The pixel fit's per-sector edge points about its centre, in order of direction:
    (directions in rad, radial offsets from the circle in px)."""
    dx, dy = f.edge_x_px - f.x_px, f.edge_y_px - f.y_px
    order = np.argsort(np.arctan2(dy, dx))
    return np.arctan2(dy, dx)[order], np.hypot(dx, dy)[order] - f.radius_px


def _widest_gap_deg(psi) -> float:
    """The widest gap (degrees) between the directions `psi` (rad, in order) of a fit's
    edge points, around the circle; 360 for fewer than two."""
    if psi.size < 2:
        return 360.0
    return float(np.degrees(np.max(np.diff(np.r_[psi, psi[0] + 2.0 * np.pi]))))


def _steep_cut_hides(f: DiscFit):
    """For a ``steep_cut`` fit: the noise figure (px) its asymmetry is judged against
    when the edge may hide a part of the marker, else None.

    A region as dark (bright) as the marker merged with it leaves the sectors facing
    it cut (a gap over :data:`_STEEP_MAX_GAP_DEG`) or bulging outwards; an occluder at
    the background's level or brighter over its edge hides a chord, the edge's deepest
    inward dip (three sectors' mean) beyond its largest outward bulge. The cut
    region's blurred edge inflates :attr:`DiscFit.edge_noise_px` (0.12-0.18 px beside
    a 255 DN clip, 0.02 px without); the scatter of the sectors' offsets about their
    neighbours' (the median absolute second difference, 0.03-0.05 px there) holds the
    noise without the occluder's smooth misfit, and the smaller of the two is used."""
    psi, delta = _edge_profile(f)
    if psi.size < 7 or _widest_gap_deg(psi) > _STEEP_MAX_GAP_DEG:
        return None
    smooth = (np.roll(delta, 1) + delta + np.roll(delta, -1)) / 3.0
    if not -smooth.min() > smooth.max():
        return None
    # the offsets' second differences: a smooth chord or bulge leaves them near zero
    # but at its two corners, which the median passes over; σ√6 for independent noise
    second = np.roll(delta, 1) - 2.0 * delta + np.roll(delta, -1)
    scatter = float(np.median(np.abs(second)) / (_MAD_TO_SIGMA * np.sqrt(6.0)))
    return min(f.edge_noise_px, scatter)


def _occluded(f: DiscFit, patch: MarkerPatch | None = None) -> Marker | None:
    """Status ``occluded`` for a fit whose edge is asymmetric about its centre, else
    None; not judged beside a neighbour (:func:`_neighbour_at_edge`, `patch` the fit's
    pixels).

    Asymmetric: the third harmonic (:func:`edge_asymmetry_px`) above
    :data:`_ASYMMETRY_SHARE` of the radius plus :data:`_ASYMMETRY_NOISE_TIMES` times
    the edge points' noise figure. A fit that cut a region as dark (bright) as the
    marker from its ring (``steep_cut``) is judged only when its edge may hide a part
    of it (:func:`_steep_cut_hides`, which also gives its noise figure): a cut
    surround's edge points sense that region (0.3-0.9 px of third harmonic beside a
    dark card edge, whose pixel fit is good to 0.1 px)."""
    noise = f.edge_noise_px
    if f.steep_cut:
        noise = _steep_cut_hides(f)
        if noise is None:
            return None
    limit = _ASYMMETRY_SHARE * f.radius_px + _ASYMMETRY_NOISE_TIMES * noise
    # the harmonic is part of the edge points' RMS distance from the circle (a/√2 of
    # it on evenly spread sectors; 1.5x for missing ones): most fits need not look
    if not 1.5 * np.sqrt(2.0) * f.residual_rms_px > limit:
        return None
    if _neighbour_at_edge(f, patch):
        return None
    a3 = edge_asymmetry_px(f)
    if not a3 > limit:
        return None
    return Marker(
        x_px=f.x_px,
        y_px=f.y_px,
        radius_px=f.radius_px,
        status="occluded",
        message=(f"the edge is not symmetric about the centre (third harmonic {a3:.2f} px, allowed "
                 f"{limit:.2f} px): part of the marker is hidden or cut by an edge, and its centre may be "
                 f"off by about {2 * a3:.1f} px"),
    )


#: Largest share of a fit's edge points that :func:`_hidden_arc` may take for one
#: hidden arc: an occluder over 5 px of a 10 px dot's edge hides a third of it;
#: beyond this the rest no longer pins an ellipse and its centre.
_ARC_MOST = 0.4
#: :func:`_hidden_arc` refits the pixels only when leaving the arc out moves the edge
#: points' centre by over this (px), and their RMS distance from their outline falls
#: by over :data:`_ARC_EDGE_RATIO` times. Rendered occluders that put a 10-15 px
#: dot's centre over 0.5 px off move it by 0.4-2 px there, at ratios of 3.5-18; the
#: photographed dots of ``benchmarks/bench_photos.py`` are refitted 0-3.4 % of them
#: a photo (0.6 % of 17000): their edges' own bumps spread over the circle.
_ARC_EDGE_PX = 0.2
_ARC_EDGE_RATIO = 2.0
#: Centre move (px) without the arc beyond which a marker is ``occluded``
#: (:func:`_hidden_arc`): half the error an ``ok`` centre may have (0.5 px, issue 31).
HIDDEN_ARC_PX = 0.25
#: ... when the ring's residual RMS (DN) also falls by over this factor without the
#: arc: the arc holds something that is not the marker (an occluder over a rendered
#: dot's edge: 2.2-8); an edge that is no model edge all round leaves its misfit in
#: the rest of the ring too (the photographed grid dots refitted: 1.0-1.8).
HIDDEN_ARC_NOISE_RATIO = 2.0
#: ... and when the move exceeds this many standard deviations of the refit's centre.
_ARC_MOVE_SIGMAS = 5.0

#: The message of an ``occluded`` marker whose edge holds an arc that is not its own
#: (:func:`_hidden_arc`).
HIDDEN_ARC_MESSAGE = (
    "an arc of the edge lies off the outline the rest of it follows: without the ring's pixels in directions "
    "{start:.0f} to {end:.0f} deg (counter-clockwise as displayed) its residual RMS falls from {noise:.1f} to "
    "{rest:.1f} DN (allowed {ratio:.0f} times) and the centre moves by {move:.2f} px (allowed {allowed} px) to "
    "({x:.2f}, {y:.2f}): part of the marker is hidden, and its centre may be off by about as much"
)


#: The upper triangle of a 5 x 5 matrix (its 15 entries, row by row) and, for each
#: entry of the matrix, its place in that list: :func:`_arc_search`'s normal
#: equations are kept as 15 sums.
_UPPER_5 = np.triu_indices(5)
_SYMMETRIC_5 = np.array([[min(i, j) * 5 - min(i, j) * (min(i, j) - 1) // 2 + abs(i - j) for j in range(5)]
                         for i in range(5)])


@lru_cache(maxsize=64)
def _arcs(n: int):
    """The arcs :func:`_arc_search` tries among `n` edge points, as two grids (read-only)
    of every start with every length: starts every n/16 points, four lengths from
    n/8 to :data:`_ARC_MOST` of them."""
    grid = np.meshgrid(np.arange(0, n, max(1, n // 16)),
                       np.unique(np.linspace(max(2, n // 8), int(_ARC_MOST * n), 4).astype(np.int64)), indexing="ij")
    for g in grid:
        g.flags.writeable = False
    return grid


def _arc_search(f: DiscFit) -> list:
    """The contiguous arcs of the pixel fit's per-sector edge points whose leaving out
    best explains their scatter about their outline, and what leaving each out
    changes: a list of (start direction, span in rad, the centre's move in px, the
    ratio of the points' RMS distance from their outline with and without the arc),
    empty for fewer than 12 edge points; the best arc first, then the best of those
    whose points lie on the other side of the rest's outline (inside it, where the
    first lies outside, or the reverse), if any.

    The outline is the edge's radial distance from the fitted centre as a Fourier
    series to the second harmonic (a circle, a shift of its centre and an ellipse:
    a disc seen at any angle), fitted by least squares. The arcs are, of those
    starting every n/16 of the n points and holding n/8 to :data:`_ARC_MOST` of
    them (four lengths), the ones whose leaving out drops the sum of squares most
    in units of the rest's variance: each candidate's normal equations from
    cumulative sums around the circle, one batched 5 x 5 solve for all. A hidden
    chord lies inside the outline of the rest, and the outline of all the points
    moves away from it, which leaves the opposite arc outside: leaving out either
    explains much of the scatter, and the wrong one may explain a little more
    (a third of a dot's edge hidden), hence the second."""
    dx, dy = f.edge_x_px - f.x_px, f.edge_y_px - f.y_px
    n = dx.size
    if n < 12:
        return []
    psi = np.arctan2(dy, dx)
    order = np.argsort(psi)
    psi, r = psi[order], np.hypot(dx, dy)[order]
    c, si = np.cos(psi), np.sin(psi)
    basis = np.stack([np.ones(n), c, si, c * c - si * si, 2.0 * c * si], axis=1)
    # per point: the 15 products of the basis (the normal matrix's upper triangle),
    # the basis times r and r², as rows; their running sums around the circle twice
    terms = np.concatenate([basis[:, _UPPER_5[0]] * basis[:, _UPPER_5[1]], basis * r[:, None], (r * r)[:, None]],
                           axis=1)
    cum = np.cumsum(np.concatenate([np.zeros((1, 21)), terms, terms]), axis=0)
    total = cum[n]

    def solved(sums):
        """The outline's coefficients and sum of squares from the sums (..., 21)."""
        b = sums[..., 15:20]
        coef = np.linalg.solve(sums[..., _SYMMETRIC_5], b[..., None])[..., 0]
        return coef, sums[..., 20] - (coef * b).sum(axis=-1)

    start, width = _arcs(n)
    arc_sums = (cum[start + width] - cum[start]).reshape(-1, 21)
    try:
        # all the points, then each arc left out: one batched solve
        p, ssr = solved(np.concatenate([total[None], total - arc_sums]))
    except np.linalg.LinAlgError:
        return []
    width = width.ravel()
    score = (ssr[0] - ssr[1:]) * (n - width - 5) / np.maximum(ssr[1:], 1e-24)
    # each arc's points' summed radial offset from the rest's outline: Σr - Σbasis·p
    # (the basis's sums are the products with its constant term, the first five)
    outside = arc_sums[:, 15] - (arc_sums[:, :5] * p[1:]).sum(axis=1) > 0.0
    best = int(np.argmax(score))
    other = np.flatnonzero(outside != outside[best])
    half = np.pi / n
    arcs = []
    for k in [best] + ([int(other[np.argmax(score[other])])] if other.size else []):
        first, w = int(start.flat[k]), int(width[k])
        ratio = math.sqrt(ssr[0] / (n - 5) / max(ssr[k + 1] / (n - w - 5), 1e-24))
        move = math.hypot(p[k + 1, 1] - p[0, 1], p[k + 1, 2] - p[0, 2])
        span = (psi[(first + w - 1) % n] - psi[first]) % (2.0 * np.pi) + 2.0 * half
        arcs.append((float(psi[first] - half), float(span), move, ratio))
    return arcs


def _hidden_arc(f: DiscFit, patch: MarkerPatch | None) -> Marker | None:
    """Status ``occluded`` for a fit an arc of whose edge is not its own, else None
    (and None without `patch`, the fit's pixels).

    An occluder over the edge hides a chord of the marker: the edge points there
    lie inside the outline that the rest of them follow, and the disc model's
    centre moves away from it, by 0.5 px for one over 2 px of a 10 px dot's edge
    whose third harmonic stays under :func:`_occluded`'s limit (an occluder that
    is not much brighter or darker than the background, or blurred). The arcs are
    found on the edge points (:func:`_arc_search`: the best, then the best on the
    other side of their outline); for each in turn, when leaving it out moves their
    centre by over :data:`_ARC_EDGE_PX` and their scatter drops
    :data:`_ARC_EDGE_RATIO` times, the marker is fitted again without the ring's
    pixels in a wedge of :data:`_ARC_MOST` of the turn about that arc
    (:func:`_without_arc`). ``occluded`` when that refit's centre is over
    :data:`HIDDEN_ARC_PX` and :data:`_ARC_MOVE_SIGMAS` of its standard deviations
    away and the ring's residual RMS is over :data:`HIDDEN_ARC_NOISE_RATIO` times
    the refit's: the arc held what the rest of the ring does not (on rendered
    occluders the refit is within 0.1 px of the truth), where an edge that is no
    model edge all round (a photographed dot's) leaves its misfit in the rest too.
    The refit's covariance counts the pixels' errors as independent (a JPEG's
    are not): the move's limit in px decides on such photographs."""
    # the edge points' RMS distance from their ellipse (the circle's, less the
    # second harmonic's share, of amplitude (1 - circularity)·R/2) over 0.35 of
    # the edge-point move looked for (0.07 px): on rendered occluders that put the
    # centre over 0.5 px off it is a third of that error (median), and at least
    # 0.087 px (an occluder 60 DN darker over 2 px of a 10 px dot's edge, blurred
    # 3.5 px, 0.51 px off); clean fits need not look further (the two-marker
    # target's leave 0.025-0.028 px, most dots of the sharp photographs less)
    c2 = 0.5 * (1.0 - f.circularity) * f.radius_px
    if patch is None or not f.residual_rms_px**2 - 0.5 * c2 * c2 > (0.35 * _ARC_EDGE_PX) ** 2:
        return None
    for arc in _arc_search(f):
        hidden = _without_arc(f, patch, arc) if arc[2] > _ARC_EDGE_PX and arc[3] > _ARC_EDGE_RATIO else None
        if hidden is not None:
            return hidden
    return None


def _without_arc(f: DiscFit, patch: MarkerPatch, arc) -> Marker | None:
    """Status ``occluded`` for the pixel fit `f` when its refit without the ring's
    pixels about `arc` (from :func:`_arc_search`) says the arc is not its own
    (:func:`_hidden_arc`), else None."""
    # the ring's pixels in a wedge of _ARC_MOST of the turn about the arc (or the
    # arc, if wider): an occluder over the edge covers the background beyond the
    # hidden chord over a wider angle than the chord, and its level there pulls too
    span = max(arc[1], 2.0 * np.pi * _ARC_MOST)
    start = arc[0] + 0.5 * (arc[1] - span)
    inside = (np.arctan2(patch.ys - f.y_px, patch.xs - f.x_px) - start) % (2.0 * np.pi) < span
    without = replace(patch, excluded=inside if patch.excluded is None else patch.excluded | inside)
    try:
        g = fit_disc(None, f.x_px, f.y_px, f.radius_px, edge_width=f.edge_width_px,
                     levels=(f.background_dn, f.foreground_dn), patch=without)
    except FitError:
        return None
    d = np.array([g.x_px - f.x_px, g.y_px - f.y_px])
    move = float(np.hypot(d[0], d[1]))
    along = d / move if move > 0 else d
    std = float(np.sqrt(max(along @ g.cov[:2, :2] @ along, 0.0)))
    if not (move > max(HIDDEN_ARC_PX, _ARC_MOVE_SIGMAS * std) and f.noise_dn > HIDDEN_ARC_NOISE_RATIO * g.noise_dn):
        return None
    return _flagged(f, "occluded", HIDDEN_ARC_MESSAGE.format(
        start=-np.degrees(start + span) % 360.0, end=-np.degrees(start) % 360.0, noise=f.noise_dn,
        rest=g.noise_dn, ratio=HIDDEN_ARC_NOISE_RATIO, move=move, allowed=HIDDEN_ARC_PX, x=g.x_px, y=g.y_px))


#: The message of an ``ok`` marker whose ring held a surround as dark as itself
#: (:attr:`~vision_torsion.pixelfit.DiscFit.steep_cut`): the centre is flagged, not
#: withheld, as such a marker may be the only one there is.
STEEP_CUT_MESSAGE = (
    "a region beside the marker as dark (bright) as it, such as an edge or a shadow, was cut from its ring: "
    f"the centre may be off by up to {STEEP_CUT_PX} px, more than its std says"
)

#: Times its own noise figure (:attr:`~vision_torsion.pixelfit.DiscFit.edge_noise_px`)
#: that a ``steep_cut`` fit's edge points may scatter about its circle (or ellipse),
#: and by over half of :data:`STEEP_CUT_PX`, before the marker is ``near_edge``
#: (:func:`_steep_edge_bent`): 0.2-3.0 times on rendered shadow edges whose fits
#: were within 0.4 px, 7-15 times (0.4-0.6 px) on those 0.37-1.5 px off; 1.2-1.8
#: times on the photographed round dots of the discorpy sets; 5.0-5.3 times (0.5 px)
#: on two dots beside the dark line along a UCL frame's edge (one 0.18 px from the
#: ML fit); 6 times but 0.15 px beside a rendered card's edge (0.07-0.13 px off). A
#: bend of the edge by an RMS of e moves the centre by up to about √2·e (its first
#: harmonic).
STEEP_EDGE_NOISE_TIMES = 6.0

#: The message of a ``near_edge`` marker whose cut surround bent its edge
#: (:func:`_steep_edge_bent`).
STEEP_EDGE_MESSAGE = (
    "a region beside the marker as dark (bright) as it, such as an edge or a shadow, was cut from its ring, and "
    "the edge left scatters about the fitted outline by {rms:.2f} px, {times:.0f} times its noise ({noise:.2f} px; "
    f"allowed {{allowed:.0f}} times and {0.5 * STEEP_CUT_PX} px): the region bends the marker's edge, and the "
    f"centre may be off by more than {STEEP_CUT_PX} px"
)


def _steep_edge_bent(f: DiscFit, rms: float) -> Marker | None:
    """Status ``near_edge`` for a ``steep_cut`` fit whose edge points scatter about its
    fitted outline (`rms`, px: the circle's or, seen obliquely, the ellipse's) by over
    :data:`STEEP_EDGE_NOISE_TIMES` times their noise figure and by over half of
    :data:`STEEP_CUT_PX`, else None (and None for any other fit). The region cut
    from the ring meets the marker's edge and bends it (a shadow's edge along the
    rim, or through the centre with half the ring cut), which the disc model's
    centre follows by more than :data:`STEEP_CUT_PX`."""
    noise = f.edge_noise_px
    if not (f.steep_cut and rms > max(STEEP_EDGE_NOISE_TIMES * noise, 0.5 * STEEP_CUT_PX)):
        return None
    return _near_edge(f, STEEP_EDGE_MESSAGE.format(rms=rms, times=rms / noise, noise=noise,
                                                   allowed=STEEP_EDGE_NOISE_TIMES))


#: Centre move (px) under a lighting also curved over the ring
#: (:attr:`~vision_torsion.pixelfit.DiscFit.lighting_shift_px`, computed where the
#: background is uneven) beyond which a marker is ``near_edge``
#: (:func:`_uneven_light`). Under lighting the model follows the move stays at the
#: noise's level. On rendered shadow edges across markers of 8-35 px radius the
#: centre's error is 0.5-2.2 times the move (5-95 %; ``benchmarks/bench_light_edge.py``).
UNEVEN_SHIFT_PX = 0.1
#: Standard deviations of its own noise
#: (:attr:`~vision_torsion.pixelfit.DiscFit.lighting_shift_std_px`) that the move
#: must exceed as well: a move the noise could make is no evidence of an edge.
UNEVEN_SHIFT_SIGMAS = 3.0


#: The message of a ``near_edge`` marker across which the background is not even
#: (:func:`_uneven_light`).
UNEVEN_LIGHT_MESSAGE = (
    "the background is not even across the marker (a shadow or light edge crosses it): its levels differ by "
    "{step:.0f} DN ({share:.0%} of the contrast) beyond the fitted lighting gradient, and a lighting curved over "
    "the marker moves the centre by {shift:.2f} px (allowed {allowed} px); the centre may be off by about as much"
)


def _uneven_light(f: DiscFit) -> Marker | None:
    """Status ``near_edge`` for a fit whose background is not even across the marker
    (its centre moves by over :data:`UNEVEN_SHIFT_PX`, and by over
    :data:`UNEVEN_SHIFT_SIGMAS` times that move's own noise, under a lighting
    curved over the ring: :attr:`~vision_torsion.pixelfit.DiscFit.lighting_shift_px`),
    else None. The fit's lighting is a plane; a shadow's or a light's edge across
    the marker is a step, which the plane follows only in part, and the misfit
    pulls the centre. A fit that cut a surround as dark as the marker from its ring
    (``steep_cut``, flagged with its own message, good to :data:`STEEP_CUT_PX`) is
    judged against that error instead of :data:`UNEVEN_SHIFT_PX`, and only when its
    edge points leave a gap wider than :data:`_STEEP_MAX_GAP_DEG`: the cut region's
    blurred flank stays in the background, uneven by construction, and where the
    edge is seen all round it holds the centre whatever the shift (0.07-0.23 px off
    beside a card's edge, which the shift put at 0.5-0.6 px; 0.01-0.09 px off for
    moves of 0.95-1.26 px on rendered shadow edges 10-15 px from the centres of
    markers of 15-25 px radius); where a part of the edge is unseen (the shaded
    part of a marker a shadow's edge crosses) the shift is the evidence there is
    (1.0-1.05 px off, moves of 0.83-0.94 px; ``benchmarks/bench_light_edge.py``)."""
    shift = f.lighting_shift_px
    allowed = STEEP_CUT_PX if f.steep_cut else UNEVEN_SHIFT_PX
    if not shift > max(allowed, UNEVEN_SHIFT_SIGMAS * f.lighting_shift_std_px):
        return None
    if f.steep_cut and not _widest_gap_deg(_edge_profile(f)[0]) > _STEEP_MAX_GAP_DEG:
        return None
    return Marker(
        x_px=f.x_px,
        y_px=f.y_px,
        radius_px=f.radius_px,
        edge_width_px=f.edge_width_px,
        status="near_edge",
        message=UNEVEN_LIGHT_MESSAGE.format(
            step=f.background_step_dn, share=f.background_step_dn / abs(f.foreground_dn - f.background_dn),
            shift=shift, allowed=allowed),
    )


#: The message of an ``ok`` marker fitted with its neighbours' gaps split
#: (:func:`crowded_patch`): their blurred edges share its background ring.
CROWDED_MESSAGE = (
    "fitted among close neighbours: the gaps to them were split along their middle, and their "
    "blurred edges share its background"
)


def _pixels_marker(f: DiscFit, *, crowded: bool = False, patch: MarkerPatch | None = None) -> Marker:
    """A :class:`Marker` from the pixel-model fit (``fit="pixels"``): ``not_round``
    when its edge is neither a circle nor an ellipse (a disc seen obliquely,
    :func:`_oblique`; then ``ok``, with the ellipse's residual and a message);
    ``occluded`` when the circle or ellipse is asymmetric about its centre
    (:func:`_occluded`; not judged when `crowded` or when a neighbour's pixels left
    out of `patch` reach its edge zone); ``near_edge`` when the background is not
    even across it (:func:`_uneven_light`) or when a surround cut from its ring bent
    its edge (:func:`_steep_edge_bent`); else ``occluded`` when an arc of its edge is
    not its own (:func:`_hidden_arc`; not judged when `crowded`); `crowded`: fitted with
    :func:`crowded_patch` (:data:`CROWDED_MESSAGE`)."""
    circ = f.circularity
    rms, n_edge, message = f.residual_rms_px, int(f.edge_x_px.size), ""
    oblique = None
    if circ < min_circularity(f.radius_px):
        oblique = _oblique(f)
        if oblique is None:
            return _not_round(f.x_px, f.y_px, f.radius_px, circ)
    # a circle or an ellipse so far; one with a chord hidden or cut is neither
    occluded = None if crowded else _occluded(f, patch)
    if occluded is not None:
        return occluded
    uneven = _uneven_light(f)
    if uneven is not None:
        return uneven
    merged = _merged_end(f, patch, None if oblique is None else oblique[2])
    if merged is not None:
        return merged
    if oblique is not None:
        ratio, rms, _ = oblique
        message = (f"seen obliquely: the edge is an ellipse of axis ratio {ratio:.2f} "
                   f"(residual {rms:.2f} px; {circ:.2f} as a circle); centre of the disc model")
    bent = _steep_edge_bent(f, rms)
    if bent is not None:
        return bent
    # last: what the checks above name more closely (a shadow's edge, a bent edge)
    # may leave an arc off the outline too
    hidden = None if crowded else _hidden_arc(f, patch)
    if hidden is not None:
        return hidden
    if f.steep_cut:
        message = "; ".join(m for m in (message, STEEP_CUT_MESSAGE) if m)
    if crowded:
        message = "; ".join(m for m in (message, CROWDED_MESSAGE) if m)
    return Marker(
        x_px=f.x_px,
        y_px=f.y_px,
        radius_px=f.radius_px,
        x_std_px=float(np.sqrt(f.cov[0, 0])),
        y_std_px=float(np.sqrt(f.cov[1, 1])),
        xy_cov_px2=float(f.cov[0, 1]),
        radius_std_px=float(np.sqrt(f.cov[2, 2])),
        residual_rms_px=rms,
        n_edge_points=n_edge,
        contrast_dn=f.foreground_dn - f.background_dn,
        circularity=circ,
        edge_width_px=f.edge_width_px,
        steep_cut=f.steep_cut,
        message=message,
    )


def _ellipse_radial(ef):
    th = -np.deg2rad(ef.angle_deg)  # image-axes orientation of the major axis
    a, b = ef.a_px, ef.b_px

    def radial(psi):
        t = psi - th
        return a * b / np.sqrt((b * np.cos(t)) ** 2 + (a * np.sin(t)) ** 2)

    return radial


def find_markers(
    image,
    *,
    polarity: str | None = None,
    radius_range=None,
    fit: str | None = None,
    settings: MeasureSettings | None = None,
) -> pd.DataFrame:
    """Find and fit every circular marker of one polarity in an image.

    Parameters
    ----------
    image : array_like, GreyImage or path
        Grey image indexed ``[y, x]``, or a file to load.
    polarity : {"dark", "bright"}, optional
        Dark markers on a bright disk (the default), or bright on dark.
    radius_range : tuple of float, optional
        (smallest, largest) marker radius in px.
    fit : {"pixels", "geometric", "algebraic", "ellipse"}, optional
        Marker-fit method (see :data:`~vision_torsion.settings.FIT_METHODS`);
        ``"pixels"`` by default.
    settings : MeasureSettings, optional
        All of the above in one object; give either `settings` or the separate
        options, not both.

    Returns
    -------
    pandas.DataFrame
        One row per candidate, largest first, with :data:`MARKER_COLUMNS`: centre
        (x_px, y_px), radius, their standard uncertainties, fit residual RMS, number
        of edge points, contrast, circularity, edge width, status and message.
        Coordinates: origin at the centre of the top-left pixel, y downwards.

    Raises
    ------
    ImageReadError
        The image is unreadable or not a 2-D grey image.
    VisionTorsionError
        `settings` given together with `polarity`, `radius_range` or `fit` (reason
        ``conflicting_options``; settings used to win silently), or an invalid option.

    Examples
    --------
    >>> from vision_torsion.synthetic import Scene, render
    >>> r = render(Scene(), 0.0, seed=3)
    >>> table = find_markers(r.image)
    >>> list(table["status"])
    ['ok', 'ok']
    >>> bool(abs(table["x_px"].max() - r.centres[:, 0].max()) < 0.02)
    True
    """
    options = {"polarity": polarity, "radius_range": radius_range, "fit": fit}
    given = {k: v for k, v in options.items() if v is not None}
    if settings is None:
        settings = MeasureSettings(**given)  # validates; defaults for the rest
    elif given:
        raise VisionTorsionError(
            f"find_markers: give either settings or {', '.join(given)}, not both "
            "(settings already says how markers are found)",
            reason="conflicting_options",
        )
    img, block_px = grey_array_and_blocks(image, keep_integers=True)
    return markers_to_frame(find_marker_list(img, settings, block_px=block_px))


def _radius_range(img: np.ndarray, settings: MeasureSettings) -> tuple[float, float]:
    """The settings' marker radius range (px), or the default for the image's size."""
    return settings.radius_range or default_radius_range(img.shape)


def neighbours_of(circles: np.ndarray, i: int, edge_width: float) -> np.ndarray:
    """The coarse circles (rows of (x, y, r), px) other than row `i` whose blurred
    disc reaches into the square of pixels marker `i`'s fit uses."""
    if len(circles) > 8:
        return circles[near_candidates(circles, np.array([i]), edge_width)[0]]
    # a few candidates (the pair search): :func:`near_candidates`'s arithmetic on plain floats,
    # without its dozen small array operations
    x, y, r = circles[i].tolist()
    extent = float(candidate_extent(r, edge_width))
    near = []
    for j, (xj, yj, rj) in enumerate(circles.tolist()):
        reach = extent + neighbour_reach(rj, edge_width)
        if j != i and abs(xj - x) < reach and abs(yj - y) < reach:
            near.append(j)
    return circles[near]


def near_candidates(circles: np.ndarray, rows: np.ndarray, edge_width: float) -> np.ndarray:
    """Flags (len(rows) x len(circles)) of :func:`neighbours_of` for each of `rows`."""
    x, y, r = circles[rows].T[:, :, None]
    reach = candidate_extent(r, edge_width) + neighbour_reach(circles[:, 2], edge_width)
    near = (np.abs(circles[:, 0] - x) < reach) & (np.abs(circles[:, 1] - y) < reach)
    near[np.arange(rows.size), rows] = False
    return near


def find_candidates(img: np.ndarray, settings: MeasureSettings) -> list[Blob]:
    """Coarse marker candidates of a validated image, largest first:
    :func:`~vision_torsion.detect.detect_blobs` with the polarity and radius range of
    `settings` (the default range for the image's size when it has none)."""
    return detect_blobs(img, polarity=settings.polarity, radius_range=_radius_range(img, settings))


def find_marker_list(
    img: np.ndarray, settings: MeasureSettings, *, enough=None, candidates: list[Blob] | None = None,
    block_px: int | None = None,
) -> list[Marker]:
    """The work of :func:`find_markers` on a validated image, as a list of :class:`Marker`.

    Parameters
    ----------
    img : numpy.ndarray
        2-D grey image: float32, or uint8/uint16 (only the pixels used are converted).
    settings : MeasureSettings
        Polarity, radius range and fit.
    enough : callable, optional
        ``enough(markers, blob) -> bool``, asked before each further candidate
        (largest first): True stops, leaving the smaller candidates unfitted. Used
        when only the target pair is wanted (bolt holes need no sub-pixel fit).
    candidates : list of Blob, optional
        :func:`find_candidates` of this image and these settings, when already found.
    block_px : int, optional
        The image's JPEG block side (px), for the fits' covariance (:func:`fit_marker`).

    Notes
    -----
    Without `enough`, the default pixel fits of all candidates are made together,
    vectorised across markers (:func:`~vision_torsion.pixelfit.fit_discs`, the same
    fit as :func:`~vision_torsion.pixelfit.fit_disc` to rounding): a photograph of a
    dot grid has hundreds of small markers. With `enough`, one by one, as each
    answer may end the search. Without `enough`, a marker beside a neighbour whose
    fitted blurred edge reaches its own is then fitted again with that edge taken
    off its pixels (:func:`_refit_beside_blurred`).
    """
    r_min, r_max = _radius_range(img, settings)
    fit = settings.fit
    markers = []
    width = 1.2  # the optics are the same for every marker: pass the fitted width on
    blobs = find_candidates(img, settings) if candidates is None else candidates
    circles = np.array([(b.x, b.y, b.radius) for b in blobs], dtype=np.float64).reshape(-1, 3)
    if enough is None and fit == "pixels" and len(blobs) > _BATCH_FROM:
        return _fit_all(img, blobs, circles, (r_min, r_max), block_px)
    for i, blob in enumerate(blobs):
        if enough is not None and enough(markers, blob):
            break
        marker = _judge(blob, img.shape, r_min, r_max, fit)
        if marker is None:
            marker = fit_marker(img, blob, fit=fit, edge_width=width, neighbours=neighbours_of(circles, i, width),
                                block_px=block_px)
            if marker.ok:
                width = marker.edge_width_px
        markers.append(marker)
    if enough is None and fit == "pixels":
        _refit_beside_blurred(img, blobs, circles, markers, width, block_px)
    _flag_unlike_neighbours(markers)
    return markers


#: Candidates from which :func:`find_marker_list` fits the markers together
#: (:func:`~vision_torsion.pixelfit.fit_discs`) rather than one by one.
_BATCH_FROM = 2


def _fit_all(img, blobs: list[Blob], circles: np.ndarray, radius_range, block_px=None) -> list[Marker]:
    """Every candidate judged and fitted with the pixel model, the fits vectorised
    across markers (:func:`~vision_torsion.pixelfit.fit_discs`).

    One candidate fitted alone gives every other fit its starting edge width and
    the reach of its neighbours' masks (:func:`neighbour_reach`), as one marker
    passes its width on to the next in the one-by-one loop of
    :func:`find_marker_list` (the optics are the same for all): the largest, unless
    it is an odd one out (not ``ok``, or an edge width over half the median
    candidate's radius: an out-of-focus blob beside a dot grid, fitted ``ok`` with
    an edge width of 32 px, made every dot's background ring vanish under its
    neighbours' masks); then the one of median radius. Every fit then finds its own
    width.
    """
    markers: list[Marker | None] = [_judge(b, img.shape, *radius_range, "pixels") for b in blobs]
    width = 1.2
    todo = [i for i, m in enumerate(markers) if m is None]
    circles = _maskable(circles, [m is not None and not is_coarse_disc(b) for b, m in zip(blobs, markers)])
    if todo:
        # blobs come largest first: the middle one of those to fit has the median radius
        middle = todo[len(todo) // 2]
        for i in dict.fromkeys((todo[0], middle)):
            todo.remove(i)
            markers[i] = fit_marker(img, blobs[i], edge_width=width, neighbours=neighbours_of(circles, i, width),
                                    block_px=block_px)
            if markers[i].ok and markers[i].edge_width_px <= 0.5 * blobs[middle].radius:
                width = markers[i].edge_width_px
                break
    patches, starts, fitted = [], [], []
    for i, prepared in zip(todo, _prepared_all(img, [blobs[i] for i in todo], circles, todo, width)):
        if isinstance(prepared, FitError):
            markers[i] = _failed(blobs[i], prepared)
            continue
        patch, (cx, cy, r, (B, F)) = prepared
        patches.append(patch)
        starts.append((cx, cy, r, B, F))
        fitted.append(i)
    for i, patch, fit in zip(fitted, patches, fit_discs(patches, starts, edge_width=width, block_px=block_px)):
        markers[i] = (_failed(blobs[i], fit) if isinstance(fit, FitError)
                      else _whole(_pixels_marker(fit, patch=patch), img.shape))
    _refit_beside_blurred(img, blobs, circles, markers, width, block_px)
    crowded = _refit_crowded(img, blobs, circles, markers, width, block_px)
    _refit_unmasked(img, blobs, circles, markers, width, crowded, block_px)
    _flag_unlike_neighbours(markers)
    return markers


#: A marker fitted as an ellipse is compared with this many of its nearest ``ok``
#: markers (:func:`_flag_unlike_neighbours`) ...
_UNLIKE_NEIGHBOURS = 6
#: ... and is ``near_edge`` when its fitted edge width is over this many times their
#: median ...
_UNLIKE_WIDTH_TIMES = 2.5
#: ... and its circularity (minor over major axis) is below their median by over this.
_UNLIKE_ROUNDER_BY = 0.1

#: The message of a marker fitted as an ellipse that its ``ok`` neighbours contradict
#: (:func:`_flag_unlike_neighbours`).
UNLIKE_NEIGHBOURS_MESSAGE = (
    "fitted as an ellipse (circularity {circ:.2f}) with an edge width of {width:.1f} px, where its nearest ok "
    "markers ({n}) are rounder ({their_circ:.2f}) and sharper ({their_width:.1f} px; allowed {times} times): no disc "
    "seen obliquely through the same optics; a shadow's or a light's edge, or a dark region beside it, widened "
    "and stretched its edge, and the centre may be off by up to the axes' difference, {off:.1f} px"
)


def _flag_unlike_neighbours(markers: list) -> None:
    """Each ``ok`` marker of `markers` fitted as an ellipse (circularity below
    :func:`min_circularity`) whose :data:`_UNLIKE_NEIGHBOURS` nearest other ``ok``
    markers are at once rounder (their median circularity above its own by over
    :data:`_UNLIKE_ROUNDER_BY`) and sharper (its edge width over
    :data:`_UNLIKE_WIDTH_TIMES` times their median) made ``near_edge`` (in place,
    :data:`UNLIKE_NEIGHBOURS_MESSAGE`); nothing when there is no other ``ok`` marker.

    A disc seen obliquely is blurred by the same optics as the markers beside it, and
    its view changes smoothly across a target; a marker's edge that a light's or a
    shadow's edge across it, or a dark region beside it, widens (the fit's edge width
    takes up the uneven background its lighting plane cannot follow) is stretched into
    an ellipse as well: an 8 px marker in a 1/3 shade 15 px from a 10 px wide shadow
    edge, fitted as an ellipse of axis ratio 0.72 with an edge width of 5.1 px beside
    a round marker of 1.1 px, 0.74 px off (and 3.4 px, ratio 0.67, 0.26 px off, 10 px
    from the edge). On photographed targets an ellipse's edge width is at most 2.2
    times its neighbours' median, and at most 1.8 times where it is also less round
    than them by over 0.1 (dots 0.23 px from the maximum-likelihood fit). The
    neighbours are judged before any is flagged: one pass over the ``ok`` markers,
    and only when one is fitted as an ellipse."""
    ok = [i for i, m in enumerate(markers) if m.ok and np.isfinite(m.edge_width_px)]
    suspects = [i for i in ok if markers[i].circularity < min_circularity(markers[i].radius_px)]
    if not suspects or len(ok) < 2:
        return
    from scipy.spatial import cKDTree  # here: only a marker fitted as an ellipse needs it

    table = np.array([(markers[i].x_px, markers[i].y_px, markers[i].edge_width_px, markers[i].circularity)
                      for i in ok])
    where = {i: k for k, i in enumerate(ok)}
    k_near = min(_UNLIKE_NEIGHBOURS, len(ok) - 1)
    rows = np.array([where[i] for i in suspects])
    # the nearest k_near + 1 hold the marker itself, unless as many others share its
    # place: then the farthest of them is the one too many
    near = cKDTree(table[:, :2]).query(table[rows, :2], k=k_near + 1)[1].reshape(rows.size, k_near + 1)
    others = near != rows[:, None]
    others[others.all(axis=1), -1] = False
    near = near[others].reshape(rows.size, k_near)
    width = np.median(table[near, 2], axis=1)
    circ = np.median(table[near, 3], axis=1)
    unlike = (table[rows, 2] > _UNLIKE_WIDTH_TIMES * width) & (table[rows, 3] < circ - _UNLIKE_ROUNDER_BY)
    flagged = [(ok[r], w, c) for r, w, c in zip(rows[unlike].tolist(), width[unlike], circ[unlike])]
    for i, width, circ in flagged:
        m = markers[i]
        markers[i] = _near_edge(m, UNLIKE_NEIGHBOURS_MESSAGE.format(
            circ=m.circularity, width=m.edge_width_px, n=k_near, their_circ=circ, their_width=width,
            times=_UNLIKE_WIDTH_TIMES, off=m.radius_px * (1.0 - m.circularity)))


#: Statuses of a candidate that turned out to be no marker nor any object whose
#: pixels a neighbouring marker's fit must leave out: specks of noise or JPEG
#: blocks found beside a blurred dot, too faint or too small to fit.
_NO_OBJECT = ("fit_failed", "low_contrast", "too_small")


def _no_object(marker: Marker, blob: Blob, own_radius: float) -> bool:
    """True when the candidate `blob`, judged or fitted as `marker`, is no object a
    marker of radius `own_radius` (px) must be fitted without (:data:`_NO_OBJECT`),
    or a region cut by the border more than 1.5 times that radius (a vignetted
    border's dark band: its coarse circle, from the part inside the frame, runs
    far from its pixels)."""
    if marker.status in _NO_OBJECT:
        return True
    return marker.status == "border" and blob.radius > 1.5 * own_radius


def _refit_unmasked(img, blobs: list[Blob], circles: np.ndarray, markers: list, width: float, crowded,
                    block_px=None) -> None:
    """Each ``ok`` marker of `markers` whose fitted edge zone held pixels left out for
    a candidate that turned out to be no object (:func:`_no_object`), fitted again
    without leaving those out (in place): the ``ok`` refit replaces it; else the
    marker is ``near_edge`` with the refit's reason (:data:`UNMASKED_MESSAGE`). The
    markers fitted among close neighbours (`crowded`, indices) are left as they are;
    `block_px` is the JPEG block size the fits take (:func:`fit_marker`).

    The pixels of the dots around it were left out before any was fitted, each for
    its coarse circle (:func:`excluding_neighbours`). A speck beside a blurred JPEG
    dot is a candidate too, and its mask takes a part of the dot's own edge: the fit
    then rests on the rest of an edge that is no perfect blurred circle, and the
    asymmetry check is not made beside a neighbour (:func:`_occluded`); such dots
    came out 0.6-1.3 px off, ``ok``. Without those masks the fit sees the whole edge
    and its own checks judge what lies there (an occluder cut, the asymmetry)."""
    # the candidates that may be no object, and the markers near them (near_candidates'
    # rule, against those columns only: on a dense grid most markers have none)
    suspects = np.flatnonzero([m.status in _NO_OBJECT or m.status == "border" for m in markers])
    rows = np.setdiff1d(np.flatnonzero([m.ok for m in markers]), np.asarray(list(crowded), dtype=np.int64))
    if not suspects.size or not rows.size:
        return
    for k in range(0, rows.size, 256):  # 256 markers at a time: a few MB at most
        x, y, r = circles[rows[k : k + 256]].T[:, :, None]
        reach = candidate_extent(r, width) + neighbour_reach(circles[suspects, 2], width)
        near = (np.abs(circles[suspects, 0] - x) < reach) & (np.abs(circles[suspects, 1] - y) < reach)
        for i, flags in zip(rows[k : k + 256].tolist(), near):
            m = markers[i]
            drop = [j for j in suspects[flags].tolist() if _no_object(markers[j], blobs[j], m.radius_px)]
            if not drop:
                continue
            nb = circles[drop]
            apart = np.hypot(nb[:, 0] - m.x_px, nb[:, 1] - m.y_px)
            if not np.any(apart < m.radius_px + 3.0 * m.edge_width_px + 1.0 + neighbour_reach(nb[:, 2], width)):
                continue  # their masks stay off its edge zone
            keep = near_candidates(circles, np.array([i]), width)[0]
            keep[drop] = False
            again = fit_marker(img, blobs[i], edge_width=width, neighbours=circles[keep], block_px=block_px)
            markers[i] = again if again.ok else _near_edge(m, UNMASKED_MESSAGE.format(reason=again.message))


def _near_edge(m: Marker | DiscFit, message: str) -> Marker:
    """The ``ok`` marker (or pixel fit) `m` made ``near_edge`` with `message`: its
    centre, radius and edge width kept, without their uncertainties."""
    return _flagged(m, "near_edge", message)


def _flagged(m: Marker | DiscFit, status: str, message: str) -> Marker:
    """The marker (or pixel fit) `m` with `status` and `message`: its centre, radius
    and edge width kept, without their uncertainties."""
    return Marker(x_px=m.x_px, y_px=m.y_px, radius_px=m.radius_px, edge_width_px=m.edge_width_px,
                  status=status, message=message)


#: The message of a marker fitted ``ok`` with a candidate's pixels left out that took
#: part of its edge, which fitted without leaving them out is not ``ok``
#: (:func:`_refit_unmasked`).
UNMASKED_MESSAGE = (
    "a candidate beside it that is no marker (a speck, a faint blob, a border region) lay over its edge; "
    "fitted with those pixels: {reason}"
)


def _maskable(circles: np.ndarray, no_disc) -> np.ndarray:
    """`circles` (rows of x, y, r in px) with those of the candidates flagged in
    `no_disc` (rejected before any fit, and of no disc's coarse shape:
    :func:`~vision_torsion.detect.is_coarse_disc`) placed nowhere (NaN centres):
    never a neighbour whose pixels are left out of a marker's fit. The coarse circle
    of such a region (a vignetted border's dark band cut by the frame, axis ratio
    0.1, r 446 px on a 2560x2160 photo) runs through the grid far from its pixels:
    the dots on that circle lost half their ring to it and came out 0.2-0.3 px off.
    The discs found inside such a region are candidates of their own; a region as
    dark as a marker that reaches into its ring is cut by the fit itself
    (:attr:`~vision_torsion.pixelfit.DiscFit.steep_cut`)."""
    flags = np.asarray(no_disc, bool)
    if not flags.any():
        return circles
    out = circles.copy()
    out[flags, :2] = np.nan
    return out


def _refit_crowded(img, blobs: list[Blob], circles: np.ndarray, markers: list, width: float,
                   block_px=None) -> list[int]:
    """The candidates of `markers` whose fit failed and which have neighbours, fitted
    again with the gaps to them split (:func:`crowded_patch`), together; a marker
    is replaced only by an ``ok`` one (in place). Returns the indices replaced."""
    failed = np.array([i for i, m in enumerate(markers) if m.status == "fit_failed"], dtype=np.int64)
    replaced: list[int] = []
    if failed.size == 0:
        return replaced
    near = near_candidates(circles, failed, width)
    patches, starts, fitted = [], [], []
    for k, i in enumerate(failed.tolist()):
        if not near[k].any():
            continue
        blob = blobs[i]
        try:
            patch = crowded_patch(candidate_patch(img, blob, width), circles[near[k]], width,
                                  (blob.x, blob.y, blob.radius))
            cx, cy, r, (B, F) = _start(patch, blob, crowded=True)
        except FitError:
            continue
        patches.append(patch)
        starts.append((cx, cy, r, B, F))
        fitted.append(i)
    for i, fit in zip(fitted, fit_discs(patches, starts, edge_width=width, block_px=block_px)):
        if not isinstance(fit, FitError):
            marker = _whole(_pixels_marker(fit, crowded=True), img.shape)
            if marker.ok:
                markers[i] = marker
                replaced.append(i)
    return replaced


#: Gap (px between two fitted edges) under which a neighbour's blurred edge, in its
#: own edge widths s, keeps over 1 % of its contrast at a marker's edge (Φ(-2.33) =
#: 0.01): the marker is then fitted again with that edge taken off its pixels
#: (:func:`_refit_beside_blurred`).
NEIGHBOUR_TAIL_WIDTHS = 2.33

#: The message of a marker whose fit with its neighbours' blurred edges taken off
#: its pixels (:func:`_refit_beside_blurred`) is not ``ok``.
BLURRED_NEIGHBOUR_MESSAGE = (
    "a neighbour's blurred edge reaches over its edge, and fitted with that edge taken off its pixels: {reason}"
)


def _neighbour_edges(patch: MarkerPatch, edges: np.ndarray) -> MarkerPatch:
    """`patch` with the blurred edges of `edges` (rows of fitted neighbours' x, y,
    radius, edge width in px and contrast F - B in DN) taken off its values: each
    neighbour's disc model less its background, (F - B)·Φ((R - d)/s), d the pixel's
    distance from its centre."""
    values = patch.values.astype(np.float64, copy=True)
    for x, y, r, s, contrast in edges.tolist():
        values -= contrast * normal_cdf((r - np.hypot(patch.xs - x, patch.ys - y)) / s)
    return MarkerPatch(values, patch.shape, patch.x0, patch.y0, patch.excluded)


def _refit_beside_blurred(img, blobs: list[Blob], circles: np.ndarray, markers: list, width: float,
                          block_px=None) -> None:
    """Each ``ok`` marker of `markers` with an ``ok`` neighbour whose fitted blurred
    edge keeps over 1 % of its contrast at the marker's edge (:func:`_blurred_pairs`),
    fitted again (together, in place) with the neighbours' fitted edges taken off
    its pixels (:func:`_neighbour_edges`): the refit replaces it when ``ok``, else
    the marker is ``near_edge`` with the refit's reason
    (:data:`BLURRED_NEIGHBOUR_MESSAGE`).

    A neighbour's pixels are left out of a marker's fit to its coarse radius plus
    the blurred edge of the starting width (:func:`neighbour_reach`); a neighbour
    more blurred than that leaves its edge's tail in the marker's ring, which the model's background does
    not follow: a blurred dot 2 px beside another came out 0.5-0.65 px off, ``ok``
    (0.2 px with the neighbour's edge taken off). Each neighbour's own fit gives its
    edge, in one pass: the neighbours' fits carry some of the same pull."""
    rows = np.flatnonzero([m.ok and np.isfinite(m.edge_width_px) for m in markers])
    if rows.size < 2:
        return
    fitted = np.array([(markers[i].x_px, markers[i].y_px, markers[i].radius_px, markers[i].edge_width_px,
                        markers[i].contrast_dn) for i in rows])
    tails: dict[int, list[int]] = {}
    for a, b in _blurred_pairs(fitted):
        tails.setdefault(int(rows[a]), []).append(int(b))
    todo = sorted(tails)
    if not todo:
        return
    patches, starts, refit = [], [], []
    for i, prepared in zip(todo, _prepared_all(img, [blobs[i] for i in todo], circles, todo, width)):
        if isinstance(prepared, FitError):
            continue
        patch, (cx, cy, r, (B, F)) = prepared
        patches.append(_neighbour_edges(patch, fitted[tails[i]]))
        starts.append((cx, cy, r, B, F))
        refit.append(i)
    for i, patch, fit in zip(refit, patches, fit_discs(patches, starts, edge_width=width, block_px=block_px)):
        again = (_failed(blobs[i], fit) if isinstance(fit, FitError)
                 else _whole(_pixels_marker(fit, patch=patch), img.shape))
        markers[i] = again if again.ok else _near_edge(markers[i], BLURRED_NEIGHBOUR_MESSAGE.format(
            reason=again.message))


def _blurred_pairs(fitted: np.ndarray):
    """The pairs (a, b) of rows of `fitted` (fitted markers' x, y, radius, edge width
    in px, and contrast) whose fitted edges are less than
    :data:`NEIGHBOUR_TAIL_WIDTHS` of b's edge width apart: b's blurred edge keeps
    over 1 % of its contrast at a's. Swept along x (sorted), all rows at once per
    offset in that order: a photograph's grid has thousands of markers."""
    order = np.argsort(fitted[:, 0], kind="stable")
    f = fitted[order]
    reach = 2.0 * f[:, 2].max() + NEIGHBOUR_TAIL_WIDTHS * f[:, 3].max()
    pairs = []
    for k in range(1, len(f)):
        a, b = f[:-k], f[k:]
        close = b[:, 0] - a[:, 0] < reach
        if not close.any():
            break  # x sorted: farther offsets are farther apart
        gap = np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]) - a[:, 2] - b[:, 2]
        for one, other, s in ((order[:-k], order[k:], b[:, 3]), (order[k:], order[:-k], a[:, 3])):
            hit = close & (gap < NEIGHBOUR_TAIL_WIDTHS * s)
            pairs.extend(zip(one[hit].tolist(), other[hit].tolist()))
    return pairs
