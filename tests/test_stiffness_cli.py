"""The ``vision-torsion stiffness`` command (issue 7)."""

import json

import pandas as pd
import tomli_w

from vision_torsion.cli import main
from vision_torsion.fileio import RECORD_NAME
from vision_torsion.synthetic import synthetic_encoder_record, synthetic_measurements


def _write_inputs(folder):
    syn = synthetic_encoder_record(seed=4)
    data = folder / "run1.csv"
    syn.frame.to_csv(data, index=False)
    rig = folder / "rig.toml"
    rig.write_bytes(tomli_w.dumps(syn.rig.to_dict()).encode())
    return syn, data, rig


def test_writes_curve_summary_and_plots_beside_data(tmp_path, capsys):
    syn, data, rig = _write_inputs(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["stiffness", str(data), "--rig", str(rig)]) == 0
    out = tmp_path / "run1_stiffness"
    # The input folder only gained the output folder.
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(before + ["run1_stiffness"])
    assert sorted(p.name for p in out.iterdir()) == [
        RECORD_NAME, "meshing_pairs.png", "stiffness_curve.csv", "stiffness_summary.json",
        "stiffness_torque.png", "torque_angle.png",
    ]
    curve = pd.read_csv(out / "stiffness_curve.csv")
    for column in ("torque_nm", "stiffness_nm_per_rad", "stiffness_std_nm_per_rad", "meshing_pairs_per_zone"):
        assert curve[column].notna().all()
    summary = json.loads((out / "stiffness_summary.json").read_text())
    assert abs(summary["backlash"]["width_deg"] / syn.backlash_deg - 1) < 0.05
    assert (out / "torque_angle.png").read_bytes()[:4] == b"\x89PNG"
    assert "dead zone" in capsys.readouterr().out


def test_camera_measurements_without_rig_and_output_option(tmp_path):
    data = tmp_path / "measurements.csv"
    synthetic_measurements(steps=12).to_csv(data, index=False)
    out = tmp_path / "elsewhere"
    assert main(["stiffness", str(data), "-o", str(out), "--method", "polynomial", "--order", "4",
                 "--quiet"]) == 0
    curve = pd.read_csv(out / "stiffness_curve.csv")
    assert curve["meshing_pairs_per_zone"].isna().all()  # no Ks: unknown, not 0
    assert not (out / "meshing_pairs.png").exists()
    steps = pd.read_csv(out / "stiffness_steps.csv")
    assert len(steps) == 4 * 12 and (out / "step_stiffness.png").exists()


def test_bad_input_exit_status_2(tmp_path, capsys):
    _, data, rig = _write_inputs(tmp_path)
    assert main(["stiffness", str(data)]) == 2
    assert "pass --rig FILE" in capsys.readouterr().err
    rig.write_text("[rig]\ntransmission_ratio = 0\npulses_per_rev = 51200\n")
    assert main(["stiffness", str(data), "--rig", str(rig)]) == 2
    assert "transmission_ratio" in capsys.readouterr().err
    assert main(["stiffness", str(tmp_path / "missing.csv"), "--cutoff-hz", "70"]) == 2
    assert not (tmp_path / "missing_stiffness").exists()
