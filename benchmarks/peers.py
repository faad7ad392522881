"""The methods a user would pick instead of vision-torsion, built from library parts.

Each peer is a function ``image -> Detection`` that returns the two target marker
centres (x, y) in image pixels (origin at the centre of the top-left pixel, x to the
right, y downwards) or raises :class:`PeerFailure` with the reason. They are written
the way a competent user would write them with OpenCV, scikit-image and SciPy, with
the same prior knowledge our default gets and no more:

- the markers are dark on a bright disk;
- their radius lies in our default range, 10 px up to a fifth of the shorter image
  side (:func:`vision_torsion.detect.default_radius_range`);
- the target is the two largest round objects (peers are never told where the true
  markers are).

Peers
-----
``hough_alt``
    ``cv2.HoughCircles`` with ``HOUGH_GRADIENT_ALT`` after the Gaussian blur
    (σ = 1.5 px) OpenCV's documentation recommends; dp 1.5 (recommended for ALT),
    Canny high threshold 80 on the Scharr gradient (150 and 300 lose a marker in the
    low-contrast scene; with the blur, 80 finds both everywhere), circle
    "perfectness" 0.8, the radius range above; the centres as returned (they come
    on the accumulator's grid, half-pixel steps here); the two largest circles.
``otsu_ellipse``
    Gaussian blur σ = 1 px, global Otsu threshold, a 5 px opening (cuts thin lines
    such as a wire off the markers), ``findContours`` and ``fitEllipse`` on the two
    largest round contours (axis ratio ≥ 0.8, area within 10 % of the ellipse's).
``moments``
    The same two blobs, then the intensity-weighted centroid of each in a circular
    window of radius r + 3 px, after subtracting a background plane fitted to the ring
    r + 3 … r + 9 px and clipping negative weights to zero. (Of windows r + 3, 4, 6
    and 8 px, with and without clipping, this was the most accurate on the standard
    scene: 0.0055 px RMS per centre coordinate against 0.0065-0.0083 px.)
``canny_circle``
    scikit-image: the same two blobs, ``feature.canny`` (σ = 2 px, the best of 1,
    1.5, 2 and 3 px on the standard scene; on the window scaled to its 1st–99th
    percentile grey range) in a window around each, the edge
    pixels within 4 px of the blob's circle, ``measure.CircleModel.from_estimate``,
    one pass dropping edge pixels more than 3 robust σ off the circle, refit. This
    is the paper's chain (pixel-level edges, least-squares circle) with library parts.
``ml_disc``
    Maximum-likelihood (least-squares, i.e. ML under Gaussian pixel noise) fit of a
    blurred-disc model to every pixel of a square window of half-size r + 11 px
    around each blob (started from the Otsu blob, as the moments peer):
    ``L(p)·(B + (F − B)·P(p))`` with ``P`` the exact convolution of a disc
    (centre, radius r) with an isotropic Gaussian of width σ — the non-central χ²
    distribution function, ``scipy.special.chndtr`` — and ``L = 1 + gx·x + gy·y`` a
    lighting plane. Eight parameters (cx, cy, r, σ, B, F, gx, gy), analytic
    Jacobian, ``scipy.optimize.least_squares`` (Levenberg–Marquardt). The pixel
    area is folded into σ (a unit box has variance 1/12: σ² ≈ σ_psf² + 1/12); the
    mismatch between a box and a Gaussian of the same variance is radially
    symmetric. On noise-free renders of the standard scene the fitted centres lie
    within 0.0006 px of the truth, a quarter of the centre's Cramér–Rao σ
    (≈ 0.0023 px). Slow, close to the physical limit: the accuracy reference.
``ours_algebraic``, ``ours_default``
    :func:`vision_torsion.pair.measure_pair` with ``fit="algebraic"`` (the paper's
    exact Kasa fit, on our sub-pixel edge points) and with the default settings.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.special import chndtr, i0e, i1e

from vision_torsion.detect import default_radius_range
from vision_torsion.pair import PairMeasurement, measure_pair
from vision_torsion.settings import MeasureSettings

__all__ = [
    "Detection",
    "PeerFailure",
    "Peer",
    "PEERS",
    "hough_alt",
    "otsu_ellipse",
    "moments",
    "canny_circle",
    "ml_disc",
    "moments_centre",
    "canny_centre",
    "ml_disc_centre",
    "ours_algebraic",
    "ours_default",
]


class PeerFailure(Exception):
    """A peer method could not produce two marker centres."""


@dataclass(frozen=True)
class Detection:
    """Two marker centres, smaller x first; ``pair`` is set for our own pipeline.

    Attributes
    ----------
    centres : numpy.ndarray
        (2, 2) centres (x, y) in image pixels, origin at the centre of the top-left
        pixel, y downwards.
    pair : PairMeasurement or None
        Our pipeline's full result (with uncertainties), None for peers.
    """

    centres: np.ndarray
    pair: PairMeasurement | None = None


def _two(circles) -> Detection:
    """The two largest of (x, y, r) rows as a Detection (smaller x first)."""
    circles = sorted(circles, key=lambda c: -c[2])
    if len(circles) < 2:
        raise PeerFailure(f"found {len(circles)} circle(s), need 2")
    c = np.array([circles[0][:2], circles[1][:2]], dtype=np.float64)
    return Detection(centres=c[np.argsort(c[:, 0])])


def _to_uint8(image: np.ndarray) -> np.ndarray:
    """8-bit copy for the OpenCV functions that require it (min-max stretch for deeper images)."""
    if image.dtype == np.uint8:
        return image
    return cv2.normalize(image, None, 0, 255, cv2.NORM_MINMAX, dtype=cv2.CV_8U)


def _radius_range(image) -> tuple[float, float]:
    return default_radius_range(image.shape)


# ---------------------------------------------------------------- OpenCV Hough


def hough_alt(image: np.ndarray) -> Detection:
    """``cv2.HoughCircles(HOUGH_GRADIENT_ALT)``; the two largest circles."""
    r_min, r_max = _radius_range(image)
    g8 = cv2.GaussianBlur(_to_uint8(image), (0, 0), 1.5)
    found = cv2.HoughCircles(
        g8,
        cv2.HOUGH_GRADIENT_ALT,
        dp=1.5,
        minDist=2 * r_min,
        param1=80,
        param2=0.8,
        minRadius=int(r_min),
        maxRadius=int(np.ceil(r_max)),
    )
    if found is None:
        raise PeerFailure("HoughCircles found no circle")
    return _two([tuple(c) for c in found.reshape(-1, 3)])


# ------------------------------------------------- OpenCV threshold + contours


def _blobs(image: np.ndarray):
    """Two largest round dark blobs: [(contour, (x, y, r))], largest first."""
    r_min, r_max = _radius_range(image)
    g8 = cv2.GaussianBlur(_to_uint8(image), (0, 0), 1.0)
    _, bw = cv2.threshold(g8, 0, 255, cv2.THRESH_BINARY_INV | cv2.THRESH_OTSU)
    bw = cv2.morphologyEx(bw, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
    contours, _ = cv2.findContours(bw, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    h, w = image.shape
    found = []
    for c in contours:
        area = cv2.contourArea(c)
        if len(c) < 12 or not 0.5 * np.pi * r_min**2 <= area <= 2 * np.pi * r_max**2:
            continue
        x, y, bw_, bh_ = cv2.boundingRect(c)
        if x == 0 or y == 0 or x + bw_ >= w or y + bh_ >= h:
            continue  # cut by the border
        (ex, ey), (a1, a2), _ = cv2.fitEllipse(c)
        if min(a1, a2) < 0.8 * max(a1, a2) or not 0.9 <= area / (np.pi * a1 * a2 / 4) <= 1.1:
            continue
        found.append((c, (ex, ey, np.sqrt(area / np.pi)), area))
    found.sort(key=lambda f: -f[2])
    if len(found) < 2:
        raise PeerFailure(f"Otsu threshold gave {len(found)} round blob(s), need 2")
    return [(c, xyr) for c, xyr, _ in found[:2]]


def otsu_ellipse(image: np.ndarray) -> Detection:
    """Otsu threshold + ``findContours`` + ``fitEllipse`` centres of the two largest round blobs."""
    circles = []
    for c, (_, _, r) in _blobs(image):
        (ex, ey), _, _ = cv2.fitEllipse(c)
        circles.append((ex, ey, r))
    return _two(circles)


# ------------------------------------------------------- intensity moments


def _window(image, x, y, half):
    h, w = image.shape
    x0, y0 = int(np.floor(x - half)), int(np.floor(y - half))
    x1, y1 = int(np.ceil(x + half)) + 1, int(np.ceil(y + half)) + 1
    if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
        raise PeerFailure("marker window leaves the image")
    ys, xs = np.mgrid[y0:y1, x0:x1].astype(np.float64)
    return image[y0:y1, x0:x1].astype(np.float64), xs, ys


def _neighbours_mask(xs, ys, others):
    """Pixels within 3 px of a neighbouring dot's disc (`others`: rows of (x, y, r) in
    px), which a careful user leaves out of a dot's window on a dense grid."""
    mask = np.zeros(xs.shape, bool)
    for ox, oy, orad in (() if others is None else others):
        mask |= np.hypot(xs - ox, ys - oy) < orad + 3.0
    return mask


def moments_centre(image: np.ndarray, x: float, y: float, r: float, others=None) -> tuple[float, float]:
    """Background-subtracted intensity-weighted centroid (px) of a dark dot started at
    (x, y), radius r (px); pixels of neighbouring dots (`others`) left out."""
    patch, xs, ys = _window(image, x, y, r + 9)
    d = np.hypot(xs - x, ys - y)
    away = ~_neighbours_mask(xs, ys, others)
    ring = (d > r + 3) & (d <= r + 9) & away
    if ring.sum() < 8:
        raise PeerFailure("too few background pixels around the dot")
    A = np.column_stack([np.ones(ring.sum()), xs[ring] - x, ys[ring] - y])
    coef, *_ = np.linalg.lstsq(A, patch[ring], rcond=None)
    background = coef[0] + coef[1] * (xs - x) + coef[2] * (ys - y)
    wgt = np.clip(background - patch, 0.0, None) * ((d <= r + 3) & away)
    total = wgt.sum()
    if not total > 0:
        raise PeerFailure("no contrast in the marker window")
    return (wgt * xs).sum() / total, (wgt * ys).sum() / total


def moments(image: np.ndarray) -> Detection:
    """Background-subtracted intensity-weighted centroid of each of the two largest blobs."""
    return _two([(*moments_centre(image, x, y, r), r) for _, (x, y, r) in _blobs(image)])


# ----------------------------------------------- scikit-image canny + circle


def canny_centre(image: np.ndarray, x: float, y: float, r: float, others=None) -> tuple[float, float, float]:
    """scikit-image ``canny`` edge pixels + ``CircleModel.from_estimate`` of a dot
    started at (x, y), radius r (px): centre and radius (px); edge pixels of
    neighbouring dots (`others`) left out."""
    from skimage.feature import canny
    from skimage.measure import CircleModel

    patch, xs, ys = _window(image, x, y, r + 8)
    lo, hi = np.percentile(patch, [1, 99])
    if not hi > lo:
        raise PeerFailure("no contrast in the marker window")
    edges = canny((patch - lo) / (hi - lo), sigma=2.0) & ~_neighbours_mask(xs, ys, others)
    ex, ey = xs[edges], ys[edges]
    near = np.abs(np.hypot(ex - x, ey - y) - r) < 4
    pts = np.column_stack([ex[near], ey[near]])
    for _ in range(2):
        if len(pts) < 10:
            raise PeerFailure(f"only {len(pts)} Canny edge pixels near the marker")
        model = CircleModel.from_estimate(pts)
        if not model:
            raise PeerFailure(f"CircleModel failed: {model}")
        res = model.residuals(pts)
        mad = 1.4826 * np.median(np.abs(res - np.median(res)))
        keep = np.abs(res) <= max(3 * mad, 0.5)
        if keep.all():
            break
        pts = pts[keep]
    return model.center[0], model.center[1], model.radius


def canny_circle(image: np.ndarray) -> Detection:
    """scikit-image ``canny`` edge pixels + ``CircleModel.from_estimate`` per blob."""
    return _two([canny_centre(image, x, y, r) for _, (x, y, r) in _blobs(image)])


# -------------------------------------------- maximum-likelihood blurred disc


def _disc_model(p, xs, ys, half):
    """Model pixels and Jacobian of L·(B + (F-B)·P) for parameters p (see module docstring)."""
    cx, cy, r, s, B, F, gx, gy = p
    s = abs(s) + 1e-6
    dx, dy = xs - cx, ys - cy
    d = np.hypot(dx, dy)
    a, b = d / s, r / s
    # exact disc ⊛ Gaussian: P(|X| <= r), X ~ N(p - c, s² I), a non-central χ²(2) cdf;
    # beyond 7σ from the edge it is 0 or 1 to 1e-12
    near = np.abs(a - b) < 7.0
    P = (d < r).astype(np.float64)
    P[near] = chndtr(b * b, 2.0, a[near] ** 2)
    # derivatives of the Marcum-Q form, with scaled Bessel functions for stability:
    # dP/da = -b·exp(-(a-b)²/2)·I1e(ab),  dP/db = b·exp(-(a-b)²/2)·I0e(ab)
    g = np.exp(-0.5 * (a - b) ** 2) * b
    dPda = -g * i1e(a * b)
    dPdb = g * i0e(a * b)
    inv_d = np.where(d > 0, 1.0 / np.maximum(d, 1e-12), 0.0)
    xn, yn = (xs - xs.mean()) / half, (ys - ys.mean()) / half
    L = 1.0 + gx * xn + gy * yn
    base = B + (F - B) * P
    k = L * (F - B)
    J = np.empty((xs.size, 8))
    J[:, 0] = k * dPda * (-dx * inv_d) / s
    J[:, 1] = k * dPda * (-dy * inv_d) / s
    J[:, 2] = k * dPdb / s
    J[:, 3] = k * (dPda * (-a / s) + dPdb * (-b / s)) * np.sign(p[3])
    J[:, 4] = L * (1.0 - P)
    J[:, 5] = L * P
    J[:, 6] = base * xn
    J[:, 7] = base * yn
    return L * base, J


def ml_disc_centre(image, x, y, r, others=None):
    """Maximum-likelihood blurred-disc fit of a dot started at (x, y), radius r (px):
    centre and radius (px); pixels of neighbouring dots (`others`) left out."""
    half = r + 4 * 1.5 + 5
    patch, xs, ys = _window(image, x, y, half)
    away = ~_neighbours_mask(xs, ys, others)
    xs, ys, z = xs[away], ys[away], patch[away]
    d = np.hypot(xs - x, ys - y)
    B0 = float(np.median(z[d > r + 4]))
    # the inside level from the core (r - 4 px; the inner half of a dot under 8 px)
    F0 = float(np.median(z[d < max(r - 4, 0.5 * r)]))
    p0 = np.array([x, y, r, 1.2, B0, F0, 0.0, 0.0])
    last = {}

    def model(p):
        # least_squares asks for the residuals and then the Jacobian at the same
        # point: evaluate the (expensive) model once for both
        key = p.tobytes()
        if key not in last:
            last.clear()
            last[key] = _disc_model(p, xs, ys, half)
        return last[key]

    if not np.all(np.isfinite(p0)):
        raise PeerFailure("no pixels to start the blurred-disc fit")
    res = least_squares(lambda p: model(p)[0] - z, p0, jac=lambda p: model(p)[1], method="lm", x_scale="jac")
    if not res.success or not np.all(np.isfinite(res.x)):
        raise PeerFailure(f"least_squares did not converge: {res.message}")
    cx, cy, rr = res.x[:3]
    if np.hypot(cx - x, cy - y) > 0.5 * r or not 0.5 * r < rr < 1.5 * r:
        raise PeerFailure("blurred-disc fit ran away from the marker")
    return cx, cy, rr


def ml_disc(image: np.ndarray) -> Detection:
    """Maximum-likelihood blurred-disc fit to the pixels around each of the two largest blobs."""
    return _two([ml_disc_centre(image, x, y, r) for _, (x, y, r) in _blobs(image)])


# --------------------------------------------------------------------- ours


def _ours(image, settings) -> Detection:
    from vision_torsion.errors import VisionTorsionError

    try:
        pair = measure_pair(image, settings=settings, name="image")
    except VisionTorsionError as exc:
        raise PeerFailure(str(exc)) from exc
    c = np.array([[m.x_px, m.y_px] for m in pair.markers])
    return Detection(centres=c, pair=pair)


_ALGEBRAIC = MeasureSettings(fit="algebraic")
_DEFAULT = MeasureSettings()


def ours_algebraic(image: np.ndarray) -> Detection:
    """Our pipeline with the paper's algebraic (Kasa) fit on our sub-pixel edge points."""
    return _ours(image, _ALGEBRAIC)


def ours_default(image: np.ndarray) -> Detection:
    """Our pipeline with its default settings (the disc model fitted to the pixels)."""
    return _ours(image, _DEFAULT)


@dataclass(frozen=True)
class Peer:
    """A method in the benchmark: short name, table label, function, whether it is a library peer."""

    name: str
    label: str
    func: Callable[[np.ndarray], Detection]
    library_peer: bool


#: Every method, in table order.
PEERS = (
    Peer("hough_alt", "OpenCV HoughCircles (GRADIENT_ALT)", hough_alt, True),
    Peer("otsu_ellipse", "OpenCV Otsu + findContours + fitEllipse", otsu_ellipse, True),
    Peer("moments", "Intensity-weighted centroid (moments)", moments, True),
    Peer("canny_circle", "skimage canny + CircleModel", canny_circle, True),
    Peer("ml_disc", "ML blurred-disc fit (reference)", ml_disc, False),
    Peer("ours_algebraic", "vision-torsion, fit=algebraic (paper)", ours_algebraic, False),
    Peer("ours_default", "vision-torsion, default", ours_default, False),
)
