"""Coarse marker detection, robust to uneven lighting.

The image is reduced (area averaging) so that detection costs little next to the
sub-pixel fit. The slowly varying background is estimated by a grey-level
morphological closing (dark markers) or opening (bright markers) with a square
window wider than the largest marker, which removes the markers but keeps lighting
gradients and vignetting. Blobs are the connected regions of the background-flattened
image above an Otsu threshold (never below five times the noise); where that one
level leaves evidence of uneven light, a second pass adds the candidates found with
levels that follow the local contrast (:func:`detect_blobs`, Notes). Each blob gets a
centre, an equivalent radius, an elongation and a flag for touching the border. A
region that is no disc, too large for one or cut by the border is looked into at
higher levels: a marker merged at the threshold with a surround as dark as itself
(a card's edge, a shadow) or with a touching neighbour stands free higher up.
Every blob is returned: judging it (round? big enough?) is the caller's job, so that
rejected candidates are reported rather than silently dropped.

Coordinates are full-resolution image pixels (x, y), origin at the centre of the
top-left pixel.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import cv2
import numpy as np

from .ring import fast_median

__all__ = ["Blob", "detect_blobs", "default_radius_range", "detection_reduction", "DEFAULT_MIN_RADIUS_PX"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class Blob:
    """A coarse marker candidate.

    Attributes
    ----------
    x, y : float
        Centre estimate (px).
    radius : float
        Radius of the circle of equal area (px).
    elongation : float
        Ratio of the minor to the major axis from second moments (1 for a disc).
    fill : float
        Area divided by the area of the moment ellipse (1 for a filled ellipse).
    touches_border : bool
        The blob reaches the image border.
    """

    x: float
    y: float
    radius: float
    elongation: float
    fill: float
    touches_border: bool


#: Smallest marker radius (px) looked for by default: a disc of radius 3 px still has
#: ~28 pixels and an edge all round, the least a person would mark as a round dot.
DEFAULT_MIN_RADIUS_PX = 3.0


def default_radius_range(shape) -> tuple[float, float]:
    """Default marker radius range (px) for an image of `shape` (rows, columns):
    :data:`DEFAULT_MIN_RADIUS_PX` up to a fifth of the shorter image side."""
    return DEFAULT_MIN_RADIUS_PX, max(min(shape) / 5.0, 2.0 * DEFAULT_MIN_RADIUS_PX)


#: Smallest marker radius in reduced pixels at the 4x and 8x detection scales: the
#: 3x3 opening that cuts wires off the markers (3 reduced px) keeps such a disc whole.
_MIN_REDUCED_RADIUS = 2.5
#: ... and at the 2x scale, used for small markers only: area averaging by 2 keeps at
#: least ~85 % of a disc's contrast at its centre while its reduced radius is 1.5 px
#: or more, wherever the disc lies on the pixel grid, and the opening keeps its core.
#: A 3 px marker (the default smallest) is found at half resolution, at a quarter of
#: the cost of full resolution.
_MIN_REDUCED_RADIUS_2X = 1.5


def detection_reduction(r_min: float) -> int:
    """Detection scale (1, 2, 4 or 8: successive 2x area reductions) for markers of
    radius `r_min` (px) and more: the coarsest keeping them
    :data:`_MIN_REDUCED_RADIUS` reduced px in radius (1.5 px at the 2x scale)."""
    for f in (8, 4, 2):
        if r_min / f >= _MIN_REDUCED_RADIUS:
            return f
    return 2 if r_min / 2 >= _MIN_REDUCED_RADIUS_2X else 1


def _noise_sigma(img: np.ndarray) -> float:
    """Robust noise estimate from horizontal pixel differences of ~16 rows (DN)."""
    d = np.diff(img[:: max(1, img.shape[0] // 16)], axis=1).ravel()
    return float(1.4826 * fast_median(np.abs(d - fast_median(d))) / np.sqrt(2))


def _background(small: np.ndarray, r_max_small: float, polarity: str, *,
                pad: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Slowly varying background without the markers, at the detection scale, and
    the same at the coarse scale it was computed at.

    The closing (dark markers) or opening (bright) runs on a further reduced copy
    where the largest marker is about 6 px in radius, which keeps its cost
    independent of the marker size; the result is interpolated back. OpenCV's
    morphology leaves the window's part outside the image out, so where the light
    rises into the image from its border the closing stays above it by the slope
    times half the window (7 DN at the border of a bowed light, against 2 DN of
    the noise's own bias inside); `pad` replicates the border outwards by half a
    window first, which the closing then follows exactly.
    """
    q = int(max(1, 2 ** np.ceil(np.log2(max(r_max_small / 6.0, 1.0)))))
    h, w = small.shape
    if q > 1:
        # padded to whole blocks: OpenCV reduces by an integer factor ten times
        # faster than by a fractional one
        hp, wp = -(-h // q) * q, -(-w // q) * q
        padded = cv2.copyMakeBorder(small, 0, hp - h, 0, wp - w, cv2.BORDER_REPLICATE)
        coarse = cv2.resize(padded, (wp // q, hp // q), interpolation=cv2.INTER_AREA)
    else:
        coarse = small
    k = int(2 * np.ceil(r_max_small / q) + 3) | 1
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (k, k))
    op = cv2.MORPH_CLOSE if polarity == "dark" else cv2.MORPH_OPEN
    if pad:
        m = k // 2 + 1
        bg = cv2.morphologyEx(cv2.copyMakeBorder(coarse, m, m, m, m, cv2.BORDER_REPLICATE), op, kernel)[m:-m, m:-m]
    else:
        bg = cv2.morphologyEx(coarse, op, kernel, borderType=cv2.BORDER_REPLICATE)
    coarse_bg = bg
    if q > 1:
        # the envelope of the coarse copy, dilated once more so interpolation between
        # coarse pixels never cuts into a marker
        extra = cv2.getStructuringElement(cv2.MORPH_RECT, (3, 3))
        bg = (cv2.dilate if polarity == "dark" else cv2.erode)(bg, extra, borderType=cv2.BORDER_REPLICATE)
        bg = cv2.resize(bg, (wp, hp), interpolation=cv2.INTER_LINEAR)[:h, :w]
    return bg, coarse_bg


#: Coarse shape limits of a candidate (second moments of its thresholded pixels) that
#: can be a disc: only gross non-discs fail them (two touching discs have an axis
#: ratio of 0.45, a wire far less); roundness is judged on the fitted edge.
COARSE_MIN_AXIS_RATIO = 0.55
COARSE_FILL_RANGE = (0.7, 1.3)
#: Levels, as multiples of the detection level, at which a region that is no disc is
#: looked into for discs: a marker merged at the detection level with a surround as
#: dark (bright) as itself, such as a card's edge or a shadow, or with a touching
#: neighbour stands free higher up (the UCL laparoscope frames' edge dots: at 1.4-2x).
_SPLIT_LEVELS = (1.4, 2.0, 2.8, 4.0)
#: A disc found inside a border-cut disc is that disc's own core, not another
#: marker, when it holds more than this share of its area, or more than a quarter
#: of it about its centre (within half its radius): a UCL laparoscope dot 2.5 px from
#: the frame's border, whose blur reached the border at the detection level, held
#: 0.498 of it 1.4 px off centre, and was reported twice (border, and fit_failed).
_CORE_SHARE = 0.5


def is_coarse_disc(blob: Blob, *, min_axis_ratio: float = COARSE_MIN_AXIS_RATIO) -> bool:
    """True when `blob`'s shape can be a disc's: axis ratio at least `min_axis_ratio`
    and fill within :data:`COARSE_FILL_RANGE`."""
    return blob.elongation >= min_axis_ratio and COARSE_FILL_RANGE[0] <= blob.fill <= COARSE_FILL_RANGE[1]


def _region(contour):
    """The pixels of an outer contour filled (a hole, such as a highlight, filled):
    (0/1 mask of its bounding box, x0, y0 of the box).

    Outer contours filled back give the blobs' pixels; connectedComponentsWithStats
    gives the same but costs a third of a millisecond more per image."""
    x0, y0, bw, bh = cv2.boundingRect(contour)
    sub = np.zeros((bh, bw), np.uint8)
    cv2.drawContours(sub, [contour], -1, 1, thickness=cv2.FILLED, offset=(-x0, -y0))
    return sub, x0, y0


def _blob(sub, x0, y0, f, shape) -> tuple[Blob | None, float]:
    """The :class:`Blob` of the region `sub` (a 0/1 mask) whose top-left pixel is
    (x0, y0) in the image reduced `f` times (of `shape`), and its area (reduced px²);
    (None, 0.0) for an empty mask."""
    m = cv2.moments(sub, binaryImage=True)
    area = m["m00"]
    if not area > 0:
        return None, 0.0
    cx, cy = m["m10"] / m["m00"], m["m01"] / m["m00"]
    # pixels as unit squares (each adds 1/12 px² of its own): a 2x2 blob is a disc
    # of fill 0.95, not 1.27 as points
    mu20, mu02, mu11 = m["mu20"] / m["m00"] + 1 / 12, m["mu02"] / m["m00"] + 1 / 12, m["mu11"] / m["m00"]
    common = np.sqrt(max((mu20 - mu02) ** 2 + 4 * mu11**2, 0.0))
    l1, l2 = (mu20 + mu02 + common) / 2, (mu20 + mu02 - common) / 2
    elong = float(np.sqrt(max(l2, 0) / l1)) if l1 > 0 else 0.0
    ellipse_area = 4 * np.pi * np.sqrt(max(l1 * l2, 1e-12))
    bh, bw = sub.shape
    sh, sw = shape
    touches = x0 == 0 or y0 == 0 or x0 + bw >= sw or y0 + bh >= sh
    # reduced pixel i covers full pixels [f·i, f·i + f - 1]: its centre is f·i + (f-1)/2
    blob = Blob(
        x=float((x0 + cx) * f + (f - 1) / 2),
        y=float((y0 + cy) * f + (f - 1) / 2),
        radius=float(np.sqrt(area / np.pi) * f),
        elongation=elong,
        fill=float(area / ellipse_area),
        touches_border=bool(touches),
    )
    return blob, float(area)


#: Margin (px) a disc must keep inside the image to count as whole.
BORDER_MARGIN_PX = 1.0


def disc_inside(shape, x, y, r, margin=BORDER_MARGIN_PX) -> bool:
    """True when the disc of radius `r` (px) at (x, y), widened by `margin` px, lies
    within the image of `shape` (rows, cols; its pixels span -0.5 .. size - 0.5)."""
    h, w = shape
    return x - r - margin >= -0.5 and y - r - margin >= -0.5 and x + r + margin <= w - 0.5 and y + r + margin <= h - 0.5


def _clear_of_border(blob: Blob, shape, f) -> bool:
    """True when `blob`'s disc lies whole inside the image (:func:`disc_inside`;
    `shape` of the image reduced `f` times): a disc found inside a region cut by the
    border is then a marker of its own, not the cut part of the region."""
    return disc_inside((shape[0] * f, shape[1] * f), blob.x, blob.y, blob.radius)


def _own_core(blob: Blob, area: float, cut_disc) -> bool:
    """True when `blob` (of `area`, reduced px²) found inside the border-cut disc
    `cut_disc` ((Blob, area), or None) is that disc's own core (:data:`_CORE_SHARE`)."""
    if cut_disc is None:
        return False
    disc, disc_area = cut_disc
    if area > _CORE_SHARE * disc_area:
        return True
    return area > 0.25 * disc_area and math.hypot(blob.x - disc.x, blob.y - disc.y) < 0.5 * disc.radius


def _discs_within(diff, sub, x0, y0, level, f, shape, limits) -> list[tuple[Blob, float]]:
    """Discs inside a region that is no disc (`sub`, its 0/1 mask at (x0, y0) of the
    reduced image; `diff` the background-flattened image, `level` its detection
    level, a number or an array of `diff`'s shape): the regions at the higher :data:`_SPLIT_LEVELS` that are whole discs
    (:func:`is_coarse_disc`, within the area `limits`, clear of the image border:
    :func:`_clear_of_border`), each taken at the lowest level where it is one and
    not again higher up, with its area (reduced px²)."""
    bh, bw = sub.shape
    box = diff[y0 : y0 + bh, x0 : x0 + bw]
    inside = sub > 0
    peak = float(box[inside].max())
    if not np.isscalar(level):
        level = level[y0 : y0 + bh, x0 : x0 + bw]
    lowest = float(level[inside].min()) if not np.isscalar(level) else level
    found: list[tuple[Blob, float]] = []
    for k in _SPLIT_LEVELS:
        if k * lowest >= peak:
            break
        inner = cv2.compare(box, k * level, cv2.CMP_GT) & (sub * 255)
        for contour in cv2.findContours(inner, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)[0]:
            part, px, py = _region(contour)
            blob, area = _blob(part, x0 + px, y0 + py, f, shape)
            if not limits[0] <= area <= limits[1] or not is_coarse_disc(blob) or not _clear_of_border(blob, shape, f):
                continue
            if any(np.hypot(blob.x - b.x, blob.y - b.y) < b.radius + blob.radius for b, _ in found):
                continue
            found.append((blob, area))
    return found


def detect_blobs(image: np.ndarray, *, polarity: str = "dark", radius_range=None,
                 local_levels: bool = True) -> list[Blob]:
    """Find marker candidates of one polarity.

    Parameters
    ----------
    image : numpy.ndarray
        2-D grey image (float32, uint8 or uint16), indexed ``[y, x]``.
    polarity : {"dark", "bright"}
        Markers darker or brighter than their surroundings.
    radius_range : tuple of float, optional
        (smallest, largest) radius in px; blobs far outside it are dropped (under
        half the smallest area or over twice the largest), after a region too large
        is looked into for discs.
    local_levels : bool
        Follow the local contrast where the light is uneven (see Notes); False keeps
        one detection level for the whole image.

    Returns
    -------
    list of Blob
        Candidates, largest first.

    Notes
    -----
    **Local levels.** One level (Otsu's, on the background-flattened image) finds
    markers whose contrast is within about 2:1 of the brightest ones: a dot in a
    shadow, at the dim end of a light falloff or under a lamp's reflection that
    clips the image stands below it, or merges with the reflection into one region
    too large for a marker. When the first, global pass leaves evidence of uneven
    light (such a region; a background that varies by more than a third of its
    largest value and by more than 10 noise σ; or a disc-shaped candidate whose
    peak is less than 1.5 times the level), a second pass follows the local
    contrast:

    - the background is estimated again with a window scaled from the largest
      candidate of coarse disc shape found (radius R; a closing or opening of side
      2·(1.5·R + 2) + 3 reduced px, never wider than the one of the largest
      allowed radius), so it follows a shadow's edge or a reflection's slope within
      a few marker sizes;
    - the level at each pixel is half the local contrast, the largest flattened
      value within R + 2 reduced px (so every pixel of a disc of radius up to R,
      and its blurred edge, sees the disc's centre: at half its peak a blurred disc
      is cut at its edge), never above the global level and never below
      :data:`LOCAL_LEVEL_FLOOR` noise σ nor the global level over
      :data:`LOCAL_LEVEL_RANGE`.

    The candidates of the second pass whose discs overlap no disc-shaped candidate
    of the first, and which stand out as the first pass's disc-shaped candidates do
    (a relative contrast of at least half their median's, or a peak of at least a
    third of it), are added to the first pass's candidates, which stay as they were
    found: the local levels only add the markers the global level missed, not the
    faint texture around a target.
    """
    r_min, r_max = radius_range if radius_range is not None else default_radius_range(image.shape)
    f = detection_reduction(r_min)
    small = image
    for _ in range(f.bit_length() - 1):
        # successive 2x area reductions: OpenCV's fast path, ten times quicker than
        # one 4x reduction and the same up to integer rounding
        small = cv2.resize(small, (small.shape[1] // 2, small.shape[0] // 2), interpolation=cv2.INTER_AREA)
    small = np.asarray(small, dtype=np.float32)  # integer images are reduced first, converted after
    background, coarse_bg = _background(small, r_max / f, polarity)
    diff, top = _flattened(small, background, polarity)
    if not top > 0:
        logger.info("no marker candidates: nothing in the image is %s than its surroundings (a constant image?)",
                    "darker" if polarity == "dark" else "brighter")
        return []
    scaled = np.multiply(diff, 255.0 / top)
    np.clip(scaled, 0, 255, out=scaled)
    otsu, _ = cv2.threshold(scaled.astype(np.uint8), 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    noise = _noise_sigma(small)
    level = max(otsu * top / 255.0, 5.0 * noise)
    limits = (max(0.5 * np.pi * (r_min / f) ** 2, 4), 2.0 * np.pi * (r_max / f) ** 2)
    blobs, peaks, too_large = _blobs_at(diff, level, f, r_min, limits)
    if local_levels and (too_large or _uneven_light(coarse_bg, peaks, level, noise)):
        discs = [b.radius / f for b in blobs if is_coarse_disc(b) and not b.touches_border]
        R = max(discs) if discs else r_min / f
        background, _ = _background(small, min(1.5 * R + 2.0, r_max / f), polarity, pad=True)
        diff, top = _flattened(small, background, polarity)
        if top > 0:
            levels = _local_levels(diff, level, noise, int(np.ceil(R + 2.0)))
            new = _apart(_blobs_at(diff, levels, f, r_min, limits, taken=_cores(blobs, f, diff.shape))[0], blobs)
            new = _contrasted(new, blobs, diff, small, f, polarity)
            logger.debug("uneven light: local detection levels %.3g-%.3g (global %.3g), %d more candidates",
                         float(levels.min()), float(levels.max()), level, len(new))
            blobs += new
    if not blobs:
        logger.info("no marker candidates: no %s blob of radius %g-%g px stands out from the background "
                    "by more than %.3g (5x the noise %.3g)", polarity, r_min, r_max, level, noise)
    blobs.sort(key=lambda b: -b.radius)
    return blobs


#: The local detection level is never below this many noise σ ...
LOCAL_LEVEL_FLOOR = 5.0
#: ... nor below the global level divided by this. Otsu's level lies near 0.4 of the
#: strongest markers' contrast, so markers down to a tenth of it are found (a 4:1
#: light falloff with a shadow of 40 % of the light at its dim end), and no fainter
#: texture of an empty surround far from any marker.
LOCAL_LEVEL_RANGE = 8.0
#: Evidence of uneven light after the global pass: the background (the image with
#: the markers closed or opened away, at the background's coarse scale) varies by
#: more than this share of its largest value ...
_UNEVEN_BACKGROUND = 1.0 / 3.0
#: ... and by more than this many noise σ; or a candidate of disc shape peaks less
#: than :data:`_DIM_PEAK` times the global level above the background (its dimmer
#: neighbours, if any, fall below the level).
_UNEVEN_NOISE = 10.0
_DIM_PEAK = 1.5


def _uneven_light(coarse_bg: np.ndarray, peaks: list[float], level: float, noise: float) -> bool:
    """True when the global pass leaves evidence of uneven light
    (:data:`_UNEVEN_BACKGROUND`, :data:`_UNEVEN_NOISE`, :data:`_DIM_PEAK`): the
    background varies, or a disc-shaped candidate (its flattened peak in `peaks`)
    stands barely above the global `level`."""
    lo, hi = cv2.minMaxLoc(coarse_bg)[:2]
    if hi - lo > _UNEVEN_BACKGROUND * hi and hi - lo > _UNEVEN_NOISE * noise:
        return True
    return bool(peaks) and min(peaks) < _DIM_PEAK * level


def _apart(blobs: list[Blob], found: list[Blob]) -> list[Blob]:
    """The candidates of `blobs` whose disc (centre, equivalent radius) overlaps
    that of no candidate of disc shape in `found`: the markers the local levels
    found and the global level did not (a candidate found by both is kept as the
    global level found it)."""
    discs = np.array([(b.x, b.y, b.radius) for b in found if is_coarse_disc(b)]).reshape(-1, 3)
    if not len(discs) or not blobs:
        return blobs
    from scipy.spatial import cKDTree  # here: only uneven light needs it

    tree = cKDTree(discs[:, :2])
    reach = float(discs[:, 2].max())
    out = []
    for b in blobs:
        near = tree.query_ball_point((b.x, b.y), b.radius + reach)
        if all(math.hypot(b.x - discs[j, 0], b.y - discs[j, 1]) > b.radius + discs[j, 2] for j in near):
            out.append(b)
    return out


#: A candidate of the second pass is kept when it stands out as the first pass's
#: disc-shaped candidates do (their medians): a relative contrast (over the brighter
#: side, :func:`_contrasts`) of at least half theirs, which light that multiplies the
#: scene (a falloff, vignetting, a shadow) leaves as it is (the test scenes' dots
#: found only by local levels: 0.98-1.2 of the median); or a flattened peak of at
#: least a third of theirs, for light added to the scene (a reflection that clips
#: the paper: 0.35-0.43). The faint texture of a table or a dome beside a target
#: (a GoPro photo: 0.08-0.3 of the median peak) and the noise of a clipped
#: reflection (0.05-0.08) are left out.
_MIN_RELATIVE_SHARE = 0.5
_MIN_PEAK_SHARE = 1.0 / 3.0


def _contrasts(blobs: list[Blob], diff: np.ndarray, small: np.ndarray, f: int, polarity: str) -> np.ndarray:
    """(peak, relative contrast) of each of `blobs`: the largest flattened value
    (`diff`) within 1 reduced px of its centre (`small`, `diff` reduced `f` times),
    and that over the brighter side's level there (the background for dark markers,
    the marker for bright ones)."""
    h, w = diff.shape
    out = np.empty((len(blobs), 2))
    for k, b in enumerate(blobs):
        i = min(max(round((b.y - (f - 1) / 2) / f), 1), h - 2)
        j = min(max(round((b.x - (f - 1) / 2) / f), 1), w - 2)
        peak = float(diff[i - 1 : i + 2, j - 1 : j + 2].max())
        bright = float(small[i, j]) + (peak if polarity == "dark" else 0.0)
        out[k] = peak, (peak / bright if bright > 0 else np.inf)
    return out


def _contrasted(new: list[Blob], found: list[Blob], diff, small, f: int, polarity: str) -> list[Blob]:
    """The candidates of `new` that stand out as the disc-shaped candidates of
    `found` do (:data:`_MIN_RELATIVE_SHARE`, :data:`_MIN_PEAK_SHARE`); all of them
    when `found` has no such candidate."""
    ref = _contrasts([b for b in found if is_coarse_disc(b)], diff, small, f, polarity)
    if not len(ref) or not new:
        return new
    peak, relative = np.median(ref, axis=0)
    mine = _contrasts(new, diff, small, f, polarity)
    keep = (mine[:, 1] >= _MIN_RELATIVE_SHARE * relative) | (mine[:, 0] >= _MIN_PEAK_SHARE * peak)
    return [b for b, k in zip(new, keep) if k]


def _local_levels(diff: np.ndarray, level: float, noise: float, half: int) -> np.ndarray:
    """Detection level at each pixel of the flattened image `diff` (see
    :func:`detect_blobs`, Notes): half the largest value within `half` reduced px,
    clipped to [max(:data:`LOCAL_LEVEL_FLOOR`·`noise`, `level` /
    :data:`LOCAL_LEVEL_RANGE`), `level`]."""
    kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * half + 1, 2 * half + 1))
    local = cv2.dilate(diff, kernel, borderType=cv2.BORDER_REPLICATE)
    local *= 0.5
    floor = max(LOCAL_LEVEL_FLOOR * noise, level / LOCAL_LEVEL_RANGE)
    return np.clip(local, min(floor, level), level, out=local)


def _flattened(small: np.ndarray, background: np.ndarray, polarity: str) -> tuple[np.ndarray, float]:
    """The markers' side of `small` above its `background` (DN, ≥ 0 where they
    stand out), and its largest value."""
    # OpenCV's float32 subtraction and maximum are numpy's to the bit, in fewer passes
    diff = cv2.subtract(background, small) if polarity == "dark" else cv2.subtract(small, background)
    return diff, float(cv2.minMaxLoc(diff)[1])


def _cores(blobs: list[Blob], f: int, shape) -> np.ndarray:
    """A 0/1 mask of the reduced image (`f` times, of `shape`) holding the middle of
    each disc-shaped candidate of `blobs`: its disc at half its radius (at least its
    centre's pixel)."""
    mask = np.zeros(shape, np.uint8)
    for b in blobs:
        if is_coarse_disc(b):
            centre = (round((b.x - (f - 1) / 2) / f), round((b.y - (f - 1) / 2) / f))
            cv2.circle(mask, centre, round(0.5 * b.radius / f), 1, thickness=-1)
    return mask


def _blobs_at(diff: np.ndarray, level, f: int, r_min: float, limits, *,
              taken: np.ndarray | None = None) -> tuple[list[Blob], list[float], bool]:
    """The candidates of the flattened image `diff` (reduced `f` times) above
    `level` (a number, or an array of `diff`'s shape), the flattened peak of each
    whole candidate of disc shape (reduced area within `limits`), and whether a
    region was too large for a marker. A region whose bounding box's middle pixel
    is set in `taken` (:func:`_cores`) is a candidate found before: skipped."""
    a_min, a_max = limits
    # 255 where diff > level (the blobs' outlines are the same as from a 0/1 mask)
    mask = cv2.compare(diff, level, cv2.CMP_GT)
    if r_min / f >= _MIN_REDUCED_RADIUS_2X:
        # cut thin lines (a wire) away from the markers they cross (a marker of
        # 1.5 reduced px in radius keeps its core through the 3x3 opening)
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3)))
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    blobs, peaks, too_large = [], [], False
    for contour in contours:
        bx, by, bw, bh = cv2.boundingRect(contour)
        if bw * bh < a_min:
            continue  # too small even to fill its box
        if taken is not None and taken[by + bh // 2, bx + bw // 2]:
            continue
        region = _region(contour)
        blob, area = _blob(*region, f, diff.shape)
        cut_disc = None
        if a_min <= area <= a_max:
            blobs.append(blob)
            if is_coarse_disc(blob):
                if not blob.touches_border:
                    sub, x0, y0 = region
                    peaks.append(cv2.minMaxLoc(diff[y0 : y0 + sub.shape[0], x0 : x0 + sub.shape[1]], sub)[1])
                    continue
                cut_disc = (blob, area)  # its own core higher up is no other marker
        elif area < a_min:
            continue
        else:
            too_large = True
        # no disc, too large for one, or cut by the border: a marker merged at this
        # level with its surround or a neighbour is looked for higher up
        for inner, inner_area in _discs_within(diff, *region, level, f, diff.shape, limits):
            # the core of a disc cut by the border is that disc, whose blurred edge the
            # border cuts (fitted, a 10 px dot blurred 2.5 px and 2 px from the border
            # came out 0.2 px off): it stays one row, border
            if not _own_core(inner, inner_area, cut_disc):
                blobs.append(inner)
    return blobs, peaks, too_large
