"""Target calibration on chessboards rendered here (warped at 4x, area-downsampled)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vision_torsion.angle import line_direction_deg
from vision_torsion.calibration import calibrate_from_target
from vision_torsion.correction import PlaneCorrection
from vision_torsion.errors import CalibrationError

# disk plane -> image: a few degrees of tilt, a slight shear and an offset
H_TRUE = np.array([[1.0, 0.02, 5.0], [0.01, 0.99, -3.0], [4e-5, -3e-5, 1.0]])


def board_image(H, *, size=(640, 480), cols=9, rows=6, pitch=40.0, origin=(130.0, 110.0), up=4, k1=0.0, f=640.0):
    """A chessboard of `cols` x `rows` inner corners on the disk plane, seen through H
    (disk → image), rendered at `up` x resolution and area-averaged (exact pixel centres:
    hi-res coordinate = up * x + (up - 1) / 2); optional radial distortion k1."""
    w, h = size
    S = np.array([[up, 0, (up - 1) / 2], [0, up, (up - 1) / 2], [0, 0, 1.0]])
    yy, xx = np.mgrid[0 : h * up, 0 : w * up]
    i = np.floor(((xx - (up - 1) / 2) / up - origin[0]) / pitch).astype(int)
    j = np.floor(((yy - (up - 1) / 2) / up - origin[1]) / pitch).astype(int)
    inside = (i >= -1) & (i <= cols - 1) & (j >= -1) & (j <= rows - 1)
    board = np.where(inside & ((i + j) % 2 == 0), 30.0, 220.0).astype(np.float32)
    hi = cv2.warpPerspective(
        board, S @ H @ np.linalg.inv(S), (w * up, h * up), flags=cv2.INTER_LINEAR, borderValue=220.0
    )
    img = cv2.resize(hi, (w, h), interpolation=cv2.INTER_AREA)
    if k1:
        # distorted pixel x_d shows the undistorted image at u = undistort(x_d)
        c = PlaneCorrection(np.eye(3), k1=k1, centre=((w - 1) / 2, (h - 1) / 2), focal_length_px=f)
        gy, gx = np.mgrid[0:h, 0:w].astype(np.float64)
        ux, uy = c.undistort(gx, gy)
        img = cv2.remap(img, ux.astype(np.float32), uy.astype(np.float32), cv2.INTER_CUBIC, borderValue=220.0)
    return np.clip(img, 0, 255).astype(np.uint8)


def _turned_pair(angle, centre=(320.0, 240.0), r=150.0):
    t = np.radians(angle)
    return np.array(
        [[centre[0] - r * np.cos(t), centre[1] + r * np.sin(t)], [centre[0] + r * np.cos(t), centre[1] - r * np.sin(t)]]
    )


def _image_of(D, H, k1=0.0, size=(640, 480), f=640.0):
    p = cv2.perspectiveTransform(D[None], H)[0]
    if k1:
        c = np.array([(size[0] - 1) / 2, (size[1] - 1) / 2])
        d = p - c
        p = c + d * (1 + k1 * np.sum(d * d, axis=1, keepdims=True) / f**2)
    return p


def _rotation_error(corr, H, k1=0.0):
    errs, raw = [], []
    ref = _image_of(_turned_pair(0.0), H, k1)
    for a in (20.0, 45.0, 70.0):
        cur = _image_of(_turned_pair(a), H, k1)
        d = [np.stack(corr.to_disk(p[:, 0], p[:, 1]), -1) for p in (ref, cur)]
        errs.append(line_direction_deg(*d[1]) - line_direction_deg(*d[0]) - a)
        raw.append(line_direction_deg(*cur) - line_direction_deg(*ref) - a)
    return np.abs(errs).max(), np.abs(raw).max()


def test_single_view_chessboard_gives_the_plane():
    corr = calibrate_from_target([board_image(H_TRUE)], pattern_size=(9, 6), square_mm=5.0)
    err, raw = _rotation_error(corr, H_TRUE)
    # uncorrected ≈ 0.7°; corners from cornerSubPix on this board scatter ≈ 0.05 px over
    # 54 points, which leaves a few thousandths of a degree on a 300 px line
    assert raw > 0.3
    assert err < 0.005
    assert corr.method == "target" and corr.k1 == 0.0 and corr.info["homography_rms_px"] < 0.2


def test_three_views_fit_distortion():
    k1 = -0.15
    views = [
        board_image(H_TRUE, k1=k1),
        board_image(np.array([[0.9, -0.1, 60.0], [0.12, 0.95, 10.0], [2e-4, 1e-4, 1.0]]), k1=k1),
        board_image(np.array([[1.05, 0.15, -20.0], [-0.1, 1.0, 30.0], [-1.5e-4, 2e-4, 1.0]]), k1=k1),
    ]
    corr = calibrate_from_target(views, pattern_size=(9, 6))
    # only k1/f² is defined (ρ = |u - c|/f); k1 = -0.15 at f = 640 px moves the board's
    # corners by ≈ 5 px, and is recovered within 10 %
    assert corr.k1 / corr.focal_length_px**2 == pytest.approx(k1 / 640.0**2, rel=0.1)
    err, raw = _rotation_error(corr, H_TRUE, k1)
    assert err < 0.02 < raw


def test_target_errors():
    blank = np.full((120, 160), 128, np.uint8)
    with pytest.raises(CalibrationError, match=r"target image 0: no 9x6 chessboard pattern found"):
        calibrate_from_target([blank], pattern_size=(9, 6))
    with pytest.raises(CalibrationError, match=r"fitting lens distortion needs at least 3 target views, got 1"):
        calibrate_from_target([blank], fit_distortion=True)
    with pytest.raises(CalibrationError, match=r"pattern must be one of \('chessboard', 'circles'\)"):
        calibrate_from_target([blank], pattern="dots")
    with pytest.raises(CalibrationError, match=r"square_mm must be a finite number > 0 \(mm\)"):
        calibrate_from_target([blank], square_mm=0)
    with pytest.raises(CalibrationError, match=r"no target images given"):
        calibrate_from_target([])
