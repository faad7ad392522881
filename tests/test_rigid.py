"""The angle from all markers of an N-marker target: identity from the layout, the weighted
rigid fit, the axis shift (a camera bump), and the per-image statuses of bad input.

Truth: rendered ring16 scenes (16 dots of r 36 px on a 300 px radius about a centre off
the pixel grid, index dot r 45 px, read noise 2 DN), whose angle CRLB is 1.5e-4°.
"""

import dataclasses
import math

import numpy as np
import pytest

from vision_torsion.errors import TargetError
from vision_torsion.markers import find_markers
from vision_torsion.rigid import (
    TargetAngle,
    axis_motion,
    fit_rigid,
    identify_markers,
    rotation_centre,
    target_angle,
    target_angles,
)
from vision_torsion.synthetic import Scene, render, target_scene
from vision_torsion.synthetic.bounds import target_angle_bound_deg
from vision_torsion.synthetic.geometry import marker_centres_image
from vision_torsion.targets import dots_target, load_target, ring_target

BASE = Scene().replace(disk=dataclasses.replace(Scene().disk, center_x=700.37, center_y=500.61))
RING = load_target("ring16")
SCENE = target_scene(RING, px_per_mm=7.5, base=BASE)


def table(scene, angle, seed):
    return find_markers(render(scene, angle, seed=seed).image)


@pytest.fixture(scope="module")
def ref():
    return table(SCENE, 0.0, 1)


@pytest.fixture(scope="module")
def turned():
    return {a: table(SCENE, a, 10 + i) for i, a in enumerate((90.0, 180.0, -107.3))}


def rotate(p, deg):
    a = math.radians(deg)
    return p @ np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


# -- the rigid fit on its own ----------------------------------------------------------

@pytest.mark.parametrize("deg", [0.0, 37.5, 90.0, 180.0, -135.0, 270.0 - 360.0])
def test_fit_rigid_recovers_turn_and_shift(deg):
    p = np.array([[500.3, 200.1], [800.7, 500.2], [500.9, 810.4], [190.2, 499.8], [650.0, 260.0]])
    o = np.array([500.0, 500.0])
    q = o + rotate(p - o, deg) + [0.7, -1.3]
    cov = np.tile(np.eye(2) * 1e-4, (5, 1, 1))
    f = fit_rigid(p, cov, q, cov, origin=o)
    assert f.angle_deg == pytest.approx(deg, abs=1e-9)
    assert (f.shift_x_px, f.shift_y_px) == pytest.approx((0.7, -1.3), abs=1e-9)
    assert all(r.used for r in f.residuals) and f.dof == 7


def test_fit_rigid_std_is_honest():
    # 2000 noisy draws: reported σ of the angle and of the shift match their scatter within 6 %
    # (the scatter of 2000 draws is good to 1.6 %; 6 % is about 4 of its σ)
    rng = np.random.default_rng(7)
    phi = np.radians(np.arange(8) * 45.0)
    p = np.column_stack([600 + 300 * np.cos(phi), 500 - 300 * np.sin(phi)])
    sd = np.array([0.02, 0.01, 0.03, 0.02, 0.01, 0.02, 0.015, 0.025])
    cov = np.einsum("n,ij->nij", sd**2, np.eye(2))
    q_true = np.array([600.0, 500.0]) + rotate(p - [600, 500], 12.0)
    angles, stds, shifts = [], [], []
    for _ in range(2000):
        f = fit_rigid(p + rng.normal(size=p.shape) * sd[:, None], cov,
                      q_true + rng.normal(size=p.shape) * sd[:, None], cov, origin=(600.0, 500.0))
        angles.append(f.angle_deg)
        stds.append(f.angle_std_deg)
        shifts.append(f.shift_x_px)
    assert np.mean(angles) == pytest.approx(12.0, abs=4 * np.std(angles) / math.sqrt(2000))
    assert np.mean(stds) / np.std(angles) == pytest.approx(1.0, abs=0.06)
    assert math.sqrt(f.shift_cov[0, 0]) / np.std(shifts) == pytest.approx(1.0, abs=0.06)


def test_fit_rigid_drops_the_marker_that_disagrees_with_its_reason():
    p = np.array([[100.0 * math.cos(a), 100.0 * math.sin(a)] for a in np.radians(np.arange(0, 360, 45))])
    q = rotate(p, 5.0)
    q[3] += [0.3, 0.0]  # dirt on one dot: 30σ off
    cov = np.tile(np.eye(2) * 1e-4, (8, 1, 1))
    f = fit_rigid(p, cov, q, cov, origin=(0.0, 0.0), dots=range(10, 18))
    dropped = [r for r in f.residuals if not r.used]
    assert [r.dot for r in dropped] == [13]
    assert "disagrees with the other 7 markers" in dropped[0].reason and dropped[0].normalised > 20
    assert f.angle_deg == pytest.approx(5.0, abs=1e-9)


def test_fit_rigid_needs_two_markers():
    p = np.array([[0.0, 0.0], [np.nan, 1.0]])
    with pytest.raises(TargetError, match=r"fit_rigid: 1 marker\(s\) measured in both images; a rigid fit needs 2"):
        fit_rigid(p, np.tile(np.eye(2), (2, 1, 1)), p, np.tile(np.eye(2), (2, 1, 1)))


def test_fit_rigid_refuses_mismatched_shapes():
    with pytest.raises(TargetError, match=r"centres must be \(n, 2\) and covariances \(n, 2, 2\)"):
        fit_rigid(np.zeros((3, 2)), np.zeros((3, 2, 2)), np.zeros((2, 2)), np.zeros((2, 2, 2)))


# -- identity and the angle on rendered targets ---------------------------------------------

@pytest.mark.parametrize("angle", [90.0, 180.0, -107.3])
def test_identity_follows_the_index_mark_all_round(turned, angle):
    ident = identify_markers(turned[angle], RING)
    assert ident.status == "ok" and ident.turn_deg % 360 == pytest.approx(angle % 360, abs=0.05)
    found = turned[angle].loc[list(ident.rows), ["x_px", "y_px"]].to_numpy()
    np.testing.assert_allclose(found, marker_centres_image(SCENE, angle), atol=0.05)


@pytest.mark.parametrize("angle", [90.0, 180.0, -107.3])
def test_target_angle_within_the_bound(ref, turned, angle):
    # 6 CRLB (1.5e-4°): a 6σ error has probability 2e-9
    bound = target_angle_bound_deg(SCENE, angle)
    res = target_angle(ref, turned[angle], target=RING)
    err = (res.angle_deg - angle + 180) % 360 - 180
    assert res.status == "ok" and res.n_used == 16 and not res.bump
    assert abs(err) < 6 * bound and res.angle_std_deg == pytest.approx(bound, rel=0.3)


def test_one_pixel_camera_bump_is_a_bump_not_a_rotation(ref):
    moved = SCENE.replace(disk=dataclasses.replace(SCENE.disk, center_x=SCENE.disk.center_x + 1.0))
    res = target_angle(ref, render(moved, 0.0, seed=5).image, target=RING)
    assert res.bump and "not a rotation" in res.message
    assert (res.shift_x_px, res.shift_y_px) == pytest.approx((1.0, 0.0), abs=0.02)  # σ ≈ 0.002 px
    assert abs(res.angle_deg) < 6 * res.angle_std_deg


def test_no_bump_without_one(ref):
    res = target_angle(ref, render(SCENE, 0.0, seed=6).image, target=RING)
    assert not res.bump and math.hypot(res.shift_x_px, res.shift_y_px) < 0.02


def test_symmetric_ring_is_ambiguous_never_a_guess(ref, turned):
    plain = ring_target(16, diameter_mm=80, dot_diameter_mm=9.6)
    ident = identify_markers(turned[90.0], plain)
    assert ident.status == "ambiguous" and "give the target an index mark" in ident.message
    assert ident.rows == (-1,) * 16
    with pytest.raises(TargetError, match=r"reference: the markers fit the target 'ring16' equally well") as err:
        target_angle(ref, turned[90.0], target=plain)
    assert err.value.reason == "ambiguous"


def painted_over(scene, angle, dots, seed):
    """A render with `dots` covered by the disk's grey (an occluder of the face's colour)."""
    img = render(scene, angle, seed=seed).image.astype(np.float64)
    yy, xx = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    for k in dots:
        x, y = marker_centres_image(scene, angle)[k]
        img[np.hypot(xx - x, yy - y) < scene.markers.radii()[k] + 4] = scene.disk.background_level
    return img


def test_a_missing_marker_is_named_and_the_others_give_the_angle(ref):
    res = target_angle(ref, painted_over(SCENE, 30.0, [5], seed=21), target=RING)
    assert res.status == "marker_missing" and "no marker at dot(s) 5 of the target 'ring16'" in res.message
    assert res.n_used == 15 and abs(res.angle_deg - 30.0) < 0.002


def test_markers_on_no_dot_are_ignored(ref):
    # six bolt holes (r 30 px) on a 180 px circle inside the ring, dust specks: not dots of the layout
    holes = SCENE.replace(distractors={"bolt_holes": 6, "bolt_hole_radius_px": 30.0, "bolt_circle_px": 180.0,
                                       "dust": 20})
    cur = table(holes, 33.0, 24)
    assert (cur["status"] == "ok").sum() == 22
    res = target_angle(ref, cur, target=RING)
    assert res.status == "ok" and res.n_used == 16 and abs(res.angle_deg - 33.0) < 0.002


def test_one_marker_is_not_an_identity(ref):
    ident = identify_markers(ref.iloc[:1], RING)
    assert ident.status == "marker_missing" and not ident.certain and ident.missing == tuple(range(16))
    assert "1 marker(s) found, the target 'ring16' has 16; all dots missing" in ident.message
    res = target_angle(ref, ref.iloc[:1], target=RING)
    assert res.status == "marker_missing" and not res.usable and math.isnan(res.angle_deg)
    with pytest.raises(TargetError, match=r"reference: 1 marker\(s\) found") as err:
        target_angle(ref.iloc[:1], ref, target=RING)
    assert err.value.reason == "marker_missing"


def test_hidden_index_mark_is_ambiguous(ref):
    res = target_angle(ref, painted_over(SCENE, 30.0, [0], seed=22), target=RING)
    assert res.status == "ambiguous" and "the index mark (dot 0)" in res.message and math.isnan(res.angle_deg)


def test_layout_that_does_not_match_is_refused(ref):
    ident = identify_markers(ref, load_target("grid5"))
    assert ident.status == "layout_mismatch" and ident.rows == (-1,) * 25
    assert "no two markers have the sizes and spacing of two dots of the target 'grid5'" in ident.message


def test_layout_that_matches_only_a_few_dots_is_refused(ref):
    # three dots of the ring (the index and its two neighbours) and seven that are not on the disk
    x = list(RING.x_mm[:2]) + [RING.x_mm[15]] + [-30.0, -20.0, -10.0, 0.0, 10.0, -30.0, -20.0]
    y = list(RING.y_mm[:2]) + [RING.y_mm[15]] + [0.0, 0.0, 0.0, 0.0, 0.0, 20.0, 20.0]
    d = [12.0, 9.6, 9.6] + [9.6] * 7
    ident = identify_markers(ref, dots_target(x, y, d, name="partial"))
    assert ident.status == "layout_mismatch"
    assert "at most 3 of the 10 dots of the target 'partial' agree with the markers found (need 5)" in ident.message


def test_a_dirty_marker_is_dropped_with_its_reason(ref):
    cur = table(SCENE, 20.0, 23).copy()
    ident = identify_markers(cur, RING)
    row = ident.rows[7]
    cur.loc[row, "x_px"] += 0.4  # ~100σ: a speck on the dot's edge
    res = target_angle(ref, cur, target=RING)
    (dropped,) = [r for r in res.residuals if not r.used]
    assert dropped.dot == 7 and "occluded, dirty or moved" in dropped.reason
    assert "dot 7 dropped" in res.message and res.n_used == 15 and abs(res.angle_deg - 20.0) < 0.002


def test_sequence_unwraps_and_finds_an_eccentric_axis(ref):
    # the description claims the axis 2 mm (15 px) to the left of the ring's centre
    off = dots_target(np.array(RING.x_mm) + 2.0, RING.y_mm, RING.diameter_mm, name="offset")
    imgs = [render(SCENE, a, seed=30 + k).image for k, a in enumerate((120.0, 170.0, -170.0))]
    res = target_angles(ref, imgs, target=off)
    assert [r.angle_deg for r in res] == pytest.approx([120.0, 170.0, 190.0], abs=0.002)
    centre = rotation_centre(res)
    assert (centre.offset_x_px, centre.offset_y_px) == pytest.approx((15.0, 0.0), abs=0.02)
    np.testing.assert_allclose(centre.shifts_px, 0.0, atol=0.02)


def test_rotation_centre_needs_a_turn(ref):
    res = target_angles(ref, [ref], target=RING)
    with pytest.raises(TargetError, match=r"rotation_centre: no usable image turned by 1° or more") as err:
        rotation_centre(res)
    assert err.value.reason == "too_few_turns"


def _axis_sequence(angles_deg, offset_px, jumps, *, sigma_px=0.01, seed=0):
    """TargetAngles of a target `offset_px` off the shaft turning by `angles_deg`, the
    axis moved by `jumps` ({image: (dx, dy)}, each image alone), shift noise `sigma_px`."""
    rng = np.random.default_rng(seed)
    cov = np.eye(2) * sigma_px**2
    out = []
    for k, a in enumerate(angles_deg):
        t = np.radians(a)
        R = np.array([[math.cos(t), math.sin(t)], [-math.sin(t), math.cos(t)]])
        shift = (np.eye(2) - R) @ np.asarray(offset_px) + np.asarray(jumps.get(k, (0.0, 0.0)))
        shift = shift + (rng.normal(0.0, sigma_px, 2) if k else 0.0)
        out.append(TargetAngle(a, 1e-3, shift_x_px=shift[0], shift_y_px=shift[1], shift_cov=cov))
    return out


LOOP = [0.0, 4.7, 4.5, 4.2, 2.0, -0.3, -2.5, -4.7, -4.5, -4.2, -2.0, 0.3, 2.5, 4.7]


def test_axis_motion_tells_an_eccentric_target_from_a_bump():
    # 12 px off the shaft: the centre swings by up to 1 px over the loop, and that is no bump
    m = axis_motion(_axis_sequence(LOOP, (12.0, -5.0), {}))
    assert m.jumps == () and abs(m.offset_x_px - 12.0) < 0.3 and abs(m.offset_y_px + 5.0) < 0.3
    assert np.nanmax(np.abs(m.shifts_px)) < 0.05


@pytest.mark.parametrize("image", [1, 7, 13])  # the largest turns, either way, and the last image
def test_axis_motion_finds_a_one_pixel_spike_anywhere(image):
    m = axis_motion(_axis_sequence(LOOP, (12.0, -5.0), {image: (0.0, 1.0)}))
    assert m.jumps == ((image, "spike"),)
    assert np.allclose(m.jump_px[image], (0.0, 1.0), atol=0.05) and m.jump_sigma[image] > 50
    assert abs(m.shifts_px[image, 1] - 1.0) < 0.05


def test_axis_motion_finds_a_camera_that_moved_for_good():
    moved = {k: (0.7, 0.0) for k in range(6, len(LOOP))}
    m = axis_motion(_axis_sequence(LOOP, (0.0, 0.0), moved))
    assert m.jumps == ((6, "step"),) and np.allclose(m.jump_px[6], (0.7, 0.0), atol=0.05)
    assert np.all(np.abs(m.shifts_px[6:, 0] - 0.7) < 0.05)


def test_axis_motion_ignores_jumps_below_the_floor_or_the_noise():
    assert axis_motion(_axis_sequence(LOOP, (0.0, 0.0), {5: (0.2, 0.0)})).jumps == ()  # 20σ, under 0.25 px
    noisy = _axis_sequence(LOOP, (0.0, 0.0), {5: (0.3, 0.0)}, sigma_px=0.1)  # 3σ, over 0.25 px
    assert axis_motion(noisy).jumps == ()


def test_axis_motion_of_unusable_images_is_blank():
    seq = _axis_sequence(LOOP[:3], (0.0, 0.0), {})
    seq[1] = TargetAngle(math.nan, math.nan, status="ambiguous")
    m = axis_motion(seq)
    assert m.jumps == () and np.isnan(m.shifts_px[1]).all() and not np.isnan(m.shifts_px[2]).any()
