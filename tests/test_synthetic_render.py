"""The renderer against exact geometry: coverage, centroids, rotation, noise, scenes."""

import numpy as np
import pytest

from vision_torsion.errors import SceneError
from vision_torsion.synthetic import Scene, load_scene, render, render_ideal, scene_from_dict, scene_to_dict
from vision_torsion.synthetic.coverage import band_coverage, shape_coverage, square_halfplane_fraction
from vision_torsion.synthetic.geometry import CameraMapping, marker_centres_disk, rotate_about
from vision_torsion.synthetic.render import circle_distance_fn

SCENES = sorted(
    (__import__("pathlib").Path(__file__).parents[1] / "vision_torsion" / "synthetic" / "scenes").glob("*.toml")
)


def _disc(cx, cy, r, size=(90, 100)):
    mapping = CameraMapping(Scene())
    return shape_coverage(circle_distance_fn(mapping, cx, cy, r), 0, 0, size[1], size[0])


def test_coverage_centroid_and_area_are_exact():
    """Centroid within 0.001 px and area within 0.01 % of pi r^2 at random sub-pixel positions.

    The coverage itself is exact to ~1e-5 (area test); the centroid taken at pixel
    centres additionally carries the discretisation of the partial edge pixels,
    which shrinks as r^-1.5 and is ~3e-4 px at the marker sizes used here (20-40 px).
    """
    rng = np.random.default_rng(11)
    ys, xs = np.mgrid[0:90, 0:100]
    for _ in range(20):
        cx, cy = 50 + rng.uniform(-1, 1), 45 + rng.uniform(-1, 1)
        r = rng.uniform(20, 40)
        cov = _disc(cx, cy, r)
        area = cov.sum()
        assert abs(area / (np.pi * r * r) - 1) < 1e-4
        assert abs((cov * xs).sum() / area - cx) < 1e-3
        assert abs((cov * ys).sum() / area - cy) < 1e-3


def test_halfplane_fraction_matches_sampling():
    rng = np.random.default_rng(3)
    sub = (np.arange(400) + 0.5) / 400 - 0.5
    px, py = np.meshgrid(sub, sub)
    for _ in range(10):
        phi = rng.uniform(0, 2 * np.pi)
        nx, ny, t = np.cos(phi), np.sin(phi), rng.uniform(-0.8, 0.8)
        sampled = np.mean(nx * px + ny * py < t)
        assert abs(float(square_halfplane_fraction(t, nx, ny)) - sampled) < 3e-3  # 400x400 sampling


def test_band_coverage_of_a_vertical_wire():
    xs, ys = np.meshgrid(np.arange(10.0), np.arange(3.0))
    cov = band_coverage(xs, ys, point=(4.25, 0.0), direction_deg=90.0, width=2.0)
    # the band covers x in [3.25, 5.25]: pixel 3 -> 0.25, 4 -> 1, 5 -> 0.75
    np.testing.assert_allclose(cov[0, 2:7], [0, 0.25, 1, 0.75, 0], atol=1e-12)


def test_rotation_moves_true_centres_as_the_rotation_says():
    scene = Scene().replace(disk={"center_x": 700.37, "center_y": 500.61})
    c0 = marker_centres_disk(scene, 0.0)
    for angle in (-70.0, 12.5, 90.0, 180.0):
        expect = rotate_about(c0, (700.37, 500.61), angle)
        np.testing.assert_allclose(render(scene, angle, seed=0).centres, expect, atol=1e-9)
    # counter-clockwise as displayed: a marker on the +x axis moves up (y decreases)
    assert render(scene, 30.0, seed=0).centres[0, 1] < c0[0, 1]


def test_render_is_deterministic_for_a_seed(small_scene):
    a = render(small_scene, 5.0, seed=42).image
    b = render(small_scene, 5.0, seed=42).image
    c = render(small_scene, 5.0, seed=43).image
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_read_noise_has_the_configured_variance(small_scene):
    scene = small_scene.replace(
        noise={"read_noise_dn": 3.0},
        image={"bit_depth": 16},
        disk={"background_level": 30000.0},
        markers={"level": 10000.0},
    )
    ideal = render_ideal(scene, 0.0)
    noisy = render(scene, 0.0, seed=5).image.astype(float)
    resid = noisy - ideal
    # 120k pixels: the sample std of N(0, 3) plus rounding (1/12) is known to ~0.5 %
    assert abs(resid.std() - np.sqrt(9 + 1 / 12)) < 0.03


def test_shot_noise_variance_follows_the_signal(small_scene):
    scene = small_scene.replace(
        noise={"read_noise_dn": 0.0, "shot_noise": True, "electrons_per_dn": 4.0},
        image={"bit_depth": 16},
        disk={"background_level": 1000.0},
        markers={"level": 400.0},
    )
    ideal = render_ideal(scene, 0.0)
    resid = render(scene, 0.0, seed=9).image.astype(float) - ideal
    flat = ideal > 999.9
    # Poisson in electrons: variance in DN = signal / electrons_per_dn = 250 (+1/12 rounding)
    assert abs(resid[flat].var() / (1000 / 4 + 1 / 12) - 1) < 0.03


@pytest.mark.parametrize("bits,dtype,top", [(8, np.uint8, 255), (12, np.uint16, 4095), (16, np.uint16, 65535)])
def test_bit_depths(small_scene, bits, dtype, top):
    scale = (2**bits - 1) / 255
    scene = small_scene.replace(
        image={"bit_depth": bits}, disk={"background_level": 200 * scale}, markers={"level": 40 * scale}
    )
    img = render(scene, 0.0, seed=1).image
    assert img.dtype == dtype and img.max() <= top and img.max() > 0.7 * top


def test_jpeg_scene_keeps_its_bytes(small_scene):
    r = render(small_scene.replace(noise={"jpeg_quality": 80}), 0.0, seed=1)
    assert r.jpeg_bytes[:3] == b"\xff\xd8\xff" and r.image.dtype == np.uint8


def test_tilt_makes_ellipses_and_projects_centres():
    scene = Scene().replace(optics={"tilt_deg": 10.0, "tilt_axis_deg": 0.0, "focal_length_px": 3000.0})
    m = CameraMapping(scene)
    X, Y = np.array([100.0, 1300.0]), np.array([200.0, 900.0])
    x, y = m.to_image(X, Y)
    X2, Y2 = m.to_disk(x, y)
    np.testing.assert_allclose([X2, Y2], [X, Y], atol=1e-9)  # the mapping inverts
    assert not np.allclose([x, y], [X, Y])


def test_distortion_round_trip():
    m = CameraMapping(Scene().replace(optics={"radial_k1": -0.05}))
    x, y = m.to_image(np.array([10.0, 690.0]), np.array([15.0, 480.0]))
    np.testing.assert_allclose(m.to_disk(x, y), [[10.0, 690.0], [15.0, 480.0]], atol=1e-9)


def test_distractors_render(scene_file):
    scene = load_scene(scene_file("distractors"))
    img = render(scene, 20.0, seed=1).image
    assert img.shape == (1000, 1400) and img.min() < 70


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_ready_scenes_load_and_round_trip(path):
    if path.stem == "paper_session":
        from vision_torsion.synthetic.session import load_session_scene

        scene, _ = load_session_scene(path)
    else:
        scene = load_scene(path)
    assert scene_from_dict(scene_to_dict(scene)) == scene


def _base():
    return {
        "disk": {"center_x": 700.0, "center_y": 500.0, "background_level": 200.0},
        "markers": {"polarity": "dark", "level": 40.0, "radius_px": 35.0, "distance_px": 300.0},
    }


def test_scene_missing_field_is_named():
    data = _base()
    del data["markers"]["radius_px"]
    with pytest.raises(SceneError, match=r"\[markers\] radius_px is missing"):
        scene_from_dict(data, where="s.toml")


def test_scene_wrong_type_is_named():
    data = _base()
    data["markers"]["radius_px"] = "big"
    with pytest.raises(SceneError, match=r"s\.toml: \[markers\] radius_px must be a number, got 'big'"):
        scene_from_dict(data, where="s.toml")
    data = _base()
    data["image"] = {"width": 1400.5}
    with pytest.raises(SceneError, match=r"\[image\] width must be an integer"):
        scene_from_dict(data)


def test_scene_unknown_field_and_table():
    data = _base()
    data["markers"]["colour"] = "red"
    with pytest.raises(SceneError, match=r"\[markers\] unknown field\(s\) \['colour'\]"):
        scene_from_dict(data)
    with pytest.raises(SceneError, match=r"unknown table\(s\) \['camera'\]"):
        scene_from_dict({**_base(), "camera": {}})


def test_scene_negative_radius():
    data = _base()
    data["markers"]["radius_px"] = -3.0
    with pytest.raises(SceneError, match=r"\[markers\] radius_px must be positive"):
        scene_from_dict(data)


def test_scene_markers_outside_frame():
    data = _base()
    data["markers"]["distance_px"] = 680.0
    with pytest.raises(SceneError, match=r"marker 1 at rotation 0° lies outside the 1400x1000 frame"):
        scene_from_dict(data)


def test_scene_markers_overlap():
    data = _base()
    data["markers"]["positions_deg"] = [0.0, 5.0]
    with pytest.raises(SceneError, match="markers 1 and 2 overlap"):
        scene_from_dict(data)


def test_scene_polarity_must_match_levels():
    data = _base()
    data["markers"]["polarity"] = "bright"
    with pytest.raises(SceneError, match="does not match polarity 'bright'"):
        scene_from_dict(data)


def test_scene_file_errors(tmp_path):
    with pytest.raises(SceneError, match="no such file; expected a scene file"):
        load_scene(tmp_path / "none.toml")
    (tmp_path / "bad.toml").write_text("[image\nwidth=")
    with pytest.raises(SceneError, match="not valid TOML"):
        load_scene(tmp_path / "bad.toml")


def test_render_refuses_a_rotation_that_leaves_the_frame():
    scene = Scene().replace(markers={"distance_px": 480.0})
    with pytest.raises(SceneError, match="marker 1 at rotation 90° lies outside the 1400x1000 frame"):
        render(scene, 90.0)


def test_session_table_errors(tmp_path, scene_file):
    from vision_torsion.synthetic.session import load_session_scene

    text = scene_file("paper_session").read_text()
    cases = {
        "k_u_nm_per_rad = 4.4": ('k_u_nm_per_rad = "stiff"', r"\[session\] k_u_nm_per_rad must be a number"),
        "cycles = 1": ("cycles = 1.5", r"\[session\] cycles must be an integer"),
        "angle_sign = -1": ("angle_sign = 2", r"\[session\] angle_sign must be 1 or -1"),
        "tau_c_nm = 0.15": ("tau_c_nm = 0.15\ncolour = 1", r"\[session\] unknown field\(s\) \['colour'\]"),
        "step_mass_kg = 0.02": ("step_mass_kg = 0.0", r"\[session\] step_mass_kg must be positive"),
    }
    for old, (new, message) in cases.items():
        path = tmp_path / "s.toml"
        path.write_text(text.replace(old, new))
        with pytest.raises(SceneError, match=message):
            load_session_scene(path)


def test_session_truth_follows_the_bilinear_model():
    """True angles of a planned session are the model's, relative to the reference."""
    from vision_torsion.analysis.models import bilinear_response
    from vision_torsion.synthetic.session import SessionSpec, session_truth

    spec = SessionSpec(mass_tolerance_kg=0.0, orientations_deg=(0.0,))
    rows = [
        {"image": f"i{k}.png", "orientation_deg": "0", "cycle": "1", "phase": ph, "step": "0", "mass_kg": m}
        for k, (ph, m) in enumerate(
            [
                ("reference", "0"),
                ("positive_unloading", "0.36"),
                ("positive_unloading", "0"),
                ("negative_loading", "0.36"),
                ("negative_unloading", "0"),
                ("positive_loading", "0.36"),
            ]
        )
    ]
    truth, _ = session_truth(spec, rows, seed=0)
    tau = 2 * truth["true_torque_nm"].to_numpy() / 2
    expect = np.degrees(bilinear_response(tau, k_u=4.4, k_l=0.3, tau_c=0.15))
    np.testing.assert_allclose(truth["true_angle_deg"], expect - expect[0], atol=1e-9)
    assert truth["true_torque_nm"].iloc[1] == pytest.approx(2 * 0.36 * 9.81 * 0.05)
