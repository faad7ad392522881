"""Plane self-calibration against the renderer's camera model (seeded synthetic truth)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vision_torsion.angle import sequence_angles
from vision_torsion.calibration import MIN_SWEEP_DEG, calibrate_plane
from vision_torsion.errors import CalibrationError
from vision_torsion.markers import Marker
from vision_torsion.pair import PairMeasurement
from vision_torsion.synthetic import load_scene, render, scene_from_dict, scene_to_dict
from vision_torsion.synthetic.geometry import CameraMapping, marker_centres_disk

TILTED = load_scene(Path(__file__).resolve().parents[1] / "vision_torsion" / "synthetic" / "scenes" / "tilted.toml")
CAM = CameraMapping(TILTED)
SIGMA = 0.005  # px: the measured centre uncertainty on the standard scene


def _pairs(angles, rng, sigma=SIGMA):
    out = []
    for a in angles:
        c = marker_centres_disk(TILTED, a)
        x, y = CAM.to_image(c[:, 0], c[:, 1])
        ms = [
            Marker(x_px=float(u + rng.normal(0, sigma)), y_px=float(v + rng.normal(0, sigma)), radius_px=35.0,
                   x_std_px=max(sigma, 1e-6), y_std_px=max(sigma, 1e-6), xy_cov_px2=0.0)
            for u, v in zip(x, y)
        ]
        out.append(PairMeasurement(*sorted(ms, key=lambda m: m.x_px)))
    return out


def _rms_error(corr, angles):
    exact = _pairs([0.0, *angles], np.random.default_rng(0), sigma=0.0)
    res = sequence_angles(exact[0], exact[1:], correction=corr)
    return float(np.sqrt(np.mean([(r.angle_deg - a) ** 2 for r, a in zip(res, angles)])))


def test_self_calibration_removes_the_tilt_error():
    rng = np.random.default_rng(42)
    sweep = np.concatenate([[0.0], np.linspace(-70, 70, 15)])
    corr = calibrate_plane(_pairs(sweep, rng), distortion_centre=tuple(CAM.c), focal_length_px=5000.0)
    test = np.linspace(-70, 70, 29)
    raw, fixed = _rms_error(None, test), _rms_error(corr, test)
    # uncorrected 3° tilt: ≈ 0.038° RMS over ±70°; the correction is limited only by the
    # calibration images' centre noise (0.005 px over 600 px ≈ 0.0005° per image), so
    # 0.001° leaves a factor ~2 of margin for the seed
    assert raw > 0.03
    assert fixed < 0.001
    assert corr.method == "self-calibration" and corr.info["n_images"] == 16
    assert corr.info["sweep_deg"] == pytest.approx(140.0, abs=0.2)
    # the fitted angles are the disk's rotation (CCW as displayed) to the same accuracy
    np.testing.assert_allclose(corr.info["angles_deg"], sweep, atol=0.003)
    assert 0.5 < corr.info["reduced_chi2"] < 2.0


def test_sweep_too_short_says_how_many_degrees():
    sweep = np.concatenate([[0.0], np.linspace(-10, 10, 8)])
    with pytest.raises(CalibrationError, match=rf"spans 20\.0°, too short .* at least {MIN_SWEEP_DEG:g}° is needed"):
        calibrate_plane(_pairs(sweep, np.random.default_rng(1)))


def test_too_few_images():
    with pytest.raises(CalibrationError, match=r"at least 6 usable images \(reference included\), got 4"):
        calibrate_plane(_pairs([0.0, -60.0, 0.0, 60.0], np.random.default_rng(1)))


def test_k1_needs_centre_for_pairs():
    with pytest.raises(CalibrationError, match=r"k1 needs distortion_centre and focal_length_px"):
        calibrate_plane(_pairs(np.linspace(-60, 60, 8), np.random.default_rng(1)), fit_k1=True)


def test_missing_covariance_is_an_error():
    pairs = _pairs(np.linspace(-60, 60, 8), np.random.default_rng(1))
    bad = PairMeasurement(Marker(x_px=1.0, y_px=2.0, radius_px=35.0), pairs[3].second)
    pairs[3] = bad
    with pytest.raises(CalibrationError, match=r"image 3: marker \d has no usable centre covariance"):
        calibrate_plane(pairs)


def test_self_calibration_from_rendered_images():
    # a small tilted scene (600x450 px, markers 120 px from the centre) keeps this fast;
    # the tilt is exaggerated to 6° (f = 2000 px) so the effect is far above the noise
    d = scene_to_dict(TILTED)
    d["image"].update(width=600, height=450)
    d["disk"].update(center_x=300.37, center_y=225.61)
    d["markers"].update(radius_px=18.0, distance_px=120.0)
    d["optics"].update(tilt_deg=6.0, focal_length_px=2000.0, radial_k1=0.0)
    scene = scene_from_dict(d)
    angles = [0.0, -70.0, -45.0, -20.0, 10.0, 35.0, 60.0, 70.0]
    images = [render(scene, a, seed=100 + i).image for i, a in enumerate(angles)]
    corr = calibrate_plane(images)
    assert corr.centre == (299.5, 224.5) and corr.focal_length_px == 600.0
    # a sweep in order whose first step is 70°: tracked without the 30° ambiguity limit
    res = sequence_angles(*_measured(images, None), max_step_deg=None)
    fixed = sequence_angles(*_measured(images, corr), correction=corr, max_step_deg=None)
    err_raw = np.abs([r.angle_deg - a for r, a in zip(res, angles[1:])]).max()
    err_fix = np.abs([r.angle_deg - a for r, a in zip(fixed, angles[1:])]).max()
    # 6° tilt: up to ≈ 0.3° error uncorrected; corrected, the error is the images' own
    # noise (reported angle σ ≈ 0.004°, largest seen 0.0024°), checked with margin
    # (centre σ ≈ 0.01 px over 240 px ≈ 0.003°), checked with a 3x margin
    assert err_raw > 0.1
    assert err_fix < 0.01


def _measured(images, corr):
    from vision_torsion.pair import measure_pair

    pairs = [measure_pair(im) for im in images]
    return pairs[0], pairs[1:]
