"""PlaneCorrection: mapping, covariance propagation, save/load and its error messages."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vision_torsion.angle import pair_angle
from vision_torsion.calibration.anchoring import normalised
from vision_torsion.correction import PlaneCorrection, load_correction
from vision_torsion.errors import CalibrationError
from vision_torsion.markers import Marker
from vision_torsion.pair import PairMeasurement
from vision_torsion.synthetic import Scene, scene_from_dict, scene_to_dict
from vision_torsion.synthetic.geometry import CameraMapping

H_TILT = np.array([[1.01, 0.02, -4.0], [-0.015, 0.995, 3.0], [2e-5, -1.5e-5, 1.0]])


def _corr(**kw):
    return PlaneCorrection(H_TILT, k1=-0.05, centre=(640.3, 480.7), focal_length_px=1500.0, **kw)


def test_undistort_inverts_the_renderer_distortion():
    d = scene_to_dict(Scene())
    d["optics"].update(radial_k1=-0.05, focal_length_px=1500.0)
    cam = CameraMapping(scene_from_dict(d))
    corr = PlaneCorrection(np.eye(3), k1=-0.05, centre=tuple(cam.c), focal_length_px=1500.0)
    rng = np.random.default_rng(3)
    u = rng.uniform(50, 1300, (40, 2))
    assert not cam.tilted  # the disk plane faces the camera: to_image is the radial distortion alone
    xd, yd = cam.to_image(u[:, 0], u[:, 1])
    ux, uy = corr.undistort(xd, yd)
    # fixed-point iteration converges geometrically; 1e-9 px is far below any centre error
    np.testing.assert_allclose(np.stack([ux, uy], -1), u, atol=1e-9)


def test_covariance_is_propagated_through_the_jacobian():
    corr = _corr()
    x, y = 1012.37, 233.81
    cov = np.array([[4e-4, 1e-4], [1e-4, 9e-4]])
    X, Y, C = corr.apply(x, y, cov)
    h = 1e-4
    J = np.empty((2, 2))
    for k, (dx, dy) in enumerate(((h, 0.0), (0.0, h))):
        Xp, Yp = corr.to_disk(x + dx, y + dy)
        Xm, Ym = corr.to_disk(x - dx, y - dy)
        J[:, k] = [(Xp - Xm) / (2 * h), (Yp - Ym) / (2 * h)]
    # central differences are exact to O(h²) ~ 1e-8 relative
    np.testing.assert_allclose(C, J @ cov @ J.T, rtol=1e-6)
    assert cov[0, 1] == 1e-4  # the caller's array is untouched


def test_apply_pair_moves_centres_and_keeps_the_rest():
    a = Marker(x_px=300.2, y_px=500.9, radius_px=35.0, x_std_px=0.01, y_std_px=0.02, xy_cov_px2=np.nan)
    b = Marker(x_px=900.6, y_px=480.1, radius_px=35.1, x_std_px=0.01, y_std_px=0.01, xy_cov_px2=0.0)
    pair = PairMeasurement(a, b)
    out = _corr().apply_pair(pair)
    X, Y = _corr().to_disk(300.2, 500.9)
    assert (out.first.x_px, out.first.y_px) == pytest.approx((float(X), float(Y)), abs=1e-12)
    assert out.first.radius_px == 35.0 and out.second.radius_px == 35.1
    assert np.isfinite(out.first.xy_cov_px2) and pair.first.x_px == 300.2


def test_correction_turns_tilted_angles_into_disk_angles():
    # truth: disk-plane points through the renderer's tilted camera (3° about 30°)
    d = scene_to_dict(Scene())
    d["optics"].update(tilt_deg=3.0, tilt_axis_deg=30.0)
    cam = CameraMapping(scene_from_dict(d))
    # the exact rectification for this camera: fit a homography to many exact points
    import cv2

    rng = np.random.default_rng(1)
    P = rng.uniform(100, 1300, (50, 2))
    x, y = cam.to_image(P[:, 0], P[:, 1])
    H, _ = cv2.findHomography(np.stack([x, y], -1), P, 0)
    corr = normalised(PlaneCorrection(H), (700.0, 500.0))

    def pair(angle):
        t = np.radians(angle)
        D = np.array([[700 - 300 * np.cos(t), 500 + 300 * np.sin(t)], [700 + 300 * np.cos(t), 500 - 300 * np.sin(t)]])
        xi, yi = cam.to_image(D[:, 0], D[:, 1])
        m = [
            Marker(x_px=float(u), y_px=float(v), radius_px=35.0, x_std_px=0.01, y_std_px=0.01, xy_cov_px2=0.0)
            for u, v in zip(xi, yi)
        ]
        return PairMeasurement(*m)

    ref, cur = pair(0.0), pair(70.0)
    raw = pair_angle(ref, cur).angle_deg
    fixed = pair_angle(ref, cur, correction=corr).angle_deg
    # a 3° tilt errs by hundredths of a degree at 70°; the exact homography by < 1e-6°
    assert abs(raw - 70.0) > 0.01
    assert fixed == pytest.approx(70.0, abs=1e-6)


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_save_load_round_trip(tmp_path, suffix):
    corr = _corr(method="self-calibration", info={"sweep_deg": 140.0, "angles_deg": [0.0, 1.5]})
    path = corr.save(tmp_path / f"plane{suffix}")
    back = PlaneCorrection.load(path)
    assert back == corr
    np.testing.assert_array_equal(back.homography, corr.homography)
    assert back.info["sweep_deg"] == 140.0 and back.method == "self-calibration"
    assert load_correction(str(path)) == corr and load_correction(None) is None


def _write(tmp_path, d, name="c.json"):
    p = tmp_path / name
    p.write_text(json.dumps(d))
    return p


def _good():
    return _corr().to_dict()


@pytest.mark.parametrize(
    "change, match",
    [
        (lambda d: d.update(version=2), r"c\.json: field 'version' must be 1, got 2"),
        (lambda d: d.update(format="other"), r"c\.json: field 'format' must be"),
        (lambda d: d.pop("homography"), r"c\.json: field 'homography' is missing"),
        (lambda d: d.update(homography=[[1, 0], [0, 1]]), r"c\.json: field 'homography' must be a 3x3"),
        (
            lambda d: d["homography"][1].__setitem__(2, "x"),
            r"c\.json: field 'homography\[1\]\[2\]' must be a finite number",
        ),
        (lambda d: d["distortion"].pop("centre_y_px"), r"c\.json: field 'distortion\.centre_y_px' is missing"),
        (lambda d: d["distortion"].update(k2=0.1), r"c\.json: unknown field\(s\) distortion\.k2"),
        (lambda d: d.update(extra=1), r"c\.json: unknown field\(s\) extra"),
        (lambda d: d.update(homography=[[1, 2, 0], [2, 4, 0], [0, 0, 1]]), r"c\.json: homography is singular"),
        (lambda d: d["distortion"].pop("focal_length_px"), r"c\.json: k1 ≠ 0 needs the distortion centre"),
    ],
)
def test_load_errors_name_file_and_field(tmp_path, change, match):
    d = _good()
    change(d)
    with pytest.raises(CalibrationError, match=match):
        PlaneCorrection.load(_write(tmp_path, d))


def test_load_errors_for_files(tmp_path):
    with pytest.raises(CalibrationError, match=r"nope\.toml: no such file; expected a plane correction file"):
        PlaneCorrection.load(tmp_path / "nope.toml")
    with pytest.raises(CalibrationError, match=r"c\.txt: a correction file must end in \.toml or \.json"):
        _corr().save(tmp_path / "c.txt")
    bad = tmp_path / "c.toml"
    bad.write_text("homography = [[1, 0")
    with pytest.raises(CalibrationError, match=r"c\.toml: not valid TOML"):
        PlaneCorrection.load(bad)


def test_normalised_keeps_angles_and_looks_like_identity():
    corr = _corr()
    n = normalised(corr, (700.0, 500.0))
    X, Y = n.to_disk(700.0, 500.0)
    assert (float(X), float(Y)) == pytest.approx((700.0, 500.0), abs=1e-9)
    J, _, _ = n.jacobian(700.0, 500.0)
    assert np.linalg.det(J) == pytest.approx(1.0, abs=1e-12) and J[0, 1] == pytest.approx(J[1, 0], abs=1e-12)
    pts = np.array([[200.0, 300.0], [1100.0, 700.0], [400.0, 900.0]])

    def direction(c):
        X, Y = c.to_disk(pts[:, 0], pts[:, 1])
        return np.degrees(np.arctan2(-(Y[1:] - Y[0]), X[1:] - X[0]))

    d0, d1 = direction(corr), direction(n)
    # a similarity turns every line by the same amount
    assert np.ptp(d1 - d0) < 1e-9
