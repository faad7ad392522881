"""Target descriptions: layouts in mm, the ready targets, symmetry, and every refusal."""

import numpy as np
import pytest

from vision_torsion.errors import TargetError
from vision_torsion.targets import (
    MIN_INDEX_RATIO,
    dots_target,
    grid_target,
    load_target,
    ready_targets,
    ring_target,
    target_from_dict,
)


def test_ring_dots_counter_clockwise_as_displayed_from_plus_x():
    t = ring_target(16, diameter_mm=80, dot_diameter_mm=9.6, index_diameter_mm=12)
    polar = np.degrees(np.arctan2(-np.array(t.y_mm), np.array(t.x_mm))) % 360
    np.testing.assert_allclose(polar, 22.5 * np.arange(16), atol=1e-9)
    np.testing.assert_allclose(np.hypot(t.x_mm, t.y_mm), 40.0, atol=1e-12)
    assert t.diameter_mm[0] == 12 and set(t.diameter_mm[1:]) == {9.6} and t.index == (0,)


def test_grid_centred_on_the_axis_index_top_left():
    t = grid_target(3, 4, pitch_mm=10, dot_diameter_mm=4, index_diameter_mm=6)
    assert t.centres_mm.mean(axis=0) == pytest.approx([0.0, 0.0], abs=1e-12)
    assert (t.x_mm[0], t.y_mm[0]) == (-15.0, -10.0) and t.index == (0,)
    assert t.min_spacing_mm == pytest.approx(10.0)


@pytest.mark.parametrize("name", ["ring16", "ring8", "grid5", "pair_distinct"])
def test_ready_targets_load_and_are_not_symmetric(name):
    assert name in ready_targets()
    t = load_target(name)
    assert t.name == name and t.symmetry_turns_deg() == ()


def test_symmetric_layouts_are_named_with_their_turns():
    assert ring_target(6, diameter_mm=60, dot_diameter_mm=5).symmetry_turns_deg() == (60, 120, 180, 240, 300)
    assert grid_target(4, 4, pitch_mm=10, dot_diameter_mm=4).symmetry_turns_deg() == (90, 180, 270)
    assert grid_target(3, 4, pitch_mm=10, dot_diameter_mm=4).symmetry_turns_deg() == (180,)
    assert dots_target([40, -40], [0, 0], [8, 8]).symmetry_turns_deg() == (180,)


def test_dots_index_is_the_dot_of_another_size():
    t = dots_target([30, 0, -30, 0], [0, -30, 0, 30], [8, 8, 8, 11])
    assert t.index == (3,) and t.layout == "dots"


def test_target_file_and_session_table_read_alike(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text('[target]\nlayout = "ring"\nmarkers = 12\ndiameter_mm = 60.0\n'
                 'dot_diameter_mm = 6.0\nindex_diameter_mm = 8.0\n', encoding="utf-8")
    t = load_target(f)
    assert t.name == "mine" and t.n_markers == 12 and t.extent_mm == pytest.approx(34.0)


@pytest.mark.parametrize("doc, match, reason", [
    ({"layout": "hexagon"}, r"layout must be one of ring, grid, dots, got 'hexagon'", "bad_value"),
    ({"layout": "ring", "markers": 8, "diameter_mm": 80, "dot_diameter_mm": 8, "pitch_mm": 3},
     r"unknown key\(s\) for layout 'ring': pitch_mm", "unknown_key"),
    ({"layout": "grid", "rows": 3, "dot_diameter_mm": 4}, r"layout 'grid' needs columns, pitch_mm", "missing_key"),
    ({"layout": "ring", "markers": 1.5, "diameter_mm": 80, "dot_diameter_mm": 8},
     r"markers must be a whole number >= 2, got 1.5", "bad_value"),
    ({"layout": "ring", "markers": 8, "diameter_mm": -80, "dot_diameter_mm": 8},
     r"diameter_mm must be a positive number \(mm\), got -80", "bad_value"),
    ({"layout": "ring", "markers": 8, "diameter_mm": "wide", "dot_diameter_mm": 8},
     r"diameter_mm must be a number, got 'wide'", "bad_value"),
    ({"layout": "ring", "markers": 40, "diameter_mm": 80, "dot_diameter_mm": 8},
     r"dots 0 and 1 overlap", "overlapping_dots"),
    ({"layout": "ring", "markers": 8, "diameter_mm": 80, "dot_diameter_mm": 8, "index_diameter_mm": 8.8},
     rf"index_diameter_mm 8.8 is within {MIN_INDEX_RATIO:g}x of dot_diameter_mm 8", "weak_index"),
    ({"layout": "grid", "rows": 1, "columns": 1, "pitch_mm": 5, "dot_diameter_mm": 2},
     r"a grid needs at least 2 dots, got 1x1", "bad_value"),
    ({"layout": "dots", "x_mm": [0, "a"], "y_mm": [0, 1], "dot_diameter_mm": 2},
     r"x_mm must hold finite numbers \(mm\), got 'a'", "bad_value"),
    ({"layout": "dots", "x_mm": [0, 10], "y_mm": [0], "dot_diameter_mm": 2},
     r"x_mm, y_mm and dot_diameter_mm must be lists of one value per dot", "bad_value"),
])
def test_bad_descriptions_are_refused_by_field(doc, match, reason):
    with pytest.raises(TargetError, match=match) as err:
        target_from_dict(doc, where="t.toml: ")
    assert err.value.reason == reason and str(err.value).startswith("t.toml: [target]")


def test_not_a_table_is_refused():
    with pytest.raises(TargetError, match=r"\[target\] must be a table, got list"):
        target_from_dict([1, 2])


def test_unknown_name_lists_the_ready_targets():
    with pytest.raises(TargetError, match=r"ring99: no such file, and no ready target of that name \(ready: grid5, "
                                          r"pair_distinct, ring16, ring8\)") as err:
        load_target("ring99")
    assert err.value.reason == "not_found"


def test_file_without_target_table_is_refused(tmp_path):
    f = tmp_path / "x.toml"
    f.write_text("[markers]\npolarity = 'dark'\n", encoding="utf-8")
    with pytest.raises(TargetError, match=r"x.toml: no \[target\] table"):
        load_target(f)

