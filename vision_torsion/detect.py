"""Coarse marker detection, robust to uneven lighting.

The image is reduced (area averaging) so that detection costs little next to the
sub-pixel fit. The slowly varying background is estimated by a grey-level
morphological closing (dark markers) or opening (bright markers) with a square
window wider than the largest marker, which removes the markers but keeps lighting
gradients and vignetting. Blobs are the connected regions of the background-flattened
image above an Otsu threshold (never below five times the noise); each gets a
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


def _background(small: np.ndarray, r_max_small: float, polarity: str) -> np.ndarray:
    """Slowly varying background without the markers, at the detection scale.

    The closing (dark markers) or opening (bright) runs on a further reduced copy
    where the largest marker is about 6 px in radius, which keeps its cost
    independent of the marker size; the result is interpolated back.
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
    bg = cv2.morphologyEx(coarse, op, kernel, borderType=cv2.BORDER_REPLICATE)
    if q > 1:
        # the envelope of the coarse copy, dilated once more so interpolation between
        # coarse pixels never cuts into a marker
        extra = cv2.getStructuringElement(cv2.MORPH_RECT, (3, 3))
        bg = (cv2.dilate if polarity == "dark" else cv2.erode)(bg, extra, borderType=cv2.BORDER_REPLICATE)
        bg = cv2.resize(bg, (wp, hp), interpolation=cv2.INTER_LINEAR)[:h, :w]
    return bg


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
    level): the regions at the higher :data:`_SPLIT_LEVELS` that are whole discs
    (:func:`is_coarse_disc`, within the area `limits`, clear of the image border:
    :func:`_clear_of_border`), each taken at the lowest level where it is one and
    not again higher up, with its area (reduced px²)."""
    bh, bw = sub.shape
    box = diff[y0 : y0 + bh, x0 : x0 + bw]
    peak = float(box[sub > 0].max())
    found: list[tuple[Blob, float]] = []
    for k in _SPLIT_LEVELS:
        if k * level >= peak:
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


def detect_blobs(image: np.ndarray, *, polarity: str = "dark", radius_range=None) -> list[Blob]:
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

    Returns
    -------
    list of Blob
        Candidates, largest first.
    """
    r_min, r_max = radius_range if radius_range is not None else default_radius_range(image.shape)
    f = detection_reduction(r_min)
    small = image
    for _ in range(f.bit_length() - 1):
        # successive 2x area reductions: OpenCV's fast path, ten times quicker than
        # one 4x reduction and the same up to integer rounding
        small = cv2.resize(small, (small.shape[1] // 2, small.shape[0] // 2), interpolation=cv2.INTER_AREA)
    small = np.asarray(small, dtype=np.float32)  # integer images are reduced first, converted after
    background = _background(small, r_max / f, polarity)
    # OpenCV's float32 subtraction and maximum are numpy's to the bit, in fewer passes
    diff = cv2.subtract(background, small) if polarity == "dark" else cv2.subtract(small, background)
    top = float(cv2.minMaxLoc(diff)[1])
    if not top > 0:
        logger.info("no marker candidates: nothing in the image is %s than its surroundings (a constant image?)",
                    "darker" if polarity == "dark" else "brighter")
        return []
    scaled = np.multiply(diff, 255.0 / top)
    np.clip(scaled, 0, 255, out=scaled)
    otsu, _ = cv2.threshold(scaled.astype(np.uint8), 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    noise = _noise_sigma(small)
    level = max(otsu * top / 255.0, 5.0 * noise)
    # 255 where diff > level (the blobs' outlines are the same as from a 0/1 mask)
    mask = cv2.compare(diff, level, cv2.CMP_GT)
    if r_min / f >= _MIN_REDUCED_RADIUS_2X:
        # cut thin lines (a wire) away from the markers they cross (a marker of
        # 1.5 reduced px in radius keeps its core through the 3x3 opening)
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3)))
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    a_min, a_max = max(0.5 * np.pi * (r_min / f) ** 2, 4), 2.0 * np.pi * (r_max / f) ** 2
    blobs = []
    for contour in contours:
        _, _, bw, bh = cv2.boundingRect(contour)
        if bw * bh < a_min:
            continue  # too small even to fill its box
        region = _region(contour)
        blob, area = _blob(*region, f, small.shape)
        cut_disc = None
        if a_min <= area <= a_max:
            blobs.append(blob)
            if is_coarse_disc(blob):
                if not blob.touches_border:
                    continue
                cut_disc = (blob, area)  # its own core higher up is no other marker
        elif area < a_min:
            continue
        # no disc, too large for one, or cut by the border: a marker merged at this
        # level with its surround or a neighbour is looked for higher up
        for inner, inner_area in _discs_within(diff, *region, level, f, small.shape, (a_min, a_max)):
            # the core of a disc cut by the border is that disc, whose blurred edge the
            # border cuts (fitted, a 10 px dot blurred 2.5 px and 2 px from the border
            # came out 0.2 px off): it stays one row, border
            if not _own_core(inner, inner_area, cut_disc):
                blobs.append(inner)
    if not blobs:
        logger.info("no marker candidates: no %s blob of radius %g-%g px stands out from the background "
                    "by more than %.3g (5x the noise %.3g)", polarity, r_min, r_max, level, noise)
    blobs.sort(key=lambda b: -b.radius)
    return blobs
