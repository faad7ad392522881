"""The measurements vocabulary and its one reader: one row-numbering rule (the CSV line,
header = line 1) from the file to every later message, and the caller's data untouched."""

import numpy as np
import pandas as pd
import pytest

from vision_torsion.analysis import analyze_session
from vision_torsion.errors import AnalysisError, MeasurementsError, RecordError, RigError
from vision_torsion.measurements import (
    CYCLE_PHASES,
    MEASUREMENT_COLUMNS,
    PHASE_SIGN,
    PHASES,
    ZERO_TORQUE_PHASES,
    TorqueRig,
    pieces_per_pan,
    read_measurements,
)
from vision_torsion.session.config import config_from_dict, config_to_dict
from vision_torsion.stiffness.records import read_record
from vision_torsion.synthetic import simulate_measurements


def _table():
    return simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0,),
                                 rng=np.random.default_rng(7))


def _write(tmp_path, frame):
    p = tmp_path / "measurements.csv"
    frame.to_csv(p, index=False)
    return p


def test_phases_vocabulary():
    assert PHASES[0] == "reference" and PHASES[-1] == "closing"
    assert CYCLE_PHASES == ("positive_unloading", "negative_loading", "negative_unloading", "positive_loading")
    assert set(PHASE_SIGN) == set(PHASES)
    assert all(PHASE_SIGN[p] == 0 for p in ZERO_TORQUE_PHASES)
    assert set(MEASUREMENT_COLUMNS) >= {"image", "phase", "torque_nm", "angle_deg", "status"}


def test_bad_value_is_reported_with_its_csv_line(tmp_path):
    table = _table()
    table = table.astype({"angle_deg": object})
    table.loc[3, "angle_deg"] = "twelve"  # data row at position 3: the file's line 5
    path = _write(tmp_path, table)
    assert path.read_text().splitlines()[4].count("twelve") == 1  # line 5 of the file, counted from 1
    with pytest.raises(MeasurementsError, match=r"measurements\.csv: 1 problem.*\n  line 5: column angle_deg "
                                                r"is not a number \('twelve'\)"):
        read_measurements(path)
    # the analysis and the stiffness curve, reading the same file, name the same line
    with pytest.raises(AnalysisError, match=r"line 5: column angle_deg is not a number"):
        analyze_session(pd.read_csv(path), n_draws=20, fit_bouc_wen=False)
    with pytest.raises(RecordError, match=r"line 5: column angle_deg is not a number"):
        read_record(path)


def test_missing_value_after_failed_rows_names_its_csv_line(tmp_path):
    """The stiffness reader drops failed rows first; a blank angle on an ok row is
    still named by its line in the file, not by its rank among the ok rows."""
    table = _table()
    table.loc[1:2, "status"] = "failed"
    table.loc[4, "angle_deg"] = np.nan  # ok row at position 4: line 6 (was "data row 3")
    path = _write(tmp_path, table)
    with pytest.raises(RecordError, match=r"column 'angle_deg' has a missing, non-numeric or infinite value "
                                          r"\(blank\) on line 6"):
        read_record(path)


def test_every_bad_row_is_listed():
    table = _table().astype({"phase": object, "torque_std_nm": object})
    table.loc[0, "phase"] = "sideways"
    table.loc[2, "torque_std_nm"] = -1.0
    with pytest.raises(MeasurementsError) as info:
        read_measurements(table)
    message = str(info.value)
    assert "2 problem(s)" in message
    assert "line 2: unknown phase 'sideways'" in message and "line 4: torque_std_nm is negative (-1)" in message
    assert info.value.reason == "bad_row"


def test_result_is_indexed_by_line_and_the_callers_frame_is_untouched():
    table = _table()
    table["cycle"] = table["cycle"].astype(int)
    table["message"] = np.nan
    before = table.copy(deep=True)
    out = read_measurements(table)
    pd.testing.assert_frame_equal(table, before)  # not mutated
    assert out is not table and list(out.index) == list(range(2, len(table) + 2))
    assert out["cycle"].dtype == np.float64 and (out["message"] == "").all()
    # a column that needed no change is shared, not copied
    assert np.shares_memory(out["angle_deg"].to_numpy(), table["angle_deg"].to_numpy())
    # rows taken from a table it returned keep their line numbers
    subset = out[out["phase"] == "negative_loading"]
    assert list(read_measurements(subset).index) == list(subset.index) != list(range(2, len(subset) + 2))


def test_bad_value_in_a_subset_keeps_its_line():
    out = read_measurements(_table())
    subset = out[out.index >= 10].astype({"angle_deg": object})
    subset.loc[12, "angle_deg"] = "?"
    with pytest.raises(MeasurementsError, match=r"line 12: column angle_deg is not a number"):
        read_measurements(subset)


def test_missing_file_and_columns():
    with pytest.raises(MeasurementsError, match="no such file") as info:
        read_measurements("/nonexistent/measurements.csv")
    assert info.value.reason == "not_found"
    with pytest.raises(MeasurementsError, match=r"missing column\(s\): angle_deg"):
        read_measurements(_table().drop(columns="angle_deg"))


def test_pieces_per_pan_scalar_and_array_agree():
    masses = [0.0, 1e-9, 0.02, 0.02000001, 0.05, 0.06, -0.02, np.nan]
    arr = pieces_per_pan(masses, 0.02)
    assert arr.tolist() == [0, 1, 1, 1, 3, 3, 0, 0]
    assert [pieces_per_pan(m, 0.02) for m in masses] == arr.tolist()


def test_session_toml_rig_reads_into_the_torque_rig_which_is_checked_once():
    doc = {"rig": {"arm_radius_m": 0.05, "mass_std_kg": 1e-4, "friction_torque_std_nm": 0.002},
           "protocol": {"orientations_deg": [0.0], "max_torque_nm": 0.3, "step_mass_kg": 0.02}}
    rig = config_from_dict(doc).rig  # [protocol] step_mass_kg is the rig's step mass in memory
    assert rig == TorqueRig(step_mass_kg=0.02, mass_std_kg=1e-4, arm_radius_m=0.05, friction_torque_std_nm=0.002)
    assert rig.step_torque_nm == pytest.approx(2 * 0.02 * 9.81 * 0.05, rel=1e-15)
    tolerance = {**doc, "rig": {"arm_radius_m": 0.05, "mass_tolerance_kg": 1e-4}}
    rig = config_from_dict(tolerance).rig
    assert rig.mass_tolerance_kg == 1e-4 and rig.mass_std_kg == pytest.approx(1e-4 / np.sqrt(3), rel=1e-15)
    assert "mass_tolerance_kg" not in rig.to_dict()
    assert TorqueRig.from_mapping(rig.to_dict()).mass_std_kg == rig.mass_std_kg
    written = config_to_dict(config_from_dict(tolerance))  # written back as given: the ± bound, in its tables
    assert written["rig"]["mass_tolerance_kg"] == 1e-4 and "mass_std_kg" not in written["rig"]
    assert written["protocol"]["step_mass_kg"] == 0.02 and "step_mass_kg" not in written["rig"]
    with pytest.raises(RigError, match=r"rig: mass_std_kg 0.0001 is not mass_tolerance_kg / sqrt\(3\) = 5.7735e-05"):
        TorqueRig(step_mass_kg=0.02, mass_std_kg=1e-4, mass_tolerance_kg=1e-4, arm_radius_m=0.05)
    with pytest.raises(RigError, match=r"rig: mass_tolerance_kg must be a finite number >= 0, got -0.0001"):
        TorqueRig.from_tolerance(mass_tolerance_kg=-1e-4, step_mass_kg=0.02, arm_radius_m=0.05)
    with pytest.raises(RigError, match="rig: arm_radius_m must be a finite number > 0, got 0.0"):
        TorqueRig(step_mass_kg=0.02, mass_std_kg=1e-4, arm_radius_m=0.0)
    with pytest.raises(RigError, match=r"rig: missing key\(s\) \['mass_std_kg'\], unknown key\(s\) \['mass'\]"):
        TorqueRig.from_mapping({"step_mass_kg": 0.02, "arm_radius_m": 0.05, "mass": 1})


def test_closing_rows_are_not_part_of_a_loop():
    table = _table()
    # the closing image is the zero-torque state after unloading from +Tmax: the same state as the end of
    # cycle 1's positive unloading (analysis compares the two for creep), so copy that row
    ends = table[(table["phase"] == "positive_unloading") & (table["torque_nm"] == 0)]
    closing = ends.groupby("orientation_deg").tail(1).assign(phase="closing", image="closing.png", step=0)
    with_closing = pd.concat([table, closing], ignore_index=True)
    a = analyze_session(table, n_draws=20, fit_bouc_wen=False)
    b = analyze_session(with_closing, n_draws=20, fit_bouc_wen=False)
    pd.testing.assert_frame_equal(a.figures, b.figures)
