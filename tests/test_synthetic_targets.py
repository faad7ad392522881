"""Rendered N-marker targets: the dots where the layout puts them, and their angle bound."""

import dataclasses

import numpy as np
import pytest

from vision_torsion.errors import SceneError
from vision_torsion.markers import find_markers
from vision_torsion.rigid import identify_markers
from vision_torsion.synthetic import Scene, render, target_scene, validate_scene
from vision_torsion.synthetic.bounds import angle_bound_deg, target_angle_bound_deg
from vision_torsion.synthetic.geometry import marker_centres_image
from vision_torsion.targets import load_target


@pytest.mark.parametrize("name, ppm, angle", [("grid5", 15.0, 33.3), ("ring8", 7.0, -141.0)])
def test_dots_are_rendered_where_the_layout_puts_them(name, ppm, angle):
    # 0.05 px: the centres' σ here is ~0.003 px; 0.05 px would be a layout error, not noise
    scene = target_scene(name, px_per_mm=ppm)
    table = find_markers(render(scene, angle, seed=3).image)
    ident = identify_markers(table, load_target(name))
    assert ident.status == "ok" and ident.scale_px_per_mm == pytest.approx(ppm, rel=1e-4)
    found = table.loc[list(ident.rows), ["x_px", "y_px"]].to_numpy()
    np.testing.assert_allclose(found, marker_centres_image(scene, angle), atol=0.05)
    assert (ident.axis_x_px, ident.axis_y_px) == pytest.approx((scene.disk.center_x, scene.disk.center_y), abs=0.02)


def test_two_marker_bound_is_the_pair_bound():
    s = Scene()
    assert target_angle_bound_deg(s, 25.0) == pytest.approx(angle_bound_deg(s, 25.0), rel=1e-6)


def test_ring_bound_gains_as_the_root_of_the_dots_perimeter():
    # same ring radius and exposure: the bound scales as 1/sqrt(sum of radii) within 5 %
    two = angle_bound_deg(Scene(), 0.0)
    ring = target_angle_bound_deg(target_scene("ring16", px_per_mm=7.5), 0.0)
    radii = target_scene("ring16", px_per_mm=7.5).markers.radii()
    assert two / ring == pytest.approx(np.sqrt(sum(radii) / 70.0), rel=0.05)
    assert two / ring > 2.5


def test_target_too_large_for_the_frame():
    with pytest.raises(SceneError, match=r"target ring16: \[markers\] marker 1 at rotation 0° lies outside the "
                                         r"1400x1000 frame"):
        target_scene("ring16", px_per_mm=20.0)


def test_distances_are_validated():
    mk = dataclasses.replace(Scene().markers, distances_px=(300.0,))
    with pytest.raises(SceneError, match=r"\[markers\] distances_px has 1 value\(s\) for 2 positions_deg"):
        validate_scene(Scene().replace(markers=mk))
    mk = dataclasses.replace(Scene().markers, distances_px=(300.0, -1.0))
    with pytest.raises(SceneError, match=r"\[markers\] distances_px must not be negative, got \[300.0, -1.0\]"):
        validate_scene(Scene().replace(markers=mk))
