"""session.toml: validation messages, defaults, round trip."""

import math

import pytest

from vision_torsion.errors import SessionError
from vision_torsion.session.config import config_from_dict, config_to_dict, load_config, write_config


def doc(**changes):
    d = {"angle_sign": -1,
         "rig": {"arm_radius_m": 0.05, "mass_tolerance_kg": 1e-4},
         "markers": {"polarity": "bright", "radius_range": [5, 30]},
         "protocol": {"orientations_deg": [0, 60], "max_torque_nm": 0.36,
                      "step_mass_kg": 0.02, "cycles": 2}}
    for path, value in changes.items():
        table, _, key = path.rpartition("__")
        target = d[table] if table else d
        if value is None:
            target.pop(key, None)
        else:
            target[key] = value
    return d


def test_defaults_and_tolerance_conversion():
    cfg = config_from_dict(doc())
    assert cfg.rig.gravity_m_per_s2 == 9.81
    assert cfg.rig.friction_torque_std_nm == 0.0
    # ± bound, uniform distribution: sigma = a / sqrt(3)
    assert cfg.rig.mass_std_kg == pytest.approx(1e-4 / math.sqrt(3), rel=1e-12)
    assert cfg.markers.radius_range == (5.0, 30.0)
    assert cfg.protocol.orientations_deg == (0.0, 60.0)
    assert cfg.angle_sign == -1


def test_mass_std_is_taken_as_is():
    cfg = config_from_dict(doc(rig__mass_tolerance_kg=None, rig__mass_std_kg=3e-5))
    assert cfg.rig.mass_std_kg == 3e-5


def test_write_load_round_trip(tmp_path):
    cfg = config_from_dict(doc(rig__friction_torque_std_nm=1e-4))
    write_config(tmp_path / "session.toml", cfg, header="a comment\nsecond line")
    text = (tmp_path / "session.toml").read_text()
    assert text.startswith("# a comment\n# second line\n")
    assert load_config(tmp_path / "session.toml") == cfg
    assert config_from_dict(config_to_dict(cfg)) == cfg


@pytest.mark.parametrize("changes, message", [
    (dict(rig__arm_radius_m=None), r"rig\.arm_radius_m: missing; expected a number"),
    (dict(rig__arm_radius_m=-0.05), r"rig\.arm_radius_m: must be a finite number > 0 \(m\), got -0\.05"),
    (dict(rig__gravity_m_per_s2="9.81"),
     r"rig\.gravity_m_per_s2: must be a finite number > 0 \(m/s²\), got '9\.81'"),
    (dict(rig__friction_torque_std_nm=-1),
     r"rig\.friction_torque_std_nm: must be a finite number >= 0 \(N·m\)"),
    (dict(rig__mass_std_kg=1e-5), r"rig\.mass_std_kg: give either mass_tolerance_kg"),
    (dict(rig__mass_tolerance_kg=None), r"rig\.mass_tolerance_kg: missing; expected the ± "),
    (dict(rig__spring=1), r"rig\.spring: unknown key"),
    (dict(angle_sign=2), r"angle_sign: expected 1 or -1, got 2"),
    (dict(format_version=7), r"format_version: expected 1, got 7"),
    (dict(rig=None), r"rig: missing table"),
    (dict(protocol__cycles=0), r"protocol\.cycles: must be a whole number >= 1, got 0"),
    (dict(protocol__orientations_deg=[]),
     r"protocol\.orientations_deg: expected a non-empty list of numbers"),
    (dict(protocol__orientations_deg=[0, 60, 0]),
     r"protocol\.orientations_deg: repeated orientation"),
    (dict(protocol__orientations_deg=None), r"protocol\.orientations_deg: missing"),
    (dict(protocol__step_mass_kg=0), r"protocol\.step_mass_kg: must be a finite number > 0 \(kg\)"),
    (dict(markers__polarity="grey"), r"markers: polarity must be one of"),
])
def test_validation_messages(changes, message):
    with pytest.raises(SessionError, match=message):
        config_from_dict(doc(**changes), source="x/session.toml")


def test_every_problem_is_listed_at_once():
    with pytest.raises(SessionError, match=r"x/session\.toml: 3 problem\(s\)") as info:
        config_from_dict(doc(angle_sign=0, rig__arm_radius_m=0, protocol__cycles=1.5),
                         source="x/session.toml")
    text = str(info.value)
    assert "angle_sign" in text and "rig.arm_radius_m" in text and "protocol.cycles" in text


def test_missing_file(tmp_path):
    with pytest.raises(SessionError, match=r"session\.toml: no such file"):
        load_config(tmp_path / "session.toml")


def test_invalid_toml(tmp_path):
    (tmp_path / "session.toml").write_text("[rig\narm_radius_m = 0.05\n")
    with pytest.raises(SessionError, match=r"session\.toml: not valid TOML"):
        load_config(tmp_path / "session.toml")
