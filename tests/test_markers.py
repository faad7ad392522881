"""find_markers on rendered images of known truth."""

import cv2
import numpy as np
import pytest
from helpers import area_image, ellipse_mask, supersampled_grid

from vision_torsion.errors import MarkerError
from vision_torsion.markers import MARKER_COLUMNS, find_markers
from vision_torsion.pair import measure_pair, select_pair
from vision_torsion.settings import MeasureSettings
from vision_torsion.synthetic import load_scene, render


def _match(table, truth):
    ok = table[table["status"] == "ok"]
    errs = []
    for x, y in truth:
        d = np.hypot(ok["x_px"] - x, ok["y_px"] - y)
        i = int(np.argmin(d))
        errs.append((ok["x_px"].iloc[i] - x, ok["y_px"].iloc[i] - y))
    return np.array(errs)


def test_table_columns_and_sub_pixel_accuracy(standard_scene):
    """Centres within 0.015 px (6x the ~0.0024 px std) at non-integer positions."""
    for seed, angle in enumerate((-63.3, 0.0, 41.7)):
        r = render(standard_scene, angle, seed=seed)
        table = find_markers(r.image)
        assert list(table.columns) == MARKER_COLUMNS
        assert list(table["status"]) == ["ok", "ok"]
        assert np.abs(_match(table, r.centres)).max() < 0.015
        assert (table["n_edge_points"] > 150).all()
        assert ((table["circularity"] > 0.99) & (table["circularity"] <= 1.0)).all()
        assert np.allclose(table["contrast_dn"], -160, atol=2)


def test_coarsest_detection_scale_is_as_accurate(standard_scene):
    """Markers of 20 px and more are found on an 8x reduced image (2.5 reduced px of
    radius at least); the fit from that start lands on the same centres. Markers of
    3-5 px (the default smallest is 3 px) are found at half resolution."""
    from vision_torsion.detect import detection_reduction

    assert [detection_reduction(r) for r in (20, 19.9, 10, 4, 3, 2.9)] == [8, 4, 4, 2, 2, 1]
    r = render(standard_scene, 23.4, seed=5)
    fine = find_markers(r.image, radius_range=(10, 60))
    coarse = find_markers(r.image, radius_range=(20, 60))
    assert list(coarse["status"]) == ["ok", "ok"]
    assert np.abs(_match(coarse, r.centres)).max() < 0.015
    by_x = [t.sort_values("x_px")[["x_px", "y_px"]].to_numpy() for t in (coarse, fine)]
    np.testing.assert_allclose(*by_x, atol=2e-3)


@pytest.mark.parametrize("fit", ["geometric", "algebraic", "ellipse"])
def test_every_fit_method_is_accurate(small_scene, fit):
    r = render(small_scene, 17.0, seed=3)
    table = find_markers(r.image, fit=fit)
    assert np.abs(_match(table, r.centres)).max() < 0.03


def test_bright_markers_on_dark_disk(small_scene):
    scene = small_scene.replace(disk={"background_level": 50.0}, markers={"polarity": "bright", "level": 210.0})
    r = render(scene, 5.0, seed=1)
    assert (find_markers(r.image, polarity="dark")["status"] != "ok").all() or len(
        find_markers(r.image, polarity="dark")
    ) == 0
    table = find_markers(r.image, polarity="bright")
    assert np.abs(_match(table, r.centres)).max() < 0.03


def test_uneven_lighting(small_scene):
    scene = small_scene.replace(lighting={"gradient_x": 0.4, "gradient_y": -0.3, "vignetting": 0.4})
    r = render(scene, -20.0, seed=2)
    assert np.abs(_match(find_markers(r.image), r.centres)).max() < 0.03


def test_marker_cut_by_border_is_reported_not_fitted(small_scene):
    img = render(small_scene, 0.0, seed=1).image[:, 90:]  # cuts the left marker in half
    table = find_markers(img, radius_range=(10, 40))
    cut = table[table["status"] == "border"]
    assert len(cut) == 1 and cut["message"].iloc[0] == "cut by the image border"
    assert np.isnan(cut["x_std_px"].iloc[0])
    assert (table["status"] == "ok").sum() == 1


def test_too_small_and_not_round_are_reported():
    img = np.full((200, 300), 200.0, np.float32)
    yy, xx = np.mgrid[0:200, 0:300]
    img[(xx - 80) ** 2 + (yy - 100) ** 2 < 22**2] = 40  # a round marker, r = 22
    img[(xx - 180) ** 2 + (yy - 100) ** 2 < 11**2] = 40  # a small one, r = 11
    img[60:140, 230:245] = 40  # a bar, not round
    table = find_markers(img, radius_range=(15, 40))
    by = dict(zip(table["status"], table["message"]))
    assert "too_small" in by and "below the smallest 15 px" in by["too_small"]
    assert "not_round" in by and "not round" in by["not_round"]
    assert (table["status"] == "ok").sum() == 1


def test_distractors_never_give_a_wrong_pair(scene_file):
    """Bolt holes, a wire crossing the markers' path and dust: the right pair or a clear error."""
    scene = load_scene(scene_file("distractors"))
    for seed, angle in enumerate((-70.0, -35.0, 0.0, 35.0, 68.0, 72.0)):
        r = render(scene, angle, seed=seed)
        try:
            pair = measure_pair(r.image)
        except MarkerError:
            continue
        found = np.array([[m.x_px, m.y_px] for m in pair.markers])
        for x, y in r.centres:
            assert np.hypot(found[:, 0] - x, found[:, 1] - y).min() < 0.05


def test_missing_marker_is_a_clear_error(small_scene):
    img = render(small_scene, 0.0, seed=1).image.copy()
    img[120:185, 265:335] = 200  # paint over one marker
    with pytest.raises(MarkerError, match=r"img: found 1 usable marker\(s\), need 2"):
        measure_pair(img, name="img")


def test_ambiguous_target_is_an_error(small_scene):
    scene = small_scene.replace(markers={"positions_deg": [0.0, 120.0, 240.0]})
    img = render(scene, 0.0, seed=1).image
    with pytest.raises(MarkerError, match="ambiguous target: 3 markers of radius"):
        measure_pair(img)


def test_no_matching_radii_is_an_error():
    img = np.full((200, 300), 200.0, np.float32)
    yy, xx = np.mgrid[0:200, 0:300]
    img[(xx - 80) ** 2 + (yy - 100) ** 2 < 30**2] = 40
    img[(xx - 220) ** 2 + (yy - 100) ** 2 < 18**2] = 40
    with pytest.raises(MarkerError, match="no two markers of matching radius"):
        select_pair(find_markers(img, radius_range=(12, 40)), name="x")


def test_low_contrast_marker_is_reported():
    rng = np.random.default_rng(0)
    img = 200 + 8 * rng.standard_normal((200, 200)).astype(np.float32)
    yy, xx = np.mgrid[0:200, 0:200]
    img[(xx - 100) ** 2 + (yy - 100) ** 2 < 25**2] -= 12  # 12 DN against 8 DN noise
    table = find_markers(img, radius_range=(15, 40))
    assert (
        (table["status"] != "ok").all()
        or table.empty
        or (table["status"].isin(["low_contrast", "not_round", "fit_failed"])).any()
    )


def test_settings_validation():
    from vision_torsion.errors import VisionTorsionError

    with pytest.raises(VisionTorsionError, match="polarity must be one of"):
        MeasureSettings(polarity="grey")
    with pytest.raises(VisionTorsionError, match="fit must be one of"):
        MeasureSettings(fit="hough")
    with pytest.raises(VisionTorsionError, match="radius_range must be"):
        MeasureSettings(radius_range=(30, 10))
    with pytest.raises(VisionTorsionError, match="unknown measurement setting"):
        MeasureSettings.from_dict({"colour": 1})


def test_input_array_not_modified(small_scene):
    img = render(small_scene, 0.0, seed=1).image
    before = img.copy()
    find_markers(img)
    assert np.array_equal(img, before)


def test_circularity_of_a_circle_with_missing_sectors_is_one():
    """Edge points on 300° of a circle (sectors dropped for an occluder) are still round.

    Regression: the radius itself leaked into the second harmonic when the points
    were unevenly spread, and a round marker was rejected as not round (0.90).
    """
    from vision_torsion.ring import points_circularity

    t = np.linspace(0.3, 0.3 + np.deg2rad(300), 200)
    assert points_circularity(812.0 + 35 * np.cos(t), 455.0 + 35 * np.sin(t), 812.0, 455.0, 35.0) > 0.999


def test_integer_and_float_images_give_the_same_markers(small_scene):
    """uint8/uint16 arrays are measured without a full-frame float copy, to the same result."""
    img = render(small_scene, 12.0, seed=7).image
    a = find_markers(img)
    b = find_markers(img.astype(np.float32))
    np.testing.assert_allclose(a[["x_px", "y_px"]].to_numpy(), b[["x_px", "y_px"]].to_numpy(), atol=1e-9)
    c = find_markers(img.astype(np.uint16) * 16)
    np.testing.assert_allclose(a[["x_px", "y_px"]].to_numpy(), c[["x_px", "y_px"]].to_numpy(), atol=1e-6)


def test_candidates_found_beforehand_give_the_same_pair(scene_file):
    """measure_pair with the candidates of find_candidates (as a session's reading
    threads find them) measures what it measures alone (to 1e-8 px), for the default
    radius range and a given one, among bolt holes and dust."""
    from vision_torsion.markers import find_candidates

    image = render(load_scene(scene_file("distractors")), 0.0, seed=2).image
    assert len(find_candidates(image, MeasureSettings())) == 10  # with the bolt holes
    for settings in (MeasureSettings(), MeasureSettings(radius_range=(20, 60))):
        candidates = find_candidates(image, settings)
        alone = measure_pair(image, settings=settings)
        given = measure_pair(image, settings=settings, candidates=candidates)
        # alone, the default range first looks at a quarter of the resolution for large
        # markers: the same fit from a start a fraction of a pixel away, equal to 1e-8 px
        for a, b in zip(given.markers, alone.markers):
            assert (a.status, a.n_edge_points) == (b.status, b.n_edge_points)
            np.testing.assert_allclose([a.x_px, a.y_px, a.radius_px], [b.x_px, b.y_px, b.radius_px], atol=1e-8)
        with pytest.raises(MarkerError):  # they are what is used: none given, none found
            measure_pair(image, settings=settings, candidates=[])


def test_pair_candidates_give_the_pair_measure_pair_finds_alone(scene_file, small_scene):
    """pair_candidates (what a session's reading threads find) passed back to
    measure_pair give exactly its own answer: the coarse first look for large markers
    (the same blobs, so bit-identical), the full detection when the coarse look
    cannot settle the pair (small markers) or the range is given."""
    from vision_torsion.pair import pair_candidates

    large = render(load_scene(scene_file("distractors")), 0.0, seed=2).image
    small = render(small_scene, 10.0, seed=3).image
    tiny_scene = small_scene.replace(markers={"radius_px": 6.0, "distance_px": 60.0})
    tiny = render(tiny_scene, 10.0, seed=4).image  # 6 px markers: the coarse look cannot settle them
    cases = [(large, MeasureSettings(), True), (large, MeasureSettings(radius_range=(20, 60)), False),
             (small, MeasureSettings(), True), (tiny, MeasureSettings(), True)]
    for image, settings, coarse in cases:
        found = pair_candidates(image, settings)
        assert found.coarse is coarse
        alone = measure_pair(image, settings=settings)
        given = measure_pair(image, settings=settings, candidates=found)
        for a, b in zip(given.markers, alone.markers):
            assert (a.status, a.n_edge_points) == (b.status, b.n_edge_points)
            assert (a.x_px, a.y_px, a.radius_px) == (b.x_px, b.y_px, b.radius_px)


def test_settings_and_explicit_options_are_not_mixed(small_scene):
    """Issue 18: settings used to override explicit keyword options silently
    (fit="algebraic" with settings of fit="pixels" fitted pixels)."""
    from vision_torsion.errors import VisionTorsionError

    image = render(small_scene, 0.0, seed=5).image
    for option in ({"fit": "algebraic"}, {"polarity": "bright"}, {"radius_range": (5.0, 40.0)}):
        with pytest.raises(VisionTorsionError, match=f"give either settings or {next(iter(option))}, not both") as info:
            find_markers(image, settings=MeasureSettings(), **option)
        assert info.value.reason == "conflicting_options"
    by_options = find_markers(image, fit="algebraic")
    by_settings = find_markers(image, settings=MeasureSettings(fit="algebraic"))
    assert by_options.equals(by_settings)
    assert not by_options.equals(find_markers(image))  # the option really chose another fit


@pytest.mark.parametrize("gap_px", [4.0, 9.0])
def test_a_large_neighbour_does_not_take_a_marker_s_own_pixels(gap_px):
    """A neighbour's pixels are left out to 1.15 times its coarse radius plus its
    blurred edge: for a dark disc of radius 60 px that reached 5-10 px into the
    marker beside it, whose fit lost its own edge on that side. A marker seen at an
    angle (an ellipse, axis ratio 0.82, still judged round) then moved 0.2-0.8 px
    (dots beside the dark surround of the card on a full UCL frame: 1-4.5 px).
    Truth: the ellipse (semi-axes 9 and 7.4 px at 40°) at a sub-pixel centre,
    `gap_px` from the large disc's edge, rendered 4x supersampled, blurred (σ 1.2
    px), noise σ 2 DN on a contrast of 160 DN: its centre's σ is ~0.01 px, so 0.05 px."""
    h, w, n = 260, 330, 4
    big, r_big, a, b, tilt = (90.3, 130.2), 60.0, 9.0, 7.4, np.deg2rad(40.0)
    small = (big[0] + r_big + gap_px + a, 130.63)
    ys, xs = (np.mgrid[0 : h * n, 0 : w * n] + 0.5) / n - 0.5
    u = (xs - small[0]) * np.cos(tilt) + (ys - small[1]) * np.sin(tilt)
    v = (ys - small[1]) * np.cos(tilt) - (xs - small[0]) * np.sin(tilt)
    dark = (np.hypot(xs - big[0], ys - big[1]) < r_big) | ((u / a) ** 2 + (v / b) ** 2 < 1.0)
    img = 200.0 - 160.0 * dark.reshape(h, n, w, n).mean(axis=(1, 3))
    img = cv2.GaussianBlur(img, (0, 0), 1.2) + np.random.default_rng(7).normal(0.0, 2.0, img.shape)
    table = find_markers(img.astype(np.float32))
    ok = table[table["status"] == "ok"]
    assert len(ok) == 2, table
    near = ok[np.hypot(ok["x_px"] - small[0], ok["y_px"] - small[1]) < 3.0]
    assert len(near) == 1, table
    assert (float(near["x_px"].iloc[0]), float(near["y_px"].iloc[0])) == pytest.approx(small, abs=0.05)


def test_neighbours_of_a_few_candidates_are_the_array_rule():
    """neighbours_of' plain-float path (up to 8 candidates: the pair search) picks the
    same circles as near_candidates's array rule, including circles exactly at its reach."""
    from vision_torsion.markers import candidate_extent, near_candidates, neighbours_of

    rng = np.random.default_rng(21)
    for _ in range(2000):
        k = int(rng.integers(1, 9))
        circles = np.column_stack([rng.uniform(0, 300, k), rng.uniform(0, 300, k), rng.uniform(1, 60, k)])
        width = float(rng.choice([0.8, 1.2, 2.5]))
        for i in range(k):
            np.testing.assert_array_equal(neighbours_of(circles, i, width),
                                          circles[near_candidates(circles, np.array([i]), width)[0]])
    # a neighbour exactly at the reach is not near (strict), one a hair inside is
    circles = np.array([[100.0, 100.0, 20.0], [0.0, 100.0, 10.0]])
    x_reach = 100.0 - (float(candidate_extent(20.0, 1.2)) + 1.15 * 10.0 + 3.0 * 1.2 + 1.0)
    for x, expected in ((x_reach, 0), (np.nextafter(x_reach, 100.0), 1)):
        circles[1, 0] = x
        assert len(neighbours_of(circles, 0, 1.2)) == expected
        assert len(circles[near_candidates(circles, np.array([0]), 1.2)[0]]) == expected


def test_a_disc_seen_obliquely_is_found_and_a_non_round_blob_is_not():
    """Dots of a card seen at an angle are ellipses: axis ratio 0.7 (45° off-axis) is
    below the circle's roundness limit (0.8), yet a person would mark them. An ellipse
    through the fit's edge points describes them: ``ok``, said so in the message, at
    the true centre. A teardrop and a 30x24 px rectangle, whose edges no ellipse
    describes, stay ``not_round``. Truth: shapes at sub-pixel centres rendered 4x
    supersampled, blurred (σ 1 px), noise σ 2 DN on a contrast of 160 DN; the
    centres' σ is ~0.01 px, hence 0.05 px."""
    ellipses = [((60.37, 60.81), 12.0, 30.0), ((160.62, 58.29), 6.0, -65.0), ((260.18, 61.55), 9.0, 90.0)]
    _assert_ellipses_ok_and_the_rest_not_round(ellipses, 0.7, shape=(200, 420), blur=1.0, noise=2.0,
                                               levels=(200.0, 160.0), seed=11, tolerance=0.05)


def test_small_noisy_discs_seen_obliquely_are_found():
    """Near the border of the full discorpy 06 frame the dots are ellipses of axis
    ratio 0.7-0.8 (lens distortion), r ≈ 5 px, blurred (s ≈ 2.3 px) and noisy: their
    edge points' RMS distance from the centred ellipse, ~1.4 times what the pixel noise
    alone gives them, was more than 0.4 of their distance from the circle, and 343 of
    its 1461 grid dots were not_round. The ellipse may now hold twice the edge points'
    noise figure as well: ten such ellipses (radius 5.5 px, axis ratio 0.75, random
    orientations, 100 DN on 120 DN, blur σ 2.2 px, noise σ 6 DN) are ok at their
    centres; the teardrop and the rectangle beside them stay not_round. Tolerance:
    the centres' σ is ~0.065 px here (100 such ellipses: RMS 0.064 px), so 0.25 px."""
    rng = np.random.default_rng(3)
    ellipses = [((30.37 + 40 * i + rng.uniform(0, 1), 30.81 + rng.uniform(0, 1)), 5.5, rng.uniform(0, 180))
                for i in range(10)]
    _assert_ellipses_ok_and_the_rest_not_round(ellipses, 0.75, shape=(160, 420), blur=2.2, noise=6.0,
                                               levels=(120.0, 100.0), seed=4, tolerance=0.25, shapes_y=100.4,
                                               may_look_round=True)


def test_small_dots_under_uneven_light_are_found_and_centred():
    """The discorpy 06 photo's light falls from 210 to 60 DN across the target. Dots of
    radius 6.5 px (92 % dark, blur σ 2.2 px) on light that rises 4x across the image,
    steepening (a power 1.5 of x) and bowed along y: every whole dot is ok, at its
    centre. The model's lighting plane over each dot takes the local gradient (up to
    20 % over a dot's ring here); its curvature over ~40 px is far below the noise.
    Noise σ 3 DN: the centres' σ is 0.02-0.04 px (darker dots noisier), so 0.15 px."""
    rng = np.random.default_rng(5)
    h, w = 240, 400
    xs, ys = supersampled_grid(h, w)
    centres = [(40.3 + 64 * i + rng.uniform(0, 1), 40.6 + 52 * j + rng.uniform(0, 1))
               for i in range(6) for j in range(4)]
    dark = np.zeros(xs.shape, bool)
    for c in centres:
        dark |= ellipse_mask(xs, ys, c, 6.5)
    yy, xx = np.mgrid[0:h, 0:w]
    light = 60.0 + 150.0 * (xx / w) ** 1.5 + 30.0 * np.sin(yy / h * np.pi)
    img = light * area_image(dark, background=1.0, depth=0.92)
    img = cv2.GaussianBlur(img, (0, 0), 2.2) + rng.normal(0.0, 3.0, img.shape)
    table = find_markers(img.astype(np.float32))
    ok = table[table["status"] == "ok"]
    assert len(ok) == len(centres) == len(table), table
    for cx, cy in centres:
        near = ok[np.hypot(ok["x_px"] - cx, ok["y_px"] - cy) < 3.0]
        assert len(near) == 1, table
        assert (float(near["x_px"].iloc[0]), float(near["y_px"].iloc[0])) == pytest.approx((cx, cy), abs=0.15)


def _assert_ellipses_ok_and_the_rest_not_round(ellipses, axis_ratio, *, shape, blur, noise, levels, seed,
                                               tolerance, shapes_y=140.4, may_look_round=False):
    """Render dark `ellipses` ((centre, geometric-mean radius, angle in degrees) of
    `axis_ratio`), a teardrop (a disc of 12 px at (100.3, `shapes_y`) and a half
    ellipse of 8 x 14 px below it) and a 30x24 px rectangle beside it, 4x supersampled
    (background and depth `levels` in DN), blurred (σ `blur` px), noise σ `noise` DN
    (seeded); assert every ellipse ok within `tolerance` px of its centre with the
    oblique message (or none, judged round through its noise, if `may_look_round`),
    and the teardrop and the rectangle not_round (the teardrop: or occluded)."""
    xs, ys = supersampled_grid(*shape)
    dark = np.zeros(xs.shape, bool)
    for centre, r, angle in ellipses:
        dark |= ellipse_mask(xs, ys, centre, r, axis_ratio, angle)
    dark |= np.hypot(xs - 100.3, ys - shapes_y) < 12.0
    dark |= (ys > shapes_y + 6.0) & (((xs - 100.3) / 8.0) ** 2 + ((ys - shapes_y - 6.0) / 14.0) ** 2 < 1.0)
    dark |= (np.abs(xs - 250.2) < 15.0) & (np.abs(ys - shapes_y - 10.3) < 12.0)  # a rectangle
    img = cv2.GaussianBlur(area_image(dark, background=levels[0], depth=levels[1]), (0, 0), blur)
    img += np.random.default_rng(seed).normal(0.0, noise, img.shape)
    table = find_markers(img.astype(np.float32), radius_range=(3, 40))
    ok = table[table["status"] == "ok"]
    assert len(ok) == len(ellipses), table
    for (cx, cy), _, _ in ellipses:
        near = ok[np.hypot(ok["x_px"] - cx, ok["y_px"] - cy) < 3.0]
        assert len(near) == 1, table
        assert (float(near["x_px"].iloc[0]), float(near["y_px"].iloc[0])) == pytest.approx((cx, cy), abs=tolerance)
        message = near["message"].iloc[0]
        assert message.startswith("seen obliquely: the edge is an ellipse of axis ratio 0.") or (
            may_look_round and message == ""), table
    rest = table[table["status"] != "ok"]
    for cx, cy in ((100.3, shapes_y + 4.6), (250.2, shapes_y + 10.3)):
        near = rest[np.hypot(rest["x_px"] - cx, rest["y_px"] - cy) < 8.0]
        # a small noisy teardrop may pass as an ellipse, whose asymmetry about its
        # centre then rejects it (occluded): either way not a disc, never ok
        assert list(near["status"]) in (["not_round"], ["occluded"]), table


def test_a_neighbour_whose_circle_holds_the_marker_takes_none_of_its_pixels():
    """A large candidate's coarse circle can hold other markers: the dark surround of a
    calibration card, cut by the image border, had a coarse circle of 114-166 px that
    covered dots of the card, and their sides facing it were left out as its pixels
    (dots 4 px off yet ok, or no start at all). Such a neighbour is no disc there, so
    none of its pixels are left out: a dot of 12 px at a sub-pixel centre, 20 px
    from a dark band along the border, given that band's coarse circle as a
    neighbour, is fitted as without it. Truth: rendered 4x supersampled, blur σ 1 px,
    noise σ 2 DN on 160 DN; σ of the centre ~0.005 px, hence 0.03 px."""
    from vision_torsion.detect import Blob
    from vision_torsion.markers import fit_marker

    h, w, n = 120, 160, 4
    centre = (70.37, 60.58)
    ys, xs = (np.mgrid[0 : h * n, 0 : w * n] + 0.5) / n - 0.5
    dark = (np.hypot(xs - centre[0], ys - centre[1]) < 12.0) | (xs < 38.0)
    img = 200.0 - 160.0 * dark.reshape(h, n, w, n).mean(axis=(1, 3))
    img = cv2.GaussianBlur(img, (0, 0), 1.0) + np.random.default_rng(4).normal(0.0, 2.0, img.shape)
    img = img.astype(np.float32)
    blob = Blob(x=70.0, y=61.0, radius=12.0, elongation=1.0, fill=1.0, touches_border=False)
    alone = fit_marker(img, blob)
    held = fit_marker(img, blob, neighbours=[(-40.0, 60.0, 120.0)])  # its circle reaches x = 80
    assert alone.ok and held.ok, (alone, held)
    assert (held.x_px, held.y_px) == pytest.approx(centre, abs=0.03)
    assert (held.x_px, held.y_px) == pytest.approx((alone.x_px, alone.y_px), abs=1e-9)


@pytest.mark.parametrize("seed, angle", [(0, -70.0), (1, 35.0), (2, 70.0)])
def test_noise_specks_of_a_faint_scene_are_not_ok_markers(seed, angle):
    # On the low-contrast scene the disc model, started on a speck of noise, could end
    # at a negative radius with a standard deviation of 10-6000 px (and a circularity
    # above 1), and such candidates were reported ok: 3-8 "markers" where the scene
    # has 2. A radius must be positive and at least twice its standard deviation.
    from vision_torsion.synthetic import marker_centres_image

    scene = load_scene("low_contrast")
    table = find_markers(render(scene, angle, seed=seed).image)
    ok = table[table.status == "ok"]
    truth = marker_centres_image(scene, angle)
    assert len(ok) == len(truth) == 2
    found = ok[["x_px", "y_px"]].to_numpy()
    assert np.all(np.min(np.hypot(*(found[:, None, :] - truth[None, :, :]).transpose(2, 0, 1)), axis=0) < 0.5)
    assert np.all(ok.radius_px > 2 * ok.radius_std_px)
    faint = table[table.message.str.contains("is not a disc's", regex=False)]
    assert len(faint) >= 2 and set(faint.status) == {"fit_failed"}


def _excluded_per_marker(patch, neighbours, edge_width, own):
    """The neighbour exclusion as it was written for one marker: every neighbour's
    distances over the whole patch (the simple version the box search replaces), none
    of a candidate whose circle holds the marker's centre."""
    from vision_torsion.markers import neighbour_reach

    rows, cols = patch.shape
    nb = np.asarray(neighbours, dtype=np.float64).reshape(-1, 3)
    reach = neighbour_reach(nb[:, 2], edge_width)
    dx = np.arange(cols) + (patch.x0 - nb[:, :1])
    dy = np.arange(rows) + (patch.y0 - nb[:, 1:2])
    d2 = dy[:, :, None] ** 2 + dx[:, None, :] ** 2
    inside = d2 < (reach**2)[:, None, None]
    # a candidate whose circle holds the marker's centre (its region) is no neighbour
    held = np.hypot(nb[:, 0] - own[0], nb[:, 1] - own[1]) < nb[:, 2]
    inside[held] = False
    large = np.flatnonzero((nb[:, 2] > 1.5 * own[2]) & ~held)
    k, y, x = np.nonzero(inside[large])
    k = large[k]
    ours = np.hypot(x + (patch.x0 - own[0]), y + (patch.y0 - own[1])) - own[2] <= np.sqrt(d2[k, y, x]) - nb[k, 2]
    inside[k[ours], y[ours], x[ours]] = False
    return inside.any(axis=0).ravel()


def test_neighbour_exclusion_of_many_patches_is_the_per_marker_one():
    """The box search over many patches at once (excluding_neighbours) flags the
    same pixels as every neighbour's distances over the whole patch, marker by
    marker: dense grids, large neighbours (with and without the marker's centre in
    their circle), patches cut by the border, centres near the image origin (where
    the patch origin's offset from a neighbour is rounded)."""
    from vision_torsion.detect import Blob
    from vision_torsion.markers import candidate_patch, excluding_neighbours, near_candidates

    rng = np.random.default_rng(2024)
    image = np.zeros((240, 320), np.uint8)
    for trial in range(60):
        n = int(rng.integers(2, 40))
        spread = (40.0, 30.0) if trial % 3 == 0 else (320.0, 240.0)  # near the origin, or anywhere
        circles = np.column_stack([rng.uniform(0.0, spread[0], n), rng.uniform(0.0, spread[1], n),
                                   rng.uniform(1.5, 6.0, n)])
        big = rng.random(n) < 0.15
        circles[big, 2] = rng.uniform(10.0, 60.0, big.sum())
        circles[:, :2] += rng.random((n, 2)) * 1e-9  # bits far below the pixel
        width = float(rng.choice([0.4, 1.0, 1.7, 3.2]))
        rows = np.arange(n)
        patches = [candidate_patch(image, Blob(x=x, y=y, radius=r, elongation=1.0, fill=1.0, touches_border=False),
                                   width) for x, y, r in circles]
        owner, near = np.nonzero(near_candidates(circles, rows, width))
        got = excluding_neighbours(patches, owner, circles[near], width, circles)
        for i in rows:
            want = _excluded_per_marker(patches[i], circles[near[owner == i]], width, circles[i])
            flags = got[i].excluded
            np.testing.assert_array_equal(np.zeros(want.size, bool) if flags is None else flags, want)
            assert (flags is None) == (not want.any())


def test_markers_of_a_jpeg_take_their_covariance_from_its_blocks(tmp_path):
    """measure_pair and find_markers given a JPEG file (or its GreyImage) fit the
    same centres as from its pixels as a plain array, with the covariance from its
    8x8 blocks (pixelfit): larger than the white-noise one at quality 75 (1.2-1.3x
    in σ here; the white one was 1.7x too small for such images in
    test_pixelfit)."""
    from vision_torsion.images import load_image, write_image
    from vision_torsion.synthetic import Scene

    scene = Scene().replace(image={"width": 500, "height": 300}, disk={"center_x": 250.3, "center_y": 150.8},
                            markers={"radius_px": 45.0, "distance_px": 150.0})
    path = tmp_path / "a.jpg"
    write_image(path, render(scene, 20.0, seed=3).image, jpeg_quality=75)
    pixels = load_image(path).data
    for given in (path, load_image(path, keep_integers=True)):
        blocks, white = measure_pair(given), measure_pair(pixels)
        for b, w in zip(blocks.markers, white.markers):
            assert (b.x_px, b.y_px) == (w.x_px, w.y_px)
            assert b.x_std_px > 1.1 * w.x_std_px and b.y_std_px > 1.1 * w.y_std_px
    table, plain = find_markers(path), find_markers(pixels)
    assert (table.x_std_px > 1.1 * plain.x_std_px).all() and (table.x_px == plain.x_px).all()
    from vision_torsion.session.targetrows import measure_target_markers

    found, bare = measure_target_markers(path).columns, measure_target_markers(pixels).columns
    assert found["x_px"] == bare["x_px"]
    assert all(b > 1.1 * w for b, w in zip(found["x_std_px"], bare["x_std_px"]))
