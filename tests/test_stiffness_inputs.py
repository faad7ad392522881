"""Rig constants, records and the bad-input contract of the stiffness analysis (issue 7)."""

import numpy as np
import pandas as pd
import pytest

from vision_torsion.errors import AnalysisError, RecordError, RigError
from vision_torsion.stiffness import (
    RigConstants,
    analyze_stiffness_curve,
    load_rig,
    lowpass,
    output_angle_deg,
    read_record,
    split_branches,
)
from vision_torsion.stiffness.filtering import filter_record
from vision_torsion.stiffness.records import record_from_encoder
from vision_torsion.synthetic import synthetic_encoder_record, synthetic_measurements


def test_output_angle_removes_sensor_twist():
    # 25600 pulses of 51200/rev = 180 deg in; / 100 = 1.8 deg out; 20 N·m on a
    # 1e4 N·m/rad sensor twists it by 2e-3 rad, which is not gear twist.
    rig = RigConstants(pulses_per_rev=51200, transmission_ratio=100, sensor_stiffness_nm_per_rad=1e4)
    got = output_angle_deg(rig, [20.0], pulses=[25600])
    assert got[0] == pytest.approx(1.8 - np.rad2deg(2e-3), abs=1e-12)
    same = output_angle_deg(rig, [20.0], input_angle_deg=[180.0])
    assert same[0] == pytest.approx(got[0], abs=1e-12)


@pytest.mark.parametrize("ratio", [0, 0.0, float("nan"), "x"])
def test_transmission_ratio_of_zero_is_refused(ratio):
    with pytest.raises(RigError, match="transmission_ratio must be a finite number, not 0"):
        RigConstants(transmission_ratio=ratio)


def test_rig_file_errors_name_the_constant(tmp_path):
    p = tmp_path / "rig.toml"
    p.write_text("[rig]\ntransmission_ratio = 0\n")
    with pytest.raises(RigError, match=r"rig.toml: rig constant transmission_ratio"):
        load_rig(p)
    p.write_text("[rig]\ntransmission_ratio = 100\nsensor_stiffness_nm_per_rad = -5\n")
    with pytest.raises(RigError, match="sensor_stiffness_nm_per_rad must be a finite number > 0"):
        load_rig(p)
    p.write_text("[rig]\ngear_ratio = 100\n")
    with pytest.raises(RigError, match=r"unknown rig constant\(s\) in \[rig\]: gear_ratio"):
        load_rig(p)
    p.write_text("[meshing]\nreference_pairs = 37\n")
    with pytest.raises(RigError, match="reference_torque_nm and reference_pairs must be given together"):
        load_rig(p)
    with pytest.raises(RigError, match="no such file; expected a rig file"):
        load_rig(tmp_path / "missing.toml")


def test_rig_round_trip(tmp_path):
    import tomli_w

    rig = RigConstants(pulses_per_rev=51200, transmission_ratio=-100, teeth=160,
                       check_torque_nm=(2, 10, 30), check_pairs=(14, 37, 49))
    p = tmp_path / "rig.toml"
    p.write_bytes(tomli_w.dumps(rig.to_dict()).encode())
    assert load_rig(p) == rig


def _encoder_frame(n=100):
    t = np.arange(n) / 100.0
    return pd.DataFrame({"time_s": t, "input_pulses": np.arange(n) * 10, "torque_nm": np.zeros(n)})


def test_too_few_points():
    with pytest.raises(RecordError, match="too few points: 12 rows, at least 30 needed"):
        record_from_encoder(_encoder_frame(12), rig=RigConstants(pulses_per_rev=100))


def test_non_monotonic_time_names_column_and_row():
    frame = _encoder_frame()
    frame.loc[40, "time_s"] = frame.loc[38, "time_s"]
    with pytest.raises(RecordError, match=r"column 'time_s' must be strictly increasing; line 42 "):
        record_from_encoder(frame, rig=RigConstants(pulses_per_rev=100))


def test_missing_and_bad_columns_are_named():
    rig = RigConstants(pulses_per_rev=100)
    with pytest.raises(RecordError, match="exactly one of the columns 'input_pulses' and 'input_angle_deg'"):
        record_from_encoder(_encoder_frame().drop(columns="input_pulses"), rig=rig)
    frame = _encoder_frame()
    frame["torque_nm"] = frame["torque_nm"].astype(object)
    frame.loc[5, "torque_nm"] = "n/a"
    with pytest.raises(RecordError, match=r"column 'torque_nm' has a missing, non-numeric or infinite "
                                          r"value 'n/a' on line 7"):
        record_from_encoder(frame, rig=rig)
    with pytest.raises(RigError, match="pulses_per_rev is needed"):
        record_from_encoder(_encoder_frame(), rig=RigConstants())


def test_torque_that_never_changes_is_a_sensor_not_read():
    # The drive moves, the torque column is one constant value (issue 16: this
    # was "the polynomial fit is not monotonic; try a lower --order").
    frame = _encoder_frame()
    frame["torque_nm"] = 2.5
    with pytest.raises(RecordError, match=r"column 'torque_nm' never changes \(every value is 2.5 N·m\)") as info:
        analyze_stiffness_curve(frame, rig=RigConstants(pulses_per_rev=100))
    assert info.value.reason == "torque_constant"


def test_torque_within_its_noise_is_not_a_load():
    frame = _encoder_frame(400)
    frame["torque_nm"] = np.random.default_rng(3).normal(0.0, 0.01, len(frame))
    with pytest.raises(RecordError, match="changes by only .* N·m, within its noise"):
        analyze_stiffness_curve(frame, rig=RigConstants(pulses_per_rev=100))


def test_inverted_transmission_ratio_has_its_own_message():
    # A ratio of the wrong sign makes the torque fall as the output angle rises
    # (issue 16: this too was "not monotonic; try a lower --order").
    syn = synthetic_encoder_record(seed=2)
    rig = RigConstants(pulses_per_rev=51200, transmission_ratio=-100, sensor_stiffness_nm_per_rad=2e4)
    with pytest.raises(AnalysisError, match=r"the sign of transmission_ratio = -100 or of the torque "
                                            r"sensor is inverted") as info:
        analyze_stiffness_curve(syn.frame, rig=rig)
    assert info.value.reason == "inverted_sign"


def test_no_loading_branch():
    # A camera table with unloading phases only.
    table = synthetic_measurements(steps=6)
    table = table[~table["phase"].isin(["positive_loading", "negative_loading"])]
    with pytest.raises(AnalysisError, match="no loading branch"):
        analyze_stiffness_curve(table, method="polynomial")


def test_cutoff_at_or_above_nyquist():
    with pytest.raises(AnalysisError, match=r"cutoff_hz = 60 Hz must be above 0 and below the Nyquist frequency 50 Hz"):
        lowpass(np.zeros(100), sampling_rate=100.0, cutoff_hz=60.0)
    syn = synthetic_encoder_record(seed=0)
    with pytest.raises(AnalysisError, match="Nyquist"):
        analyze_stiffness_curve(syn.frame, rig=syn.rig, cutoff_hz=50.0)


def test_lowpass_does_not_touch_input_and_has_no_lag():
    t = np.arange(2000) / 100.0
    slow = np.sin(2 * np.pi * 0.1 * t)
    x = slow + np.random.default_rng(7).normal(0, 0.1, t.size)
    before = x.copy()
    y = lowpass(x, sampling_rate=100.0)
    assert np.array_equal(x, before)
    # Zero phase: the 0.1 Hz component keeps its phase. A causal 4th-order 5 Hz
    # Butterworth delays it by ~0.1 s, i.e. 0.06 rad; we allow 0.005 rad (noise).
    basis = np.column_stack([np.sin(2 * np.pi * 0.1 * t), np.cos(2 * np.pi * 0.1 * t)])
    (a_sin, a_cos), *_ = np.linalg.lstsq(basis, y, rcond=None)
    assert abs(np.arctan2(a_cos, a_sin)) < 0.005


def test_branch_split_matches_truth():
    syn = synthetic_encoder_record(seed=11, cycles=2)
    record = record_from_encoder(syn.frame, rig=syn.rig)
    split = split_branches(filter_record(record), raw_torque_nm=record.torque_nm)
    kinds = [b.kind for b in split.branches]
    assert kinds == ["positive_loading", "positive_unloading", "negative_loading", "negative_unloading"] * 2
    # Every sample given a branch kind carries the true kind (samples in the zero
    # band are dead_zone by construction, so compare the others only).
    labelled = np.isin(split.labels, ["positive_loading", "positive_unloading",
                                      "negative_loading", "negative_unloading"])
    assert np.mean(split.labels[labelled] == syn.true_phase[labelled]) > 0.995


def test_measurements_only_ok_rows_and_phase_check(tmp_path):
    table = synthetic_measurements(steps=6)
    table.loc[3, "status"] = "failed"
    table.loc[3, "torque_nm"] = np.nan  # a failed row may be empty: it is skipped
    p = tmp_path / "measurements.csv"
    table.to_csv(p, index=False)
    record = read_record(p)
    assert record.source == "camera" and len(record) == len(table) - 1
    table.loc[5, "phase"] = "sideways"
    table.to_csv(p, index=False)
    with pytest.raises(RecordError, match=r"line 7: unknown phase 'sideways'"):
        read_record(p)
