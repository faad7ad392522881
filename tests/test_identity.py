"""Marker identity is never silently wrong.

A folder of independent rotations (a rotary-stage check shot in any order): with two
equal markers, `check-accuracy` settles identity from the reference angles,
`measure --order independent` takes the smallest rotation, and `measure` in sequence
order flags what it cannot know instead of guessing. A target with two markers of
clearly different radii is certain at any angle. Truth: the renderer's angles.
"""

import numpy as np
import pandas as pd
import pytest

from vision_torsion.angle import MAX_STEP_DEG, sequence_angles
from vision_torsion.calibration.accuracy import check_accuracy
from vision_torsion.cli import main
from vision_torsion.errors import MarkerError, VisionTorsionError
from vision_torsion.markers import Marker
from vision_torsion.measure import measure_folder
from vision_torsion.pair import measure_pair, select_pair
from vision_torsion.session.plan import plan_config, plan_session
from vision_torsion.settings import MeasureSettings
from vision_torsion.synthetic import Scene, render
from vision_torsion.synthetic.folders import write_accuracy_folder
from vision_torsion.synthetic.scene import SceneError, scene_from_dict

#: Error allowed on a right answer (deg): these 400x300 renders measure to ~0.003°;
#: a swapped pair is 180° off, so anything under a degree separates the two.
TOL_DEG = 0.02


def _scene(**markers):
    return Scene().replace(
        image={"width": 400, "height": 300},
        disk={"center_x": 200.3, "center_y": 150.8},
        markers={"radius_px": 16.0, "distance_px": 100.0, **markers},
    )


#: Twelve independent rotations between -70° and +70°, shuffled (seeded).
ANGLES = list(np.random.default_rng(17).permutation(np.linspace(-70.0, 70.0, 12) + 0.37))


@pytest.fixture(scope="module")
def shuffled_folder(tmp_path_factory):
    return write_accuracy_folder(_scene(), tmp_path_factory.mktemp("stage"), angles_deg=ANGLES, seed=3)


def _truth(folder):
    return dict(pd.read_csv(folder / "reference.csv").itertuples(index=False, name=None))


def test_check_accuracy_gets_every_angle_of_a_shuffled_folder_right(shuffled_folder, tmp_path):
    res = check_accuracy(shuffled_folder, out_dir=tmp_path, tolerance_deg=TOL_DEG)
    assert res.passed and res.n == 12 and res.n_failed == 0
    assert res.max_abs_error_deg < TOL_DEG


def test_measure_independent_gets_every_angle_right(shuffled_folder, tmp_path):
    res = measure_folder(shuffled_folder, reference=shuffled_folder / "reference.png", out_dir=tmp_path,
                         order="independent")
    truth = _truth(shuffled_folder)
    assert res.n_failed == 0 and res.n_ok == 13
    err = [row.angle_deg - truth[row.image] for row in res.table.itertuples()]
    assert np.abs(err).max() < TOL_DEG


def test_measure_sequence_never_reports_a_swapped_pair_as_ok(shuffled_folder, tmp_path):
    """Turns between these images reach 140°: the nearer candidate is then the swapped
    one, 40° from the previous angle. Every such image must be `ambiguous`, and every
    `ok` one right."""
    res = measure_folder(shuffled_folder, reference=shuffled_folder / "reference.png", out_dir=tmp_path)
    truth = _truth(shuffled_folder)
    table = res.table
    ok = table[table["status"] == "ok"]
    assert np.abs(ok["angle_deg"] - ok["image"].map(truth)).max() < TOL_DEG
    amb = table[table["status"] == "ambiguous"]
    assert len(amb) >= 4  # this order has at least four turns of more than 30°
    assert amb["angle_deg"].isna().all()
    assert amb["message"].str.startswith("ambiguous marker identity").all()
    assert len(ok) + len(amb) == len(table)


def test_ambiguous_message_names_both_candidates_and_the_limit(small_scene):
    ref = measure_pair(render(small_scene, 0.0, seed=1).image)
    cur = measure_pair(render(small_scene, 50.0, seed=2).image)
    (res,) = sequence_angles(ref, [cur])
    assert res.ambiguous.startswith("ambiguous marker identity: with two equal markers the image is at 50.0")
    assert "or -130.0" in res.ambiguous and f"more than the {MAX_STEP_DEG:g}° limit" in res.ambiguous
    (ind,) = sequence_angles(ref, [cur], order="independent")
    assert not ind.ambiguous and ind.angle_deg == pytest.approx(50.0, abs=TOL_DEG)


def test_sequence_of_small_steps_is_tracked_past_90_degrees(small_scene):
    """A slow turn through 170° in 10° steps: tracked and unwrapped, nothing ambiguous."""
    angles = np.arange(10.0, 171.0, 10.0)
    ref = measure_pair(render(small_scene, 0.0, seed=1).image)
    pairs = [measure_pair(render(small_scene, a, seed=k + 2).image) for k, a in enumerate(angles)]
    res = sequence_angles(ref, pairs)
    assert not any(r.ambiguous for r in res)
    assert np.abs([r.angle_deg for r in res] - angles).max() < TOL_DEG


def test_two_radii_target_is_certain_at_any_angle(tmp_path):
    """Markers of 16 and 11 px: every rotation in a shuffled ±180° folder is right in
    sequence order, whatever the turn between images."""
    angles = [170.0, -120.0, 95.0, -60.0, 25.0, -175.0, 140.0]
    folder = write_accuracy_folder(_scene(radii_px=(16.0, 11.0)), tmp_path / "two", angles_deg=angles, seed=5)
    settings = MeasureSettings(pair="distinct")
    res = measure_folder(folder, reference=folder / "reference.png", out_dir=tmp_path / "out", settings=settings)
    truth = _truth(folder)
    assert res.n_failed == 0
    err = [(row.angle_deg - truth[row.image] + 180) % 360 - 180 for row in res.table.itertuples()]
    assert np.abs(err).max() < TOL_DEG
    assert check_accuracy(folder, out_dir=tmp_path / "acc", tolerance_deg=TOL_DEG, settings=settings).passed


def _marker(r, x=0.0):
    return Marker(x_px=x, y_px=0.0, radius_px=r, radius_std_px=0.01)


def test_distinct_pair_needs_clearly_different_radii():
    with pytest.raises(MarkerError, match="pair 'distinct' needs two markers of clearly different radii"):
        select_pair([_marker(20.0), _marker(19.0, 50)], pair="distinct")


def test_distinct_pair_with_two_candidates_for_the_small_marker_is_ambiguous():
    with pytest.raises(MarkerError, match="ambiguous target: more than one marker of radius"):
        select_pair([_marker(20.0), _marker(12.0, 50), _marker(12.2, 90)], pair="distinct")


def test_distinct_pair_picks_the_largest_and_the_clearly_smaller():
    p = select_pair([_marker(20.0), _marker(12.0, 50), _marker(5.0, 90)], pair="distinct")
    assert sorted(m.radius_px for m in p.markers) == [12.0, 20.0]


def test_scene_radii_must_match_the_positions():
    data = {"disk": {"center_x": 700.0, "center_y": 500.0, "background_level": 200.0},
            "markers": {"polarity": "dark", "level": 40.0, "radius_px": 35.0, "distance_px": 300.0,
                        "radii_px": [35.0]}}
    with pytest.raises(SceneError, match=r"radii_px has 1 value\(s\) for 2 positions_deg"):
        scene_from_dict(data)
    data["markers"]["radii_px"] = [35.0, -2.0]
    with pytest.raises(SceneError, match="radii_px must all be positive"):
        scene_from_dict(data)


def test_measure_folder_rejects_an_unknown_order(shuffled_folder, tmp_path):
    with pytest.raises(VisionTorsionError, match="order must be one of"):
        measure_folder(shuffled_folder, reference=shuffled_folder / "reference.png", out_dir=tmp_path, order="x")
    with pytest.raises(VisionTorsionError, match="max_step_deg must be between 0 and 90 degrees"):
        measure_folder(shuffled_folder, reference=shuffled_folder / "reference.png", out_dir=tmp_path,
                       max_step_deg=120.0)


def test_measure_command_order_independent(shuffled_folder, tmp_path, capsys):
    ref = str(shuffled_folder / "reference.png")
    assert main(["measure", str(shuffled_folder), "--reference", ref, "-o", str(tmp_path / "a"), "-q",
                 "--order", "independent"]) == 0
    assert main(["measure", str(shuffled_folder), "--reference", ref, "-o", str(tmp_path / "b"), "-q"]) == 1
    captured = capsys.readouterr()
    assert "ambiguous marker identity" in captured.out + captured.err


def test_plan_target_distinct_writes_the_pair_and_says_why(tmp_path):
    plan = plan_session(plan_config(max_torque_nm=0.1, step_mass_kg=0.02, arm_radius_m=0.05, orientations_deg=[0],
                                    target="distinct"), tmp_path / "s")
    assert plan.config.markers.pair == "distinct"
    assert 'pair = "distinct"' in (tmp_path / "s" / "session.toml").read_text()
    assert "two markers of clearly different radii" in (tmp_path / "s" / "capture_sheet.md").read_text()
    equal = plan_session(plan_config(max_torque_nm=0.1, step_mass_kg=0.02, arm_radius_m=0.05,
                                     orientations_deg=[0]), tmp_path / "e")
    assert equal.config.markers.pair == "largest"
    assert "keep the turn between consecutive photographs small" in (tmp_path / "e" / "capture_sheet.md").read_text()


def test_plan_rejects_an_unknown_target(tmp_path):
    from vision_torsion.session.config import SessionError

    with pytest.raises(SessionError, match="target must be 'equal', 'distinct' or a target description"):
        plan_session(plan_config(max_torque_nm=0.1, step_mass_kg=0.02, arm_radius_m=0.05, target="x"), tmp_path / "s")
