"""A marker beside something dark whose blurred edge reaches into its ring: a blurred
neighbour, a large dark region, a candidate that is no marker over its edge. Each
marker is found ``ok`` close to its true centre, or is not ``ok``: never ``ok`` more
than 0.5 px off (issue 31).

Truth comes from images rendered here by exact sub-pixel area coverage (4 x 4 per
pixel: dark discs at 40 DN on 200 DN), blurred by a Gaussian of the given σ, with
2 DN of seeded noise, at non-integer centres.
"""

import cv2
import numpy as np
import pytest
from helpers import area_image, ellipse_mask, supersampled_grid

from vision_torsion.detect import Blob
from vision_torsion.markers import (
    HIDDEN_ARC_MESSAGE,
    MERGED_END_MESSAGE,
    UNLIKE_NEIGHBOURS_MESSAGE,
    UNMASKED_MESSAGE,
    find_candidates,
    find_marker_list,
    find_markers,
)
from vision_torsion.settings import MeasureSettings
from vision_torsion.synthetic import Scene, render

#: The issue's bound: an ``ok`` centre is never further than this from the truth (px).
BOUND_PX = 0.5


def _render(shape, dots, *, blur, seed, region=None):
    """8-bit image of dark discs ((centre, radius) each) and the dark sub-pixels
    `region(xs, ys)` flags, blurred by `blur` px, with 2 DN of noise."""
    xs, ys = supersampled_grid(*shape)
    dark = np.zeros(xs.shape, bool)
    for centre, radius in dots:
        dark |= ellipse_mask(xs, ys, centre, radius)
    if region is not None:
        dark |= region(xs, ys)
    img = cv2.GaussianBlur(area_image(dark), (0, 0), blur)
    img += np.random.default_rng(seed).normal(0.0, 2.0, shape)
    return np.clip(img, 0, 255).astype(np.uint8)


def _nearest(table, centre):
    """The row of `table` nearest `centre` and its distance from it (px)."""
    d = np.hypot(table["x_px"] - centre[0], table["y_px"] - centre[1])
    return table.loc[d.idxmin()], float(d.min())


CENTRE = (60.3, 60.6)


@pytest.mark.parametrize(
    "radius, blur, gap",
    [(6.0, 3.5, 4.0), (6.0, 3.5, 8.0), (10.0, 3.5, 2.0), (10.0, 3.5, 4.0), (6.0, 2.0, 2.0), (6.0, 1.0, 2.0),
     (6.0, 3.5, 2.0)],
)
@pytest.mark.parametrize("seed", [3, 4])
def test_a_blurred_dot_beside_a_neighbour_is_never_ok_far_off(radius, blur, gap, seed):
    """A dot beside another `gap` px away, both blurred `blur` px: the neighbour's
    pixels are left out of the fit, its blurred edge beyond them reaches in, and is
    taken off the dot's pixels from the neighbour's own fit. ``ok`` within the bound
    (found: 0.003-0.2 px; 0.5-0.65 px at a 2 px gap, radius 6 px, blur 3.5 px, before
    the neighbours' edges were taken off), or not ``ok``."""
    neighbour = (CENTRE[0] + 2 * radius + gap, CENTRE[1])
    img = _render((120, 140 + int(2 * radius + gap)), [(CENTRE, radius), (neighbour, radius)], blur=blur, seed=seed)
    row, err = _nearest(find_markers(img), CENTRE)
    assert row["status"] != "ok" or err < BOUND_PX


@pytest.mark.parametrize("radius", [6.0, 8.0])
@pytest.mark.parametrize("seed", [3, 4, 5])
def test_a_blurred_pair_fitted_one_by_one_is_never_ok_far_off(radius, seed):
    """Two dots 2 px apart, blurred 3.5 px, handed over as the only two candidates
    (fitted one by one, the first with the starting edge width, whose mask leaves
    the other's blurred edge in its ring): the first came out 0.32-0.58 px off,
    ``ok``. With the neighbour's fitted edge taken off its pixels, both are ``ok``
    within the bound (found: up to 0.07 px), or not ``ok``."""
    centres = [CENTRE, (CENTRE[0] + 2 * radius + 2.0, CENTRE[1])]
    img = _render((120, 140 + int(2 * radius + 2.0)), [(c, radius) for c in centres], blur=3.5, seed=seed)
    settings = MeasureSettings()
    dots = [b for b in find_candidates(img, settings) if b.radius < 1.5 * radius]  # not the two merged
    assert len(dots) == 2
    for m in find_marker_list(img, settings, candidates=dots):
        err = min(np.hypot(m.x_px - x, m.y_px - y) for x, y in centres)
        assert m.status != "ok" or err < BOUND_PX


def _region_scene(radius, blur, gap, seed):
    """A dot at CENTRE and a dark rectangle (rows 20-100) from `gap` px beyond its edge
    to the image's right border, both blurred by `blur` px."""
    edge = CENTRE[0] + radius + gap
    return _render((120, 160), [(CENTRE, radius)], blur=blur, seed=seed,
                   region=lambda xs, ys: (xs > edge) & (ys > 20) & (ys < 100))


@pytest.mark.parametrize("gap", [2.0, 3.0, 4.0, 6.0])
@pytest.mark.parametrize("seed", [3, 4])
def test_a_dot_2_px_from_a_dark_region_blurred_3_5_px_is_not_ok_far_off(gap, seed):
    """The case the issue names, the worst of the rendered sweep: a 6 px dot `gap` px
    from a dark region, both blurred 3.5 px; the region's blurred edge merges with the
    dot's, and the fit's outline follows it on that side (at a 2 px gap an ellipse of
    axis ratio 0.69, 3.0 px off, was ``ok``; 0.58-0.62 px off at 4 px). ``ok`` within
    the bound, or not ``ok`` (found: ``near_edge`` 0.58-3.0 px off at gaps of 2-4 px,
    or ``fit_failed``; ``ok`` 0.29-0.30 px off at 6 px)."""
    row, err = _nearest(find_markers(_region_scene(6.0, 3.5, gap, seed)), CENTRE)
    assert row["status"] != "ok" or err < BOUND_PX


def test_an_ellipse_whose_major_axis_ends_at_a_dark_region_says_so():
    """The dot 2 px from the dark region, fitted as an ellipse whose major axis points
    at the region (left out of the fit, a candidate of its own): ``near_edge`` with
    the merged region's message, which gives the ellipse's axis ratio."""
    row, err = _nearest(find_markers(_region_scene(6.0, 3.5, 2.0, 3)), CENTRE)
    assert row["status"] == "near_edge"
    assert row["message"].startswith(MERGED_END_MESSAGE.split("{")[0] + "0.69")


def _occluder_scene(darkness, over, blur, seed):
    """A 10 px dot at (100.3, 100.6) and one at (60.2, 175.4), blurred 1 px; a region
    `darkness` DN below the 200 DN background (a clip, blurred `blur` px) from `over`
    px inside the first dot's right edge rightwards, rows 40-150."""
    img = _render((200, 300), [((100.3, 100.6), 10.0), ((60.2, 175.4), 10.0)], blur=1.0, seed=seed)
    yy, xx = np.mgrid[0:200, 0:300]
    region = cv2.GaussianBlur(((xx >= 110.3 - over) & (yy < 150) & (yy > 40)).astype(float), (0, 0), blur)
    return np.clip(img * (1 - region) + (200.0 - darkness) * region, 0, 255).astype(np.uint8)


def _assert_hidden_arc_flagged(img):
    """In an occluder scene: the first dot's fit is over the bound off and
    ``occluded`` with the hidden-arc message; the other dot is ``ok``."""
    table = find_markers(img)
    row, err = _nearest(table, (100.3, 100.6))
    assert err > BOUND_PX  # the fit is that far off: the flag is what keeps it from ok
    assert row["status"] == "occluded"
    assert row["message"].startswith(HIDDEN_ARC_MESSAGE.split("{")[0])
    assert _nearest(table, (60.2, 175.4))[0]["status"] == "ok"


def _assert_occluded_dot_not_ok_far_off(img):
    """In an occluder scene: the first dot ``ok`` within the bound or not ``ok``;
    the other ``ok`` within 0.05 px (its σ is ~0.01 px)."""
    table = find_markers(img)
    row, err = _nearest(table, (100.3, 100.6))
    assert row["status"] != "ok" or err < BOUND_PX
    other, far = _nearest(table, (60.2, 175.4))
    assert other["status"] == "ok" and far < 0.05


def test_a_slightly_darker_occluder_over_a_dot_edge_is_not_ok_far_off():
    """A region at 185 DN (background 200 DN, blurred 1.5 px) over 2 px of a 10 px
    dot's edge hides a chord and moves the centre 0.51 px; its third harmonic
    (0.27 px) stays under :func:`~vision_torsion.markers.edge_asymmetry_px`'s limit,
    but without the ring's pixels around that arc the ring's residual RMS falls
    from 7.1 to 2.1 DN and the centre moves by 0.48 px, to 0.04 px from the truth:
    ``occluded`` with that message; the other dot stays ``ok``."""
    _assert_hidden_arc_flagged(_occluder_scene(15.0, 2.0, 1.5, 3))


@pytest.mark.parametrize("darkness", [5.0, 15.0, 30.0, 60.0])
@pytest.mark.parametrize("over", [1.0, 2.0, 3.0, 4.0])
@pytest.mark.parametrize("blur", [0.75, 1.5, 3.0])
def test_an_occluder_over_a_dot_edge_is_never_ok_far_off(darkness, over, blur):
    """Occluders 5-60 DN darker than the background over 1-4 px of a 10 px dot's edge,
    blurred 0.75-3 px (two seeds each): the dot is ``ok`` within the bound or not
    ``ok`` (before the hidden-arc check, 23 of these 96 cases came out ``ok``
    0.51-1.08 px off: blurred or slightly darker occluders leave the third harmonic
    under its limit), and the dot beside it stays ``ok`` within 0.05 px (found:
    0.013)."""
    for seed in (3, 4):
        _assert_occluded_dot_not_ok_far_off(_occluder_scene(darkness, over, blur, seed))


def test_an_occluder_over_a_third_of_a_dot_edge_is_occluded():
    """An occluder 20 DN darker than the background over 5 px of a 10 px dot's edge (a
    third of it), blurred 3 px, seed 4: the fit is 1.37 px off, and the arc whose
    leaving out best explains the edge points' scatter was the one opposite the
    hidden chord (the outline of all of them moves away from the chord, which leaves
    the far side outside it): ``ok``. The best arc on the other side of the outline
    is tried as well: ``occluded``, with the refit's message, and the other dot stays
    ``ok``."""
    _assert_hidden_arc_flagged(_occluder_scene(20.0, 5.0, 3.0, 4))


@pytest.mark.parametrize("darkness", [15.0, 20.0, 30.0])
@pytest.mark.parametrize("over", [4.0, 5.0, 6.0])
@pytest.mark.parametrize("blur", [2.0, 3.0, 3.5])
def test_an_occluder_over_a_third_of_a_dot_edge_is_never_ok_far_off(darkness, over, blur):
    """Around that case: occluders 15-30 DN darker than the background over 4-6 px of
    a 10 px dot's edge, blurred 2-3.5 px (three seeds each): ``ok`` within the bound
    or not ``ok`` (before the arc on the other side was tried, 11 of these 81 came
    out ``ok`` 1.3-1.8 px off, 3 of them seen obliquely), and the dot beside it
    stays ``ok`` within 0.05 px (found: 0.013)."""
    for seed in (3, 4, 5):
        _assert_occluded_dot_not_ok_far_off(_occluder_scene(darkness, over, blur, seed))


@pytest.mark.parametrize("darkness", [45.0, 60.0])
@pytest.mark.parametrize("over", [1.0, 2.0, 3.0])
@pytest.mark.parametrize("blur", [3.0, 3.5])
def test_a_dark_blurred_occluder_over_a_little_of_a_dot_edge_is_never_ok_far_off(darkness, over, blur):
    """Occluders 45-60 DN darker than the background over 1-3 px of a 10 px dot's
    edge, blurred 3-3.5 px (three seeds each): the edge points scatter about their
    ellipse by as little as 0.087 px, under the 0.1 px from which the hidden arc
    was looked for, and 4 of these 36 came out ``ok`` 0.51-0.54 px off (over 2 px,
    blur 3.5 px); looked for from 0.07 px, ``ok`` within the bound (found: up to
    0.11 px) or not ``ok``, and the dot beside it stays ``ok`` within 0.05 px."""
    for seed in (3, 4, 5):
        _assert_occluded_dot_not_ok_far_off(_occluder_scene(darkness, over, blur, seed))


def _jpeg_grid(seed):
    """A 5 x 4 grid of dots of radius 7 px 45 px apart, blurred 3 px, JPEG at quality
    30 (blocky, irregular edges, as a compressed photo's), and their centres."""
    centres = np.array([(40.3 + 45 * i, 40.6 + 40 * j) for j in range(4) for i in range(5)])
    img = _render((200, 260), [(c, 7.0) for c in centres], blur=3.0, seed=seed)
    ok, data = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 30])
    assert ok
    return cv2.imdecode(data, cv2.IMREAD_GRAYSCALE), centres


@pytest.mark.parametrize("offset", [0.0, 2.0, 4.0])
def test_a_speck_candidate_over_a_dot_edge_takes_none_of_its_pixels(offset):
    """A speck of noise beside a blurred JPEG dot is a candidate too small to be a
    marker (``too_small``); its pixels were left out of the dot's fit, which took part
    of the dot's own edge, and the rest of an irregular edge moved the centre (by up to
    0.31 px here; GoPro fisheye photo: 0.6-1.3 px, ``ok``). Now such a candidate takes
    no pixels: every dot's centre is the one found without it, to 0.01 px (found: up
    to 0.007 px; the refit is the single fit, and the start width may differ)."""
    img, centres = _jpeg_grid(3)
    settings = MeasureSettings()
    blobs = find_candidates(img, settings)
    angle = np.random.default_rng(7).uniform(0.0, 2.0 * np.pi, len(centres))
    specks = [Blob(x=x + (7.0 + offset) * np.cos(a), y=y + (7.0 + offset) * np.sin(a), radius=1.5,
                   elongation=1.0, fill=1.0, touches_border=False) for (x, y), a in zip(centres, angle)]
    clean = find_marker_list(img, settings, candidates=blobs)
    beside = find_marker_list(img, settings, candidates=blobs + specks)
    assert {m.status for m in beside[len(blobs):]} == {"too_small"}
    for m, n in zip(clean, beside):
        assert m.ok and n.ok
        assert np.hypot(m.x_px - n.x_px, m.y_px - n.y_px) < 0.01


def _clip_and_speck(over, level):
    """Three 10 px dots, a clip at `level` DN (blurred 1.5 px) over `over` px of the
    first one's edge (rows 40-150, to x = 160), and the markers found with a speck
    candidate (radius 1.5 px) on the clip beside that edge: (the first dot's
    marker, all the markers)."""
    dots = [((100.3, 100.6), 10.0), ((60.2, 175.4), 10.0), ((220.7, 60.2), 10.0)]
    img = _render((200, 300), dots, blur=1.0, seed=3)
    yy, xx = np.mgrid[0:200, 0:300]
    clip = cv2.GaussianBlur(((xx >= 110.3 - over) & (xx < 160) & (yy > 40) & (yy < 150)).astype(float), (0, 0), 1.5)
    img = np.clip(img * (1 - clip) + level * clip, 0, 255).astype(np.uint8)
    settings = MeasureSettings()
    speck = Blob(x=112.0, y=100.6, radius=1.5, elongation=1.0, fill=1.0, touches_border=False)
    markers = find_marker_list(img, settings, candidates=find_candidates(img, settings) + [speck])
    return min(markers, key=lambda m: np.hypot(m.x_px - 100.3, m.y_px - 100.6)), markers


@pytest.mark.parametrize("over, reason", [(3.0, "the edge is not symmetric about the centre"),
                                          (4.0, "edge is not circular")])
def test_an_occluder_a_speck_candidate_hid_is_seen(over, reason):
    """A clip a little brighter than the background (215 DN on 200) over `over` px of
    a 10 px dot's edge, and a speck candidate (``too_small``) on it: the speck's mask
    took the clip's pixels from the fit, which came out ``ok``. Fitted without that
    mask, the dot is ``occluded`` (3 px) or ``not_round`` (4 px), so it is
    ``near_edge`` with that reason."""
    dot, markers = _clip_and_speck(over, 215.0)
    assert dot.status == "near_edge"
    assert dot.message.startswith(UNMASKED_MESSAGE.split("{")[0] + reason)
    assert sorted(m.status for m in markers) == ["near_edge", "ok", "ok", "too_small"]


@pytest.mark.parametrize("over", [3.0, 4.0])
def test_a_clip_at_the_background_level_a_speck_hid_is_occluded(over):
    """The same with the clip at the background's level (200 DN): the fit with the
    speck's mask came out ``ok`` 0.4-0.7 px off. The edge it sees is a chord short of
    the rest's outline: without the ring's pixels around it the centre moves by 0.39
    (3 px) or 0.68 px (4 px), so the dot is ``occluded`` on that fit, with that
    message, and the two other dots stay ``ok``."""
    dot, markers = _clip_and_speck(over, 200.0)
    assert dot.status == "occluded"
    assert dot.message.startswith(HIDDEN_ARC_MESSAGE.split("{")[0])
    assert sorted(m.status for m in markers) == ["occluded", "ok", "ok", "too_small"]


@pytest.mark.parametrize("radius, blur, gap", [(6.0, 1.0, 6.0), (6.0, 2.0, 6.0), (6.0, 3.5, 8.0),
                                               (10.0, 3.5, 6.0), (10.0, 1.0, 3.0)])
def test_clean_grids_lose_no_dot(radius, blur, gap):
    """Grids of alike dots `gap` px apart, blurred 1-3.5 px, nothing else in the
    image: every dot ``ok`` (none ``near_edge``), within the bound (found: up to
    0.09 px; 0.34 px on the grid's outer dots of radius 10 px 6 px apart blurred
    3.5 px, whose neighbours' blurred edges reach in from one side only)."""
    pitch = 2 * radius + gap
    centres = np.array([(30.3 + pitch * i, 30.6 + pitch * j) for j in range(5) for i in range(6)])
    shape = (int(60 + 4 * pitch), int(60 + 5 * pitch))
    table = find_markers(_render(shape, [(c, radius) for c in centres], blur=blur, seed=3))
    assert (table["status"] == "ok").all()
    ok = table[table["status"] == "ok"]
    d = np.hypot(ok["x_px"].to_numpy()[:, None] - centres[:, 0], ok["y_px"].to_numpy()[:, None] - centres[:, 1])
    assert d.min(axis=0).max() < BOUND_PX


def _shade_scene(distance):
    """The standard scene with markers of radius 8 px, in a 1/3 shade whose straight
    edge, 10 px wide at 20°, runs `distance` px from the first marker's centre (into
    the shade: the centre in it); the image and that centre (px)."""
    scene = Scene().replace(markers={"radius_px": 8.0})
    x, y = render(scene, 0.0, seed=0).centres[0]
    normal = np.array([np.cos(np.radians(20.0)), -np.sin(np.radians(20.0))])  # into the shade, y down
    offset = float((np.array([x, y]) - (np.array([scene.image.width, scene.image.height]) / 2 - 0.5)) @ normal)
    lighting = {"shadow": 1 / 3, "shadow_angle_deg": 20.0, "shadow_edge_px": 10.0,
                "shadow_offset_px": offset - distance}
    return render(scene.replace(lighting=lighting), 0.0, seed=1).image, (x, y)


@pytest.mark.parametrize(("distance", "status", "message"), [(10.0, "near_edge", UNLIKE_NEIGHBOURS_MESSAGE),
                                                             (15.0, "occluded", HIDDEN_ARC_MESSAGE)])
def test_a_marker_a_shadow_edge_widens_into_an_ellipse_is_not_ok_far_off(distance, status, message):
    """An 8 px marker in a 1/3 shade 10-15 px from the shadow's 10 px wide edge (as in
    ``benchmarks/bench_light_edge.py``): its fit took the edge of the light for a
    wide, stretched edge of its own (an ellipse of axis ratio 0.6-0.7, edge width
    3.4-5.1 px, beside the other marker's round 1.1 px) and came out ``ok`` 0.26 and
    0.74 px off. Now ``near_edge``, its ``ok`` neighbour being rounder and sharper, and
    the message says so (10 px); or, 15 px from it, ``occluded`` first: without the
    ring's pixels on the shadow's side the centre moves by the 0.74 px it is off
    (:data:`~vision_torsion.markers.HIDDEN_ARC_MESSAGE`). The other marker stays
    ``ok`` within 0.05 px (its σ is ~0.01 px)."""
    img, (x, y) = _shade_scene(distance)
    table = find_markers(img, polarity="dark")
    row, err = _nearest(table, (x, y))
    assert row["status"] == status
    assert row["message"].startswith(message.split("{")[0])
    other = table[table["status"] == "ok"]
    assert len(other) == 1
    assert _nearest(other, tuple(render(Scene().replace(markers={"radius_px": 8.0}), 0.0, seed=0).centres[1]))[1] < 0.05


@pytest.mark.parametrize("blur", [1.0, 2.5])
def test_a_disc_seen_obliquely_among_round_markers_of_the_same_blur_stays_ok(blur):
    """A disc seen obliquely (axis ratio 0.65, r 9 px) beside two round markers, all
    blurred alike: less round than its neighbours by far more than 0.1, but as sharp
    as they are, so a disc seen through the same optics; all three ``ok`` within
    0.05 px (the centres' σ is ~0.01 px)."""
    centres = [(50.3, 60.6), (130.7, 58.2), (210.4, 61.9)]
    xs, ys = supersampled_grid(120, 260)
    dark = ellipse_mask(xs, ys, centres[0], 9.0) | ellipse_mask(xs, ys, centres[2], 9.0)
    dark |= ellipse_mask(xs, ys, centres[1], 9.0, 0.65, 35.0)
    img = cv2.GaussianBlur(area_image(dark), (0, 0), blur) + np.random.default_rng(5).normal(0.0, 2.0, (120, 260))
    table = find_markers(np.clip(img, 0, 255).astype(np.uint8))
    assert list(table["status"]) == ["ok"] * 3
    assert table["message"].str.startswith("seen obliquely").sum() == 1
    for c in centres:
        assert _nearest(table, c)[1] < 0.05
