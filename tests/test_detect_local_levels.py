"""Local detection levels: dot grids under strongly uneven light are found in full.

Each scene is a rendered 11x15 dot grid (1400x1000 px, blur σ 1 px, read noise
2 DN, seeded) under one kind of uneven light, chosen so that one detection level
for the whole image (``local_levels=False``) misses dots: a 4:1 light falloff
across the frame, vignetting down to a quarter of the light at the grid's corners,
a shadow over half the frame with a third of the light, a lamp's reflection that
clips the paper. With the defaults every dot must come out ``ok`` within 0.5 px of
its true centre (the issue's limit for an ``ok`` dot against an independent fit;
the fits here are 0.03-0.4 px off, the most on the shadow's edge and in the
clipped reflection), or, on the shadow's edge, ``near_edge`` for the uneven
background there (:data:`~vision_torsion.markers.UNEVEN_LIGHT_MESSAGE`), and no
``ok`` marker may lie anywhere else.
"""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

import vision_torsion
from vision_torsion.detect import detect_blobs
from vision_torsion.errors import MarkerError, SceneError
from vision_torsion.markers import UNEVEN_LIGHT_MESSAGE, find_markers
from vision_torsion.pair import measure_pair
from vision_torsion.report.session_report import demo_scene
from vision_torsion.synthetic import Scene, load_scene, render
from vision_torsion.synthetic.target_scenes import target_scene
from vision_torsion.targets import grid_target

SHADOW = {"shadow": 1 / 3, "shadow_edge_px": 30.0, "shadow_angle_deg": 20.0}
LAMP = {"reflection_dn": 180.0, "reflection_x": 900.0, "reflection_y": 400.0, "reflection_sigma_px": 160.0}

CASES = {
    # light 1.6 at the left edge, 0.4 at the right
    "falloff 4:1, bright dots": ({"gradient_x": 1.2}, 12.0, "bright"),
    # light 1 - 0.95·ρ²: 0.23 at the grid's corner dots
    "vignetting, dark dots": ({"vignetting": 0.95}, 12.0, "dark"),
    "vignetting, bright dots": ({"vignetting": 0.95}, 8.0, "bright"),
    "half-frame shadow, dark dots": (SHADOW, 8.0, "dark"),
    "half-frame shadow, bright dots": (SHADOW, 8.0, "bright"),
    # the paper clips at 255 DN under the reflection: the dots' contrast there falls to
    # 0.37 of the others' (a dot a reflection takes below a third of the others'
    # contrast is not told from a table's texture by the second pass, and is missed)
    "lamp reflection, dark dots": (LAMP, 8.0, "dark"),
}


def grid_scene(lighting: dict, radius_px: float, polarity: str) -> Scene:
    """An 11x15 grid of dots of `radius_px`, 90 px apart, under `lighting`."""
    target = grid_target(11, 15, pitch_mm=10.0, dot_diameter_mm=2 * radius_px / 9.0, name="grid11x15")
    paper, ink = (150.0, 30.0) if polarity == "dark" else (40.0, 160.0)
    base = Scene().replace(markers={"polarity": polarity, "level": ink}, disk={"background_level": paper},
                           lighting=lighting)
    return target_scene(target, px_per_mm=9.0, base=base)


def _found(blobs, centres, within):
    """How many of the true `centres` have a candidate within `within` px."""
    d = cKDTree(np.array([(b.x, b.y) for b in blobs]).reshape(-1, 2)).query(centres)[0]
    return int((d < within).sum())


@pytest.mark.parametrize("case", list(CASES))
def test_uneven_light_grid_found_in_full(case):
    lighting, radius, polarity = CASES[case]
    rendered = render(grid_scene(lighting, radius, polarity), 0.0, seed=3)
    n = len(rendered.centres)
    # one level for the image leaves dots without a candidate on them (the point of
    # the case); the local levels give every dot one
    assert _found(detect_blobs(rendered.image, polarity=polarity, local_levels=False), rendered.centres, radius) < n
    assert _found(detect_blobs(rendered.image, polarity=polarity), rendered.centres, radius) == n
    table = find_markers(rendered.image, polarity=polarity)
    # every dot, and nothing else, accepted; on the shadow's edge a dot may be
    # near_edge for the uneven background there (2 of 165 are)
    uneven = table["status"].eq("near_edge") & table["message"].str.startswith(UNEVEN_LIGHT_MESSAGE.split("{")[0])
    assert uneven.sum() <= (2 if "shadow" in case else 0)
    ok = table[table["status"] == "ok"][["x_px", "y_px"]].to_numpy()
    assert len(ok) + uneven.sum() == n
    dots = np.concatenate([ok, table[uneven][["x_px", "y_px"]].to_numpy()])
    assert len(set(cKDTree(dots).query(rendered.centres)[1])) == n  # one each
    assert cKDTree(rendered.centres).query(ok)[0].max() < 0.5


@pytest.mark.parametrize("polarity", ["dark", "bright"])
def test_even_light_keeps_the_global_candidates(polarity):
    """Under even light the global pass leaves no evidence of uneven light: the
    candidates are the global level's, bit for bit."""
    rendered = render(grid_scene({}, 8.0, polarity), 0.0, seed=5)
    assert detect_blobs(rendered.image, polarity=polarity) == detect_blobs(
        rendered.image, polarity=polarity, local_levels=False)


def test_demo_scene_keeps_the_global_candidates():
    scene, _ = demo_scene()
    image = render(scene, 7.0, seed=2).image
    assert detect_blobs(image) == detect_blobs(image, local_levels=False)


@pytest.mark.parametrize("lighting", [{"gradient_x": 1.2}, SHADOW], ids=["falloff", "shadow"])
def test_uneven_light_still_picks_the_right_pair_among_distractors(lighting):
    """The distractor scene (eight bolt holes, a wire, forty dust specks) under a
    4:1 falloff or a half-frame shadow: the pair measured is the two markers at
    every angle (a distractor found at a lower local level never takes a marker's
    place; with one global level the marker in the shade is missed at -25° and
    the pair is ambiguous). 1.5 px: the identity, not the fit, is tested here; the
    nearest distractor is 100 px away. Under the shadow at -70° both markers
    straddle its 30 px penumbra, which the pixel fit's lighting plane cannot model
    (one was fitted 1.0 px off, ``ok``): both are ``near_edge`` for the uneven
    background, and the pair is not measured."""
    scene = load_scene(Path(vision_torsion.__file__).parent / "synthetic" / "scenes" / "distractors.toml")
    scene = scene.replace(lighting=lighting, disk={"background_level": 150.0}, markers={"level": 30.0},
                          distractors={"bolt_level": 25.0, "wire_level": 45.0, "dust_level": 90.0})
    for i, angle in enumerate((-70.0, -25.0, 5.0, 42.5, 70.0)):
        rendered = render(scene, angle, seed=600 + i)
        if angle == -70.0 and "shadow" in lighting:
            table = find_markers(rendered.image)
            d = cKDTree(table[["x_px", "y_px"]].to_numpy()).query(rendered.centres)
            assert list(table["status"].to_numpy()[d[1]]) == ["near_edge", "near_edge"]
            assert all(m.startswith(UNEVEN_LIGHT_MESSAGE.split("{")[0]) for m in table["message"].to_numpy()[d[1]])
            with pytest.raises(MarkerError):
                measure_pair(rendered.image)
            continue
        pair = measure_pair(rendered.image)
        found = np.array([[m.x_px, m.y_px] for m in pair.markers])
        assert cKDTree(found).query(rendered.centres)[0].max() < 1.5, angle


@pytest.mark.parametrize(("lighting", "message"), [
    ({"shadow": 0.0}, r"\[lighting\] shadow must be within \(0, 1\] \(the relative light in the shade\), got 0.0"),
    ({"shadow_edge_px": -1.0}, r"\[lighting\] shadow_edge_px and reflection_dn must not be negative"),
    ({"reflection_sigma_px": 0.0}, r"\[lighting\] reflection_sigma_px must be positive, got 0.0"),
])
def test_lighting_errors(lighting, message):
    with pytest.raises(SceneError, match=message):
        Scene().replace(lighting=lighting)


def test_shadow_and_reflection_render_as_described():
    """The shade has `shadow` of the light beyond the edge; the reflection adds its
    peak at its centre (noise-free, no blur, no markers in the sampled pixels)."""
    scene = Scene().replace(
        noise={"read_noise_dn": 0.0}, optics={"blur_sigma_px": 0.0}, disk={"background_level": 90.0},
        lighting={"shadow": 0.5, "shadow_angle_deg": 0.0, "shadow_offset_px": 100.0, "shadow_edge_px": 20.0,
                  "reflection_dn": 60.0, "reflection_x": 200.0, "reflection_y": 100.0,
                  "reflection_sigma_px": 30.0})
    image = render(scene, 0.0, seed=0).image.astype(float)
    # x = 699.5 + 100 is the edge: 10 px beyond it, the full shade; 10 px before, full light
    assert image[900, 1100] == 45.0
    assert image[900, 300] == 90.0
    # 0.5 px before the edge in a 20 px penumbra: 0.475 of the way into the shade
    assert image[900, 799] == round(90.0 * (1 - 0.5 * 0.475))
    assert image[100, 200] == 150.0
