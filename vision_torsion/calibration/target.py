"""Plane and lens correction from a calibration target: ``calibrate_from_target``.

The user lays a chessboard or a (symmetric) circle grid flat on the torque disk and
takes one or more images. OpenCV finds the pattern (``findChessboardCorners`` refined
by ``cornerSubPix``, or ``findCirclesGrid``); with three or more views
``calibrateCamera`` estimates the first radial distortion coefficient k1 (principal
point fixed at the image centre, square pixels, no tangential terms, k2 = k3 = 0:
the few views of a lab set-up do not determine more, and k1 is the model of
:class:`~vision_torsion.correction.PlaneCorrection`). The plane
homography comes from the view chosen by ``plane_image`` (the target lying on the
disk): its undistorted pattern points are mapped onto the pattern's own metric grid
with ``findHomography`` (plain least squares over all points).

Coordinates are image pixels (x, y), origin at the centre of the top-left pixel
(OpenCV's convention too), y downwards. The result is normalised to look like the
identity at the pattern's centre (disk-plane units ≈ image pixels there).
"""

from __future__ import annotations

import logging

import cv2
import numpy as np

from ..correction import PlaneCorrection
from ..errors import CalibrationError
from ..images import as_grey_array
from ..validate import check_number
from .anchoring import normalised

__all__ = ["calibrate_from_target", "PATTERNS", "find_pattern"]

logger = logging.getLogger(__name__)

PATTERNS = ("chessboard", "circles")
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)


def _to_uint8(arr: np.ndarray) -> np.ndarray:
    lo, hi = float(arr.min()), float(arr.max())
    if hi <= lo:
        return np.zeros(arr.shape, np.uint8)
    return np.round((arr - lo) * (255.0 / (hi - lo))).astype(np.uint8)


def find_pattern(image, *, pattern: str = "chessboard", pattern_size=(9, 6), name: str = "image") -> np.ndarray:
    """Pattern points of one target image, (n, 2) in image px.

    Parameters
    ----------
    image : path, GreyImage or array_like
        The image.
    pattern : {"chessboard", "circles"}
        A chessboard (inner corners) or a symmetric grid of dark circles.
    pattern_size : (int, int)
        (columns, rows) of inner corners or of circles.
    name : str
        What to call the image in messages.

    Raises
    ------
    CalibrationError
        Unknown pattern, or the pattern is not found in the image.
    """
    if pattern not in PATTERNS:
        raise CalibrationError(f"pattern must be one of {PATTERNS}, got {pattern!r}")
    cols, rows = (int(v) for v in pattern_size)
    img = _to_uint8(as_grey_array(image, name=name))
    if pattern == "chessboard":
        ok, pts = cv2.findChessboardCorners(img, (cols, rows), flags=cv2.CALIB_CB_ADAPTIVE_THRESH)
        if ok:
            pts = cv2.cornerSubPix(img, pts, (7, 7), (-1, -1), _SUBPIX_CRITERIA)
    else:
        ok, pts = cv2.findCirclesGrid(img, (cols, rows), flags=cv2.CALIB_CB_SYMMETRIC_GRID)
    if not ok or pts is None:
        raise CalibrationError(f"{name}: no {cols}x{rows} {pattern} pattern found")
    return pts.reshape(-1, 2).astype(np.float64)


def calibrate_from_target(
    images,
    *,
    pattern: str = "chessboard",
    pattern_size=(9, 6),
    square_mm: float = 1.0,
    plane_image: int = 0,
    fit_distortion: bool | None = None,
) -> PlaneCorrection:
    """Plane (and lens) correction from images of a flat target on the disk.

    Parameters
    ----------
    images : sequence of path, GreyImage or array_like
        Views of the target; all the same size.
    pattern : {"chessboard", "circles"}
        Target kind (see :func:`find_pattern`).
    pattern_size : (int, int)
        (columns, rows) of inner corners (chessboard) or circles.
    square_mm : float
        Pitch of the pattern (mm); only scales the disk plane, so angles do not
        depend on it.
    plane_image : int
        Index of the view showing the target lying on the disk plane.
    fit_distortion : bool, optional
        Estimate k1 with ``cv2.calibrateCamera``; by default when there are at least
        three views.

    Returns
    -------
    PlaneCorrection
        ``method = "target"``; ``info`` has the views used, OpenCV's reprojection
        RMS (px) when k1 is fitted, and the homography's residual RMS (px).

    Raises
    ------
    CalibrationError
        No images, images of different sizes, a pattern not found (naming the
        image), fewer than 3 views when `fit_distortion` is True, `plane_image`
        out of range, or a non-positive `square_mm`.
    """
    images = list(images)
    if not images:
        raise CalibrationError("no target images given")
    check_number(square_mm, name="square_mm", error=CalibrationError, low=0, low_open=True, unit="mm")
    if not 0 <= plane_image < len(images):
        raise CalibrationError(f"plane_image {plane_image} is out of range for {len(images)} image(s)")
    fit_distortion = len(images) >= 3 if fit_distortion is None else bool(fit_distortion)
    if fit_distortion and len(images) < 3:
        raise CalibrationError(f"fitting lens distortion needs at least 3 target views, got {len(images)}")
    cols, rows = (int(v) for v in pattern_size)
    grid = np.zeros((rows * cols, 3), np.float32)
    grid[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * float(square_mm)
    points, shape = [], None
    for i, im in enumerate(images):
        name = str(im) if isinstance(im, str) or hasattr(im, "__fspath__") else f"target image {i}"
        arr = as_grey_array(im, name=name)
        if shape is not None and arr.shape != shape:
            raise CalibrationError(f"{name}: size {arr.shape[1]}x{arr.shape[0]} differs from the first image's")
        shape = arr.shape
        points.append(find_pattern(arr, pattern=pattern, pattern_size=(cols, rows), name=name))
    h, w = shape
    centre = ((w - 1) / 2.0, (h - 1) / 2.0)
    f = float(max(w, h))
    k1, info = 0.0, {"n_images": len(images), "pattern": pattern, "pattern_size": [cols, rows]}
    if fit_distortion:
        K = np.array([[f, 0, centre[0]], [0, f, centre[1]], [0, 0, 1]])
        flags = (
            cv2.CALIB_USE_INTRINSIC_GUESS
            | cv2.CALIB_FIX_PRINCIPAL_POINT
            | cv2.CALIB_FIX_ASPECT_RATIO
            | cv2.CALIB_ZERO_TANGENT_DIST
            | cv2.CALIB_FIX_K2
            | cv2.CALIB_FIX_K3
        )
        rms, K, dist, _, _ = cv2.calibrateCamera(
            [grid] * len(points), [p.astype(np.float32) for p in points], (w, h), K, np.zeros(5), flags=flags
        )
        f, k1 = float(K[0, 0]), float(dist.ravel()[0])
        info["reprojection_rms_px"] = float(rms)
    base = PlaneCorrection(np.eye(3), k1=k1, centre=centre, focal_length_px=f)
    ux, uy = base.undistort(points[plane_image][:, 0], points[plane_image][:, 1])
    und = np.stack([ux, uy], -1)
    H, _ = cv2.findHomography(und, grid[:, :2].astype(np.float64), 0)
    if H is None:
        raise CalibrationError("no homography fits the target's points")
    back = cv2.perspectiveTransform(grid[None, :, :2].astype(np.float64), np.linalg.inv(H))[0]
    info["homography_rms_px"] = float(np.sqrt(np.mean(np.sum((back - und) ** 2, axis=1))))
    corr = PlaneCorrection(H, k1=k1, centre=centre, focal_length_px=f, method="target", info=info)
    return normalised(corr, points[plane_image].mean(axis=0))
