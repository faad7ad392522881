"""An N-marker target in session.toml: planned with `plan --target`, read back, validated
by key; `process` of a planned session not shot yet (its images measured:
test_session_target_process)."""

import pytest

from vision_torsion.cli import main
from vision_torsion.errors import SessionError
from vision_torsion.session.config import config_from_dict, config_to_dict, load_config
from vision_torsion.session.plan import plan_config, plan_session
from vision_torsion.session.process import process_session

RIG = {"arm_radius_m": 0.05, "mass_tolerance_kg": 1e-4}
PROTOCOL = {"max_torque_nm": 0.2, "step_mass_kg": 0.02, "orientations_deg": [0.0]}


def test_plan_writes_the_ready_target_and_reads_it_back(tmp_path):
    plan_session(plan_config(steps=2, step_mass_kg=0.02, arm_radius_m=0.05, target="ring16"), tmp_path / "s")
    cfg = load_config(tmp_path / "s" / "session.toml")
    assert cfg.target.name == "ring16" and cfg.target.n_markers == 16 and cfg.target.index == (0,)
    assert cfg.markers.pair == "largest"
    assert config_from_dict(config_to_dict(cfg)).target == cfg.target


@pytest.mark.parametrize("target, pair", [("equal", "largest"), ("distinct", "distinct")])
def test_two_marker_targets_are_kept(tmp_path, target, pair):
    plan_session(plan_config(steps=2, step_mass_kg=0.02, arm_radius_m=0.05, target=target), tmp_path / "s")
    cfg = load_config(tmp_path / "s" / "session.toml")
    assert cfg.target is None and cfg.markers.pair == pair


def test_plan_command_takes_a_target_file(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text('[target]\nlayout = "grid"\nrows = 3\ncolumns = 4\npitch_mm = 12.0\ndot_diameter_mm = 5.0\n'
                 'index_diameter_mm = 7.0\n', encoding="utf-8")
    assert main(["plan", str(tmp_path / "s"), "--steps", "2", "--step-mass", "0.02", "--arm-radius", "0.05",
                 "--target", str(f), "--no-pdf", "-q"]) == 0
    cfg = load_config(tmp_path / "s" / "session.toml")
    assert cfg.target.name == "mine" and cfg.target.n_markers == 12 and cfg.target.layout == "grid"


def test_unknown_target_is_refused_by_plan(tmp_path):
    with pytest.raises(SessionError, match=r"plan_config: target must be 'equal', 'distinct' or a target "
                                           r"description: ring99: no such file") as err:
        plan_session(plan_config(steps=2, step_mass_kg=0.02, arm_radius_m=0.05, target="ring99"), tmp_path / "s")
    assert err.value.reason == "not_found" and not (tmp_path / "s" / "session.toml").exists()


def test_session_target_table_is_validated_by_key():
    with pytest.raises(SessionError, match=r"target: \[target\] layout 'ring' needs diameter_mm"):
        config_from_dict({"rig": RIG, "protocol": PROTOCOL, "target": {"layout": "ring", "markers": 8,
                                                                        "dot_diameter_mm": 5}})


def test_session_target_by_name():
    cfg = config_from_dict({"rig": RIG, "protocol": PROTOCOL, "target": {"name": "grid5"}})
    assert cfg.target.n_markers == 25


def test_process_of_a_target_session_waits_for_its_images(tmp_path):
    plan_session(plan_config(steps=2, step_mass_kg=0.02, arm_radius_m=0.05, target="ring8"), tmp_path / "s")
    res = process_session(tmp_path / "s", jobs=1)
    assert res.n_pending == res.n_images and res.n_failed == 0
    assert res.measurements_path.read_text(encoding="utf-8").splitlines()[0].endswith(
        "message,markers_used,centre_shift_x_px,centre_shift_y_px,centre_shift_x_std_px,centre_shift_y_std_px,bump")
