"""A shadow's or a light's edge across a marker: the fit's lighting is a plane, which
follows a step only in part, and the misfit pulls the centre (rendered: up to 1.2 px
off with status ``ok`` before the check). Such a marker is ``near_edge``; markers
under lighting the plane follows stay ``ok``."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from vision_torsion.markers import (
    STEEP_CUT_MESSAGE,
    STEEP_CUT_PX,
    STEEP_EDGE_MESSAGE,
    UNEVEN_LIGHT_MESSAGE,
    UNEVEN_SHIFT_PX,
    UNEVEN_SHIFT_SIGMAS,
    find_markers,
)
from vision_torsion.pixelfit import UNEVEN_BACKGROUND, fit_disc
from vision_torsion.synthetic import Scene, render
from vision_torsion.synthetic.target_scenes import target_scene
from vision_torsion.targets import grid_target

#: The part of the message before its first figure.
UNEVEN_PREFIX = UNEVEN_LIGHT_MESSAGE.split("{")[0]


def grid_scene(lighting: dict, *, blur_px: float | None = None) -> Scene:
    """An 11x15 grid of dark dots of radius 8 px, 90 px apart, under `lighting`."""
    target = grid_target(11, 15, pitch_mm=10.0, dot_diameter_mm=16.0 / 9.0, name="grid11x15")
    changes = {"markers": {"polarity": "dark", "level": 30.0}, "disk": {"background_level": 150.0},
               "lighting": lighting}
    if blur_px is not None:
        changes["optics"] = {"blur_sigma_px": blur_px}
    return target_scene(target, px_per_mm=9.0, base=Scene().replace(**changes))


@pytest.mark.parametrize(("edge_px", "offset_px", "seed"), [(0.0, 23.0, 7), (3.0, 47.0, 8), (8.0, 0.0, 9),
                                                             (30.0, 23.0, 10)])
def test_a_shadow_edge_across_a_marker_is_not_ok_when_off(edge_px, offset_px, seed):
    """A shadow (a third of the light) whose edge, `edge_px` wide, crosses the grid
    at 20°: every ``ok`` dot within 0.5 px of its true centre (the must-reach of
    the photographs), and the dots the edge crosses are ``near_edge`` with the
    message (before the check: 0.9-1.2 px off, ``ok``, for edges up to 8 px wide)."""
    lighting = {"shadow": 1 / 3, "shadow_edge_px": edge_px, "shadow_angle_deg": 20.0,
                "shadow_offset_px": offset_px}
    rendered = render(grid_scene(lighting), 0.0, seed=seed)
    table = find_markers(rendered.image, polarity="dark")
    ok = table[table["status"] == "ok"]
    assert cKDTree(rendered.centres).query(ok[["x_px", "y_px"]].to_numpy())[0].max() < 0.5
    uneven = table[table["message"].str.startswith(UNEVEN_PREFIX)]
    assert len(uneven) >= 1
    assert (uneven["status"] == "near_edge").all()
    # the dots under the shadow's edge, not elsewhere: within 60 px of its line
    normal = np.array([np.cos(np.radians(20.0)), -np.sin(np.radians(20.0))])  # y down
    centre = np.array([rendered.image.shape[1] / 2 - 0.5, rendered.image.shape[0] / 2 - 0.5])
    across = (uneven[["x_px", "y_px"]].to_numpy() - centre) @ normal - offset_px
    assert np.abs(across).max() < 60.0
    # at most the two columns of dots along the edge
    assert len(uneven) <= 2 * 11 + 4


@pytest.mark.parametrize(("lighting", "blur_px"), [({}, None), ({}, 3.0), ({"gradient_x": 1.2}, None),
                                                   ({"shadow": 0.85, "shadow_edge_px": 30.0}, None)],
                         ids=["even", "blurred", "falloff 4:1", "soft faint shadow"])
def test_markers_under_lighting_the_fit_follows_stay_ok(lighting, blur_px):
    """Even light, a 3 px blur, a 4:1 falloff across the frame, a faint shadow
    with a 30 px penumbra: every dot ``ok`` (the move under a curved lighting
    stays under 0.003 px there, the limit is 0.1 px)."""
    rendered = render(grid_scene(lighting, blur_px=blur_px), 0.0, seed=4)
    table = find_markers(rendered.image, polarity="dark")
    assert len(table) == len(rendered.centres)
    assert (table["status"] == "ok").all()


def test_fit_reports_the_background_step_and_the_lighting_shift():
    """The fit's figures: on a marker under even light the background's sector
    medians agree to a few % of the contrast and the shift is not computed
    (NaN); with a hard shadow edge across the marker (30 px from the centre of a
    35 px marker, half the light beyond it) they differ by over a third of it
    and the centre moves by more than the limit (found: 0.57 px, the centre 0.13 px
    off), by over three times that move's own noise."""
    scene = Scene()
    clean = render(scene, 0.0, seed=3)
    x, y = clean.centres[0]
    f = fit_disc(clean.image, x + 0.3, y - 0.2, 34.0)
    contrast = abs(f.foreground_dn - f.background_dn)
    assert f.background_step_dn < UNEVEN_BACKGROUND * contrast
    assert np.isnan(f.lighting_shift_px) and np.isnan(f.lighting_shift_std_px)
    # the shadow's edge across the first marker, its normal at 30° to the x axis
    normal = np.array([np.cos(np.radians(30.0)), -np.sin(np.radians(30.0))])
    offset = float((np.array([x, y]) - (np.array(clean.image.shape[::-1]) / 2 - 0.5)) @ normal) + 30.0
    shaded = render(scene.replace(lighting={"shadow": 0.5, "shadow_angle_deg": 30.0, "shadow_offset_px": offset}),
                    0.0, seed=3)
    g = fit_disc(shaded.image, x + 0.3, y - 0.2, 34.0)
    assert g.background_step_dn > 0.3 * abs(g.foreground_dn - g.background_dn)
    assert g.lighting_shift_px > UNEVEN_SHIFT_PX
    # the move's own noise: a few hundredths of a px on a 35 px marker (found 0.029)
    assert 0.0 < g.lighting_shift_std_px < g.lighting_shift_px / UNEVEN_SHIFT_SIGMAS


def edge_across(radius: float, distance: float, width: float, shade: float, seed: int):
    """The standard scene with markers of `radius` px under a shadow (the light falls to
    `shade`) whose edge, `width` px wide at 20°, runs `distance` px from the first
    marker's centre (beyond it: the centre in the light), rendered with `seed`; the
    image and that centre."""
    scene = Scene().replace(markers={"radius_px": radius})
    x, y = render(scene, 0.0, seed=0).centres[0]
    normal = np.array([np.cos(np.radians(20.0)), -np.sin(np.radians(20.0))])  # into the shade, y down
    offset = float((np.array([x, y]) - (np.array([scene.image.width, scene.image.height]) / 2 - 0.5)) @ normal)
    scene = scene.replace(lighting={"shadow": shade, "shadow_angle_deg": 20.0, "shadow_edge_px": width,
                                    "shadow_offset_px": offset + distance})
    return render(scene, 0.0, seed=seed).image, (x, y)


def _nearest(table, centre):
    err = np.hypot(table["x_px"] - centre[0], table["y_px"] - centre[1])
    return table.loc[err.idxmin()], float(err.min())


@pytest.mark.parametrize(("radius", "distance", "width", "shade"), [(15.0, 0.0, 10.0, 0.7), (35.0, 0.0, 30.0, 1 / 3),
                                                                   (15.0, 5.0, 0.0, 1 / 3), (25.0, 5.0, 30.0, 1 / 3)])
def test_an_edge_through_or_by_the_centre_is_flagged(radius, distance, width, shade):
    """A shadow's edge through the marker's centre or 5 px beside it moves the
    centre 0.19-0.34 px (found); the quadratic lighting terms, even about the centre,
    moved it under 0.06 px and the marker was ``ok``. The step's first harmonic grows
    with the radius unlike the gradient's, which the (ρ - 1) terms follow:
    ``near_edge`` with the message."""
    image, centre = edge_across(radius, distance, width, shade, 1)
    row, err = _nearest(find_markers(image, polarity="dark"), centre)
    assert err > 0.15
    assert row["status"] == "near_edge"
    assert row["message"].startswith(UNEVEN_PREFIX)


@pytest.mark.parametrize("distance", [10.0, 15.0])
def test_a_soft_edge_beside_the_centre_of_an_accurate_marker_is_not_flagged(distance):
    """A soft shadow edge (30 px wide, a third of the light) `distance` px beyond
    the centre of a 15 px marker leaves it within 0.12 px (found 0.046 and 0.108 px)
    and ``ok``; the quadratic terms' moves, 0.105 and 0.110 px, made both
    ``near_edge``."""
    image, centre = edge_across(15.0, distance, 30.0, 1 / 3, 1)
    row, err = _nearest(find_markers(image, polarity="dark"), centre)
    assert row["status"] == "ok"
    assert err < 0.12


@pytest.mark.parametrize(("radius", "distance", "width", "reason"),
                         [(35.0, 0.0, 10.0, "bent"), (35.0, 25.0, 3.0, "uneven"), (35.0, 25.0, 10.0, "uneven")])
def test_a_steep_cut_marker_off_by_more_than_its_message_admits_is_flagged(radius, distance, width, reason):
    """A shadow (a third of the light) whose edge crosses a 35 px marker through its
    centre or 25 px beside it: the shade is cut from the ring as a surround as dark
    as the marker (``steep_cut``) and the centre comes out 1.0-1.5 px off (this
    seed; under others the fit beside it may keep the shaded edge and be within
    0.01 px), which was ``ok`` with the caveat "up to 0.3 px". Now ``near_edge``: the edge left
    bent beyond its noise (through the centre), or, with the shaded part of the
    edge unseen, the lighting shift beyond :data:`STEEP_CUT_PX` (beside it)."""
    image, centre = edge_across(radius, distance, width, 1 / 3, 1)
    row, err = _nearest(find_markers(image, polarity="dark"), centre)
    assert err > 0.5
    assert row["status"] == "near_edge"
    if reason == "bent":
        assert row["message"].startswith(STEEP_EDGE_MESSAGE.split("{")[0])
    else:
        assert row["message"].startswith(UNEVEN_PREFIX)
        assert f"(allowed {STEEP_CUT_PX} px)" in row["message"]


@pytest.mark.parametrize(("radius", "distance", "width"), [(15.0, 10.0, 0.0), (25.0, 10.0, 10.0)])
def test_an_accurate_steep_cut_marker_with_its_edge_seen_all_round_stays_ok(radius, distance, width):
    """A shadow's edge (a third of the light) 10 px beyond the centre of a 15 or
    25 px marker: the shade is cut from the ring (``steep_cut``), the lighting
    shift is 0.95-1.25 px, yet the edge, seen all round, holds the centre to
    0.1 px (found 0.006 and 0.094): ``ok``, with the steep cut's caveat."""
    image, centre = edge_across(radius, distance, width, 1 / 3, 1)
    row, err = _nearest(find_markers(image, polarity="dark"), centre)
    assert err < 0.1
    assert row["status"] == "ok" and bool(row["steep_cut"])
    assert row["message"] == STEEP_CUT_MESSAGE
