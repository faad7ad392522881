"""read_toml: one way to read a TOML file, and every TOML reader of the project uses it."""

import os

import pytest

from vision_torsion.calibration.accuracy import load_spec
from vision_torsion.correction import load_correction
from vision_torsion.errors import (
    CalibrationError,
    ReferenceTableError,
    RigError,
    SceneError,
    SessionError,
    VisionTorsionError,
)
from vision_torsion.session.config import load_config
from vision_torsion.stiffness.rig import load_rig
from vision_torsion.synthetic.scene import load_scene
from vision_torsion.synthetic.session import load_session_scene
from vision_torsion.textfiles import read_toml

READERS = [
    (load_config, SessionError),
    (load_scene, SceneError),
    (load_session_scene, SceneError),
    (load_spec, ReferenceTableError),
    (load_correction, CalibrationError),
    (load_rig, RigError),
]


def test_read_toml_reads_and_names_each_failure(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text('title = "x"\n[rig]\narm_radius_m = 0.05\n', encoding="utf-8")
    assert read_toml(good, what="a test file") == {"title": "x", "rig": {"arm_radius_m": 0.05}}
    cases = {
        "not_found": (tmp_path / "missing.toml", r"missing\.toml: no such file; expected a test file"),
        "unreadable": (tmp_path, r"cannot be read \(Is a directory\)"),
        "not_utf8": (tmp_path / "latin.toml", r"latin\.toml: line 1: not UTF-8 text \(byte 0xfc at column 10\)"),
        "bad_toml": (tmp_path / "bad.toml", r"bad\.toml: not valid TOML \(.*line 2"),
    }
    (tmp_path / "latin.toml").write_bytes('name = "Müller"\n'.encode("latin-1"))
    (tmp_path / "bad.toml").write_text("a = 1\nb = = 2\n", encoding="utf-8")
    for reason, (path, match) in cases.items():
        if reason == "unreadable" and os.name == "nt":
            continue
        with pytest.raises(SessionError, match=match) as info:
            read_toml(path, what="a test file", error=SessionError)
        assert info.value.reason == reason


@pytest.mark.parametrize("reader, error", READERS, ids=[r.__name__ for r, _ in READERS])
def test_every_toml_reader_fails_the_same_way(tmp_path, reader, error):
    bad = tmp_path / "bad.toml"
    bad.write_text("key = = 1\n", encoding="utf-8")
    with pytest.raises(error, match=r"bad\.toml: not valid TOML") as info:
        reader(bad)
    assert info.value.reason == "bad_toml" and isinstance(info.value, VisionTorsionError)
    with pytest.raises(error, match=r"gone\.toml: no such file; expected ") as info:
        reader(tmp_path / "gone.toml")
    assert info.value.reason == "not_found"
