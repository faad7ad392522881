"""The one parameter checker (vision_torsion.validate) and the errors' built-in bases."""

import pickle

import pytest

from vision_torsion import errors
from vision_torsion.correction import PlaneCorrection
from vision_torsion.errors import (
    ImageReadError,
    ManifestError,
    MeasurementsError,
    OutputError,
    RigError,
    SessionError,
    VisionTorsionError,
)
from vision_torsion.measurements import TorqueRig
from vision_torsion.session.process import process_session
from vision_torsion.stiffness import RigConstants, meshing_pairs
from vision_torsion.stiffness.branches import zero_band
from vision_torsion.synthetic import realistic_encoder_record, synthetic_encoder_record, synthetic_measurements
from vision_torsion.textfiles import MAX_TOML_DEPTH, parse_toml, read_text_bytes, read_toml
from vision_torsion.validate import MAX_MAGNITUDE, check_number, describe_range, number_problem


@pytest.mark.parametrize("value, kw, message", [
    (-0.05, dict(low=0, low_open=True, unit="m"), r"^arm must be a finite number > 0 \(m\), got -0\.05$"),
    (0, dict(low=0, low_open=True), r"^arm must be a finite number > 0, got 0$"),
    (float("nan"), dict(), r"^arm must be a finite number, got nan$"),
    (float("inf"), dict(low=0), r"^arm must be a finite number >= 0, got inf$"),
    ("2,5,10", dict(low=0), r"^arm must be a finite number >= 0, got '2,5,10'$"),
    (None, dict(), r"^arm must be a finite number, got None$"),
    (True, dict(), r"^arm must be a finite number, got True$"),
    ([1, 2], dict(), r"^arm must be a finite number, got \[1, 2\]$"),
    (2.5, dict(low=1, whole=True), r"^arm must be a whole number >= 1, got 2\.5$"),
    (0.0, dict(nonzero=True), r"^arm must be a finite number, not 0, got 0\.0$"),
    (3.0, dict(low=1e-3, high=2.0, unit="m"), r"^arm must be a finite number in \[0\.001, 2\] \(m\), got 3\.0$"),
    (2.0, dict(high=2.0, high_open=True), r"^arm must be a finite number < 2, got 2\.0$"),
    (1e308, dict(), r"^arm must be a finite number \(its magnitude is limited to 1e\+12\), got 1e\+308$"),
    (10**400, dict(low=0),
     r"^arm must be a finite number >= 0 \(its magnitude is limited to 1e\+12\), got an integer of about 400 digits$"),
])
def test_check_number_names_parameter_value_and_range(value, kw, message):
    with pytest.raises(RigError, match=message) as info:
        check_number(value, name="arm", error=RigError, **kw)
    assert info.value.reason == "bad_value"


def test_check_number_returns_the_value():
    assert check_number(3.0, name="n", low=1, whole=True) == 3
    assert isinstance(check_number(3.0, name="n", low=1, whole=True), int)
    assert check_number(5, name="x", low=0, low_open=True) == 5.0
    assert check_number(-MAX_MAGNITUDE, name="x") == -MAX_MAGNITUDE
    assert number_problem(0.05, low=0, low_open=True) is None


def test_long_text_is_cut_in_the_message():
    why = number_problem("x" * 500)
    assert len(why) < 120 and why.endswith("...")


def test_describe_range_forms():
    assert describe_range() == "a finite number"
    assert describe_range(low=0, high=1, low_open=True, high_open=True) == "a finite number in (0, 1)"


# -- errors are also the matching built-in ------------------------------------------


@pytest.mark.parametrize("cls", [c for c in map(lambda n: getattr(errors, n), errors.__all__)
                                 if c is not VisionTorsionError])
def test_every_error_is_a_builtin_a_user_can_catch(cls):
    builtin = OSError if cls in (ImageReadError, OutputError) else ValueError
    with pytest.raises(builtin, match="^where: why$") as info:
        raise cls("where: why", reason="code")
    assert isinstance(info.value, VisionTorsionError)
    assert info.value.reason == "code"
    again = pickle.loads(pickle.dumps(info.value))  # worker processes send them back
    assert type(again) is cls and str(again) == "where: why" and again.reason == "code"


def test_measurements_error_keeps_both_families():
    assert issubclass(MeasurementsError, ValueError)
    with pytest.raises(ValueError):
        raise MeasurementsError("m.csv: line 3: bad")


def test_a_users_except_valueerror_catches_a_bad_session(tmp_path):
    (tmp_path / "session.toml").write_text("[rig]\narm_radius_m = -1\n")
    from vision_torsion.session.config import load_config

    with pytest.raises(ValueError, match=r"rig\.arm_radius_m: must be a finite number > 0 \(m\), got -1"):
        load_config(tmp_path / "session.toml")


# -- TOML limits ---------------------------------------------------------------------


def test_toml_nested_past_the_parser_is_refused():
    text = "a = " + "[" * 5000 + "]" * 5000
    with pytest.raises(SessionError, match=rf"^s\.toml: not valid TOML \(tables or arrays nested deeper than "
                                           rf"{MAX_TOML_DEPTH} levels\)$") as info:
        parse_toml(text, source="s.toml", error=SessionError)
    assert info.value.reason == "bad_toml"


def test_toml_nested_past_the_limit_is_refused():
    text = "[" + ".".join(["t"] * (MAX_TOML_DEPTH + 1)) + "]\n"
    with pytest.raises(SessionError, match=rf"s\.toml: not valid TOML for vision-torsion \(t\.t.* is nested "
                                           rf"{MAX_TOML_DEPTH + 1} levels deep, more than {MAX_TOML_DEPTH}\)"):
        parse_toml(text, source="s.toml", error=SessionError)
    assert parse_toml("[" + ".".join(["t"] * (MAX_TOML_DEPTH - 1)) + "]\n", source="s")


def test_toml_integer_beyond_64_bits_is_refused():
    with pytest.raises(SessionError, match=r"s\.toml: rig\.arm_radius_m is an integer beyond TOML's 64 bits"):
        parse_toml("[rig]\narm_radius_m = " + "9" * 400, source="s.toml", error=SessionError)
    with pytest.raises(SessionError, match=r"s\.toml: protocol\.orientations_deg\[1\] is an integer beyond"):
        parse_toml("[protocol]\norientations_deg = [0, " + "9" * 30 + "]", source="s.toml", error=SessionError)
    assert parse_toml(f"a = {2**63 - 1}", source="s")["a"] == 2**63 - 1


def test_toml_integer_of_thousands_of_digits_is_refused():
    with pytest.raises(SessionError, match=r"s\.toml: not valid TOML \(an integer of thousands of digits; "
                                           r"TOML integers are 64-bit"):
        parse_toml("a = " + "9" * 5000, source="s.toml", error=SessionError)


def test_text_file_size_is_checked_before_reading(tmp_path):
    big = tmp_path / "big.toml"
    with open(big, "wb") as fh:
        fh.truncate(3 * 1024**3)  # sparse: no disk space used
    with pytest.raises(SessionError, match=r"big\.toml: 3221225472 bytes, more than the 268435456 a session "
                                           r"description may have") as info:
        read_toml(big, what="a session description", error=SessionError)
    assert info.value.reason == "too_large"


def test_read_text_bytes_limit_and_loop(tmp_path):
    p = tmp_path / "m.csv"
    p.write_bytes(b"x" * 11)
    assert read_text_bytes(p, what="a manifest", limit=11) == b"x" * 11
    with pytest.raises(ManifestError, match=r"m\.csv: 11 bytes, more than the 10 a manifest may have"):
        read_text_bytes(p, what="a manifest", error=ManifestError, limit=10)
    loop = tmp_path / "loop.toml"
    loop.symlink_to(loop)
    with pytest.raises(SessionError, match=r"loop\.toml: cannot be read \(Too many levels of symbolic links\)"):
        read_toml(loop, what="a session description", error=SessionError)


# -- the checker where the hand-written checks were ------------------------------------


@pytest.mark.parametrize("call, error, message", [
    (lambda: synthetic_encoder_record(cycles=0),
     errors.SceneError, r"^synthetic_encoder_record: cycles must be a whole number >= 1, got 0$"),
    (lambda: synthetic_encoder_record(torque_noise_nm=-1),
     errors.SceneError, r"^synthetic_encoder_record: torque_noise_nm must be a finite number >= 0 \(N·m\), got -1$"),
    (lambda: realistic_encoder_record(friction_ratio=0.7),
     errors.SceneError, r"^realistic_encoder_record: friction_ratio must be a finite number in \[0, 0\.5\), got 0\.7$"),
    (lambda: realistic_encoder_record(bedding_in_deg=0.3),
     errors.SceneError, r"^realistic_encoder_record: bedding_in_deg must be a finite number in \[0, 0\.2\) "
                        r"\(degrees, below backlash_deg\), got 0\.3$"),
    (lambda: realistic_encoder_record(sampling_rate_hz=60),
     errors.SceneError, r"^realistic_encoder_record: sampling_rate_hz must be a finite number > 100 "
                        r"\(Hz, above 2·hum_hz\), got 60$"),
    (lambda: meshing_pairs(
        [1.0], tooth_stiffness_nm_per_rad=float("nan")),
     RigError, r"^rig constant tooth_stiffness_nm_per_rad must be a finite number > 0 \(N·m/rad\), got nan$"),
    (lambda: zero_band([0.0, 1.0], threshold_nm=-2),
     errors.AnalysisError, r"^threshold_nm must be a finite number > 0 \(N·m\), got -2$"),
    (lambda: TorqueRig(
        step_mass_kg="0.02", mass_std_kg=0, arm_radius_m=0.05),
     RigError, r"^rig: step_mass_kg must be a finite number > 0, got '0\.02'$"),
    (lambda: TorqueRig(
        step_mass_kg=0.02, mass_std_kg=-1e-5, arm_radius_m=0.05),
     RigError, r"^rig: mass_std_kg must be a finite number >= 0, got -1e-05$"),
    (lambda: PlaneCorrection(
        homography=[[1, 0, 0], [0, 1, 0], [0, 0, 1]], k1=float("inf")),
     errors.CalibrationError, r"^k1 must be a finite number, got inf$"),
    (lambda: RigConstants(teeth=160.5),
     RigError, r"^rig constant teeth must be a whole number >= 1, got 160\.5$"),
    (lambda: synthetic_measurements(steps=0),
     errors.SceneError, r"^synthetic_measurements: steps must be a whole number >= 1, got 0$"),
    (lambda: process_session("/nonexistent", jobs=0),
     SessionError, r"^jobs must be a whole number >= 1, got 0$"),
])
def test_hand_written_checks_now_name_parameter_value_and_range(call, error, message):
    with pytest.raises(error, match=message) as info:
        call()
    assert info.value.reason == "bad_value"
