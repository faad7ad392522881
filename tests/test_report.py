"""write_report: files, Table 1 layout, self-contained HTML, failure lists."""

import json
import re

import numpy as np
import pandas as pd
import pytest

from vision_torsion.analysis import analyze_session
from vision_torsion.errors import AnalysisError
from vision_torsion.report import STIFFNESS_TABLE_COLUMNS, write_report
from vision_torsion.synthetic import simulate_measurements


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    df = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0, 60), rng=np.random.default_rng(4))
    df.loc[7, ["status", "message"]] = ["failed", "marker not found: 1 of 2 markers"]
    df = df[~((df.orientation_deg == 60) & (df.phase == "positive_loading"))].reset_index(drop=True)
    a = analyze_session(df, n_draws=50, fit_bouc_wen=False)
    out = tmp_path_factory.mktemp("rep")
    files = write_report(df, a, conditions={"rig": "synthetic", "arm_radius_m": 0.05, "g_m_per_s2": 9.81},
                         out_dir=out, failures=[{"image": "x.png", "message": "unreadable file"}],
                         extra_sections=[("Stiffness curve", "<p id='extra'>curve</p>")])
    return df, a, files


def test_files_written(report):
    _, _, files = report
    for p in (files.summary_json, files.stiffness_table_csv, files.report_html, *files.figures):
        assert p.exists() and p.stat().st_size > 0
    assert {p.name for p in files.figures} >= {"loops_overlay.svg", "fit_residuals.svg"}
    assert not list(files.out_dir.glob(".*.tmp"))  # atomic writes leave no temporaries


def test_stiffness_table_like_table1(report):
    _, _, files = report
    t = pd.read_csv(files.stiffness_table_csv)
    assert list(t.columns) == STIFFNESS_TABLE_COLUMNS
    assert len(t) == 8
    row = t[(t.orientation_deg == 0) & (t.phase == "positive_unloading")].iloc[0]
    assert row.torque_from_nm == pytest.approx(0.36) and row.torque_to_nm == 0
    assert row.stiffness_nm_per_rad == pytest.approx(4.4, rel=0.01)
    assert row.stiffness_nm_per_arcmin == pytest.approx(row.stiffness_nm_per_rad * np.pi / 180 / 60)
    missing = t[(t.orientation_deg == 60) & (t.phase == "positive_loading")].iloc[0]
    assert np.isnan(missing.stiffness_nm_per_rad) and np.isnan(missing.hysteresis_deg)


def test_summary_json(report):
    df, a, files = report
    d = json.loads(files.summary_json.read_text())
    assert d["conditions"]["arm_radius_m"] == 0.05
    assert d["counts"]["images"] == len(df) and d["counts"]["images_failed"] == 2
    assert {f["image"] for f in d["failed_images"]} == {df.loc[7, "image"], "x.png"}
    # the failed image leaves a gap in its loop: that loop's hysteresis is withheld, not interpolated
    assert d["summary"]["hysteresis"]["n"] == 0
    assert any("gap" in i["reason"] for i in d["issues"] if i["figure"] == "hysteresis")
    assert "NaN" not in files.summary_json.read_text()


def test_html_self_contained_and_complete(report):
    _, _, files = report
    page = files.report_html.read_text()
    assert not re.search(r"(src|href)=\"(https?:)?//", page)  # nothing fetched from the network
    assert "<script" not in page
    assert page.count("data:image/svg+xml;base64,") == 4  # overlay, fit residuals, stiffness, orientation
    for text in ("Test conditions", "Failed images", "unreadable file", "marker not found: 1 of 2 markers",
                 "Figures withheld or flagged, and why", "phase(s) positive_loading missing", "id='extra'",
                 "Stiffness per phase and orientation"):
        assert text in page, text


def test_loop_captions_name_only_the_fits_drawn(report):
    """The loop figures draw the bilinear fit only (Bouc–Wen, fitted on request, is judged in
    the lack-of-fit table): the captions must not name a fit that is not drawn."""
    _, _, files = report
    page = files.report_html.read_text()
    assert "each loop's bilinear fit (thin black line)" in page
    assert "Bouc–Wen fit" not in page


def test_bad_conditions_and_failures(report, tmp_path):
    df, a, _ = report
    with pytest.raises(AnalysisError, match="conditions must be a dict"):
        write_report(df, a, conditions=None, out_dir=tmp_path)
    with pytest.raises(AnalysisError, match="failures must have 'image' and 'message'"):
        write_report(df, a, conditions={}, out_dir=tmp_path, failures=[{"file": "a"}])
