"""check-accuracy: the reference table's checks, outputs, exit codes and the correction."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from vision_torsion.angle import rotation_angle
from vision_torsion.calibration import check_accuracy, load_spec, read_reference_table
from vision_torsion.cli import main
from vision_torsion.correction import PlaneCorrection
from vision_torsion.errors import ReferenceTableError
from vision_torsion.fileio import RECORD_NAME
from vision_torsion.measure import measure_folder
from vision_torsion.settings import MeasureSettings
from vision_torsion.synthetic import load_scene
from vision_torsion.synthetic.folders import write_accuracy_folder

ROOT = Path(__file__).resolve().parents[1]
ANGLES = [0.0, -40.0, 15.0, 65.0]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("acc") / "check"
    write_accuracy_folder(
        load_scene(ROOT / "vision_torsion" / "synthetic" / "scenes" / "standard.toml"), out, angles_deg=ANGLES, seed=5
    )
    return out


def _snapshot(d: Path) -> dict:
    return {
        p.relative_to(d).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest() for p in d.rglob("*") if p.is_file()
    }


def _copy(folder, tmp_path):
    dst = tmp_path / "check"
    shutil.copytree(folder, dst, ignore=shutil.ignore_patterns("results"))
    return dst


def test_check_passes_and_writes_outputs_only_in_results(folder):
    before = _snapshot(folder)
    res = check_accuracy(folder)
    after = {k: v for k, v in _snapshot(folder).items() if not k.startswith("results/")}
    assert after == before
    out = folder / "results"
    assert sorted(p.name for p in out.iterdir()) == [RECORD_NAME, "accuracy.csv", "accuracy.json", "accuracy.png"]
    table = pd.read_csv(out / "accuracy.csv")
    assert list(table.columns) == [
        "image",
        "reference_angle_deg",
        "measured_angle_deg",
        "error_deg",
        "angle_std_deg",
        "status",
    ]
    assert list(table["status"]) == ["reference", "ok", "ok", "ok"]
    summary = json.loads((out / "accuracy.json").read_text())
    for key in (
        "n",
        "bias_deg",
        "rms_deg",
        "max_abs_error_deg",
        "scale_error",
        "offset_deg",
        "fit_residual_rms_deg",
        "u95_deg",
        "coverage_factor",
        "u95_method",
        "tolerance_deg",
        "passed",
    ):
        assert key in summary
    assert summary["n"] == 3 and summary["passed"] is True and summary["tolerance_deg"] == 0.02
    assert res.passed and res.n_failed == 0
    # the standard scene measures to ≈ 0.001° per angle; 0.005° is a generous ceiling
    assert res.rms_deg < 0.005
    # the same RMS as measuring each image directly against the reference (same images)
    truth = pd.read_csv(folder / "truth.csv")
    direct = [
        rotation_angle(folder / "reference.png", folder / n).angle_deg - a
        for n, a in zip(truth["image"][1:], truth["true_angle_deg"][1:])
    ]
    assert res.rms_deg == pytest.approx(float(np.sqrt(np.mean(np.square(direct)))), rel=1e-12)
    # U95 = t(0.975, n-1) * RMS with no reference uncertainty: t(0.975, 2) = 4.303
    assert res.coverage_factor == pytest.approx(4.3027, abs=1e-4)
    assert res.u95_deg == pytest.approx(res.coverage_factor * res.rms_deg)
    assert (out / "accuracy.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_exit_codes(folder, tmp_path, capsys):
    assert main(["check-accuracy", str(folder), "-o", str(tmp_path / "a")]) == 0
    assert "PASSED" in capsys.readouterr().out
    assert main(["check-accuracy", str(folder), "-o", str(tmp_path / "b"), "--tolerance", "1e-7"]) == 1
    assert "FAILED" in capsys.readouterr().out
    assert json.loads((tmp_path / "b" / "accuracy.json").read_text())["passed"] is False
    bad = _copy(folder, tmp_path)
    (bad / "reference.csv").write_text("image,reference_angle_deg\nreference.png,0\n")
    assert main(["check-accuracy", str(bad), "-q"]) == 2
    assert "need at least 3" in capsys.readouterr().err
    assert not (bad / "results").exists()


def test_spec_sets_tolerance_and_cli_overrides(folder, tmp_path):
    spec = ROOT / "vision_torsion" / "calibration" / "specs" / "synthetic_selfcheck.toml"
    assert load_spec(spec).tolerance_deg == 0.005
    assert load_spec(ROOT / "vision_torsion" / "calibration" / "specs" / "rotary_stage.toml").tolerance_deg == 0.02
    res = check_accuracy(folder, out_dir=tmp_path / "s", spec=spec)
    assert res.tolerance_deg == 0.005
    assert (
        main(
            ["check-accuracy", str(folder), "-o", str(tmp_path / "t"), "--spec", str(spec), "--tolerance", "1e-7", "-q"]
        )
        == 1
    )


def test_one_bad_image_gets_a_status_and_the_run_goes_on(folder, tmp_path):
    d = _copy(folder, tmp_path)
    (d / "img_002.png").write_bytes(b"not an image at all")
    res = check_accuracy(d)
    status = dict(zip(res.table["image"], res.table["status"]))
    assert status["img_001.png"] == "ok" and status["img_003.png"] == "ok"
    assert status["img_002.png"].startswith("failed: ")
    assert res.n == 2 and res.n_failed == 1 and not res.passed
    assert main(["check-accuracy", str(d), "-q"]) == 1


def _table_folder(tmp_path, text, images=("a.png", "b.png", "c.png")):
    for n in images:
        (tmp_path / n).write_bytes(b"")
    (tmp_path / "reference.csv").write_text(text)
    return tmp_path


@pytest.mark.parametrize(
    "text, match",
    [
        (
            "image,reference_angle_deg\na.png,0\nb.png,10\nd.png,20\n",
            r"reference\.csv, line 4: image 'd\.png' not found",
        ),
        (
            "image,reference_angle_deg\na.png,0\nb.png,10\nb.png,20\n",
            r"line 4: duplicate image 'b\.png' \(first on line 3\)",
        ),
        (
            "image,reference_angle_deg\na.png,0\nb.png,ten\nc.png,20\n",
            r"line 3: reference_angle_deg 'ten' is not a number",
        ),
        (
            "image,reference_angle_deg\na.png,0\nb.png,nan\nc.png,20\n",
            r"line 3: reference_angle_deg 'nan' is not finite",
        ),
        ("image,reference_angle_deg\na.png,0\nb.png,10\n", r"2 row\(s\); need at least 3"),
        ("image,angle\na.png,0\nb.png,10\nc.png,20\n", r"missing column\(s\) reference_angle_deg"),
        ("image,reference_angle_deg\na.png,0\nb.png,10,5\nc.png,20\n", r"line 3: expected 2 fields, got 3"),
        ("", r"reference\.csv: empty file"),
    ],
)
def test_reference_table_errors(tmp_path, text, match):
    with pytest.raises(ReferenceTableError, match=match):
        read_reference_table(_table_folder(tmp_path, text))


def test_reference_table_missing(tmp_path):
    with pytest.raises(ReferenceTableError, match=r"reference\.csv: no reference table"):
        check_accuracy(tmp_path)


def test_reference_table_reads(tmp_path):
    t = read_reference_table(_table_folder(tmp_path, "image,reference_angle_deg\na.png,0\n\nb.png,-1.5\nc.png,2e1\n"))
    assert list(t["image"]) == ["a.png", "b.png", "c.png"]
    assert list(t["reference_angle_deg"]) == [0.0, -1.5, 20.0]


@pytest.mark.parametrize(
    "text, match",
    [
        ("tolerance_deg = -1\n", r"spec\.toml: tolerance_deg must be a finite number > 0 \(degrees\), got -1"),
        ("tolerance = 0.1\n", r"spec\.toml: unknown key\(s\) tolerance"),
        ("[markers]\npolarity = 'grey'\n", r"spec\.toml: \[markers\]: polarity must be one of"),
        ("tolerance_deg = [\n", r"spec\.toml: not valid TOML"),
    ],
)
def test_spec_errors(tmp_path, text, match):
    p = tmp_path / "spec.toml"
    p.write_text(text)
    with pytest.raises(ReferenceTableError, match=match):
        load_spec(p)


def test_correction_is_applied_by_check_and_measure(folder, tmp_path):
    # a similarity (turn + scale + shift) changes no angle: results must agree exactly,
    # while a shear must change them (so the correction is really applied)
    c, s = np.cos(0.3), np.sin(0.3)
    PlaneCorrection(np.array([[1.2 * c, -1.2 * s, 40.0], [1.2 * s, 1.2 * c, -7.0], [0, 0, 1.0]])).save(
        tmp_path / "sim.toml"
    )
    shear = PlaneCorrection(np.array([[1.0, 0.01, 0.0], [0.0, 1.0, 0.0], [0, 0, 1.0]])).save(tmp_path / "shear.json")
    spec = tmp_path / "spec.toml"
    spec.write_text('tolerance_deg = 0.02\ncorrection = "sim.toml"\n')
    plain = check_accuracy(folder, out_dir=tmp_path / "p")
    with_sim = check_accuracy(folder, out_dir=tmp_path / "q", spec=spec)
    with_shear = check_accuracy(folder, out_dir=tmp_path / "r", correction=shear)
    np.testing.assert_allclose(with_sim.table["measured_angle_deg"], plain.table["measured_angle_deg"], atol=1e-9)
    assert np.abs(with_shear.table["measured_angle_deg"] - plain.table["measured_angle_deg"]).max() > 0.05
    # independent rotations (a check folder): each the smallest turn from the reference
    m0 = measure_folder(folder, reference=folder / "reference.png", out_dir=tmp_path / "m0", order="independent")
    m1 = measure_folder(
        folder,
        reference=folder / "reference.png",
        out_dir=tmp_path / "m1",
        settings=MeasureSettings(correction=str(shear)),
        order="independent",
    )
    ok = m0.table["image"] != "reference.png"
    assert np.abs(m1.table["angle_deg"][ok] - m0.table["angle_deg"][ok]).max() > 0.05
    assert (
        main(
            [
                "measure",
                str(folder),
                "--reference",
                str(folder / "reference.png"),
                "-o",
                str(tmp_path / "m2"),
                "--correction",
                str(tmp_path / "missing.toml"),
                "-q",
            ]
        )
        == 2
    )
