"""Conformity verdicts (ISO 14253-1 guard bands), the [spec] table, and the test's
identity from plan through session.toml to the report, summary.json and file name."""

import json

import numpy as np
import pytest

from vision_torsion.analysis.conformity import Limit, conformity, judge
from vision_torsion.errors import AnalysisError, SessionError
from vision_torsion.report import export_name
from vision_torsion.report.analyze import analyze_table, spec_limits
from vision_torsion.session.config import config_from_dict, config_to_dict, load_config
from vision_torsion.session.plan import plan_config, plan_session
from vision_torsion.synthetic import simulate_measurements

BASE = {
    "rig": {"arm_radius_m": 0.05, "mass_tolerance_kg": 1e-4},
    "protocol": {"orientations_deg": [0.0, 60.0], "max_torque_nm": 0.36, "step_mass_kg": 0.02},
}


@pytest.mark.parametrize(
    ("kind", "value", "u95", "decision"),
    [
        # a minimum of 10: conformity proven from y - U >= 10, the boundary included
        ("min", 12.0, 2.0, "pass"),
        ("min", 12.0 + 1e-12, 2.0, "pass"),
        ("min", 12.0 - 1e-9, 2.0, "not_decidable"),
        ("min", 10.0, 2.0, "not_decidable"),
        # non-conformity proven only strictly beyond the limit extended by U
        ("min", 8.0, 2.0, "not_decidable"),
        ("min", 8.0 - 1e-9, 2.0, "fail"),
        # a maximum of 10: the mirror image
        ("max", 8.0, 2.0, "pass"),
        ("max", 8.0 + 1e-9, 2.0, "not_decidable"),
        ("max", 12.0, 2.0, "not_decidable"),
        ("max", 12.0 + 1e-9, 2.0, "fail"),
        # no uncertainty: the limit itself decides
        ("max", 10.0, 0.0, "pass"),
        ("min", 9.99, 0.0, "fail"),
    ],
)
def test_guard_band_rule_at_the_boundaries(kind, value, u95, decision):
    assert judge(Limit("k1", kind, 10.0), value, u95)[0] == decision


@pytest.mark.parametrize(("value", "u95"), [(None, 1.0), (1.0, None), (float("nan"), 1.0), (1.0, -1.0)])
def test_no_value_is_not_judged(value, u95):
    assert judge(Limit("k1", "min", 1.0), value, u95)[0] == "no_value"


def test_conformity_names_why_a_figure_has_no_value():
    summary = {"k1": {"mean": 5.0, "mean_u95": 0.5, "coverage_factor": 2.0, "flag": ""},
               "k2": {"mean": None, "mean_u95": None, "flag": "withheld: lack of fit"}}
    v = conformity(summary, [Limit("k1", "min", 4.0), Limit("k2", "min", 4.0), Limit("k3", "min", 4.0)])
    assert [x.decision for x in v] == ["pass", "no_value", "no_value"]
    assert "lack of fit" in v[1].reason and "not computed" in v[2].reason
    assert v[0].to_dict()["limit"] == 4.0 and v[0].reason == "inside the limit by 2 U"


@pytest.mark.parametrize(("kind", "value", "match"), [("low", 1.0, "kind must be 'min' or 'max'"),
                                                      ("min", float("inf"), "value must be a finite number")])
def test_bad_limit(kind, value, match):
    with pytest.raises(AnalysisError, match=match):
        Limit("k1", kind, value)


def test_spec_round_trip_and_limits_in_analysis_units():
    doc = {**BASE, "gear": {"t1_nm": 0.05, "t2_nm": 0.2, "rated_torque_nm": 5.0},
           "spec": {"k1_min_nm_per_rad": 0.2, "lost_motion_max_arcmin": 30.0, "hysteresis_loss_max_arcmin": 6.0}}
    cfg = config_from_dict(doc)
    assert config_from_dict(config_to_dict(cfg)) == cfg
    limits = spec_limits(cfg.spec, ["k1", "lost_motion_3pct", "lost_motion_4pct", "hysteresis"])
    assert [(x.figure, x.kind, x.value) for x in limits] == [
        ("k1", "min", 0.2), ("lost_motion_3pct", "max", 0.5), ("lost_motion_4pct", "max", 0.5),
        ("hysteresis_loss", "max", 0.1)]
    assert not config_from_dict(BASE).spec


@pytest.mark.parametrize(
    ("spec", "gear", "match"),
    [
        ({"k2_min_nm_per_rad": 1.0}, {}, r"spec.k2_min_nm_per_rad: needs gear.t1_nm and gear.t2_nm"),
        ({"lost_motion_max_arcmin": 1.0}, {}, r"spec.lost_motion_max_arcmin: needs gear.rated_torque_nm"),
        ({"hysteresis_loss_max_arcmin": -1.0}, {},
         r"spec.hysteresis_loss_max_arcmin: must be a finite number > 0, got -1\.0"),
        ({"k4_min": 1.0}, {}, r"spec.k4_min: unknown key"),
    ],
)
def test_spec_validation(spec, gear, match):
    with pytest.raises(SessionError, match=match):
        config_from_dict({**BASE, "gear": gear, "spec": spec})


def test_toml_date_is_kept_in_iso_form():
    import datetime

    cfg = config_from_dict({**BASE, "test": {"date": datetime.date(2026, 11, 27)}})
    assert cfg.test.date == "2026-11-27"


def test_export_name_is_a_safe_file_name():
    assert export_name({"gear": "CSF/17:100", "serial": "  ", "date": "2026-11-27"}) == \
        "CSF-17-100_2026-11-27_report.html"
    assert export_name({"operator": "J. Doe"}) is None


def test_plan_unknown_header_key(tmp_path):
    with pytest.raises(SessionError, match=r"header key\(s\) 'colour' unknown"):
        plan_session(plan_config(max_torque_nm=0.36, step_mass_kg=0.02, arm_radius_m=0.05,
                                 header={"colour": "red"}), tmp_path, pdf=False)


def test_identity_from_plan_to_session_toml_summary_and_file_name(tmp_path):
    ident = {"gear": "HFUC-20-100", "serial": "SN 7", "operator": "J. Doe", "date": "2026-11-27",
             "notes": "after run-in"}
    plan_session(plan_config(max_torque_nm=0.36, step_mass_kg=0.02, arm_radius_m=0.05, orientations_deg=(0, 60),
                             header=ident, rated_torque_nm=5.0), tmp_path / "s", pdf=False)
    cfg = load_config(tmp_path / "s" / "session.toml")
    assert (cfg.gear.name, cfg.gear.serial, cfg.test.operator, cfg.test.date, cfg.test.notes) == tuple(ident.values())
    # a [spec] added to the planned session gives the verdict table
    text = (tmp_path / "s" / "session.toml").read_text()
    (tmp_path / "s" / "session.toml").write_text(
        text + "\n[spec]\nlost_motion_max_arcmin = 1.0\nhysteresis_loss_max_arcmin = 3000.0\n")
    df = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0, 60), rng=np.random.default_rng(3))
    res = analyze_table(df, session=tmp_path / "s" / "session.toml", out_dir=tmp_path / "out", n_draws=50)
    summary = json.loads(res.files.summary_json.read_text())
    assert summary["identity"] == ident
    assert summary["files"]["export"] == "HFUC-20-100_SN-7_2026-11-27_report.html"
    assert res.files.export_html.read_text() == res.files.report_html.read_text()
    verdicts = {v["figure"]: v["decision"] for v in summary["conformity"]["verdicts"]}
    # lost motion here is tens of degrees: far beyond 1 arcmin; hysteresis loss ~27 deg < 3000 arcmin
    assert verdicts == {"lost_motion_3pct": "fail", "lost_motion_4pct": "fail", "hysteresis_loss": "pass"}
    assert "ISO 14253-1" in summary["conformity"]["rule"]
    page = res.files.report_html.read_text()
    # page 1 order: identity, then the verdict, then the flags, before the test conditions
    assert page.index("HFUC-20-100") < page.index("Verdict against the catalogue") < page.index("Flags:") \
        < page.index("Test conditions")


def test_old_session_toml_without_identity_still_reports(tmp_path):
    df = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0,), rng=np.random.default_rng(5))
    res = analyze_table(df, session=config_from_dict(BASE), out_dir=tmp_path, n_draws=30)
    summary = json.loads(res.files.summary_json.read_text())
    assert summary["identity"] == {} and "conformity" not in summary and res.files.export_html is None
    assert "not given (plan --serial" in res.files.report_html.read_text()


def test_printed_report_page_one_shows_identity_and_verdict(tmp_path):
    import shutil
    import subprocess

    from vision_torsion.session.sheet import find_chromium

    exe = find_chromium()
    if exe is None or shutil.which("pdftotext") is None:
        pytest.skip("no Chromium or pdftotext on this machine")
    doc = {**BASE, "gear": {"name": "CSF-17-100", "serial": "A-123", "t1_nm": 0.05, "t2_nm": 0.2,
                            "rated_torque_nm": 5.0},
           "test": {"operator": "J. Doe", "date": "2026-11-27"},
           "spec": {"k3_min_nm_per_rad": 4.0, "hysteresis_loss_max_arcmin": 3000.0}}
    df = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0, 60), rng=np.random.default_rng(9))
    res = analyze_table(df, session=config_from_dict(doc), out_dir=tmp_path / "out", n_draws=50)
    pdf = tmp_path / "report.pdf"
    subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                    "--disable-background-networking", "--disable-component-update", "--disable-sync",
                    f"--user-data-dir={tmp_path / 'profile'}", f"--print-to-pdf={pdf}",
                    res.files.report_html.resolve().as_uri()], capture_output=True, timeout=120, check=True)
    text = subprocess.run(["pdftotext", "-layout", "-f", "1", "-l", "1", str(pdf), "-"], capture_output=True,
                          text=True, check=True).stdout
    for expected in ("CSF-17-100", "A-123", "J. Doe", "2026-11-27", "Verdict against the catalogue", "K3",
                     "Hysteresis loss", "Decision rule: ISO 14253-1", "Flags:"):
        assert expected in text, expected


CATALOGUE = """[gear]
name = "CSF-17-100"
rated_torque_nm = 5.0
t1_nm = 0.05
t2_nm = 0.2

[spec]
k3_min_nm_per_rad = 4.0
lost_motion_max_arcmin = 1.0
"""


def test_catalogue_file_for_a_table_without_session(tmp_path):
    cat = tmp_path / "csf17.toml"
    cat.write_text(CATALOGUE)
    df = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0,), rng=np.random.default_rng(2))
    res = analyze_table(df, out_dir=tmp_path / "o", n_draws=30, catalogue=cat)
    summary = json.loads(res.files.summary_json.read_text())
    assert summary["identity"] == {"gear": "CSF-17-100"}
    assert summary["settings"]["catalogue_breaks_nm"] == [0.05, 0.2]  # K1-K3 at the catalogue's breaks
    assert {v["figure"] for v in summary["conformity"]["verdicts"]} == {"k3", "lost_motion_3pct", "lost_motion_4pct"}


def test_plan_copies_the_catalogue_into_session_toml(tmp_path):
    cat = tmp_path / "csf17.toml"
    cat.write_text(CATALOGUE)
    plan_session(plan_config(max_torque_nm=0.36, step_mass_kg=0.02, arm_radius_m=0.05, orientations_deg=(0,),
                             catalogue=cat, header={"serial": "A-1"}), tmp_path / "s", pdf=False)
    cfg = load_config(tmp_path / "s" / "session.toml")
    assert (cfg.gear.name, cfg.gear.serial, cfg.gear.rated_torque_nm, cfg.gear.t2_nm) == ("CSF-17-100", "A-1", 5.0, 0.2)
    assert cfg.spec.lost_motion_max_arcmin == 1.0 and cfg.spec.k3_min_nm_per_rad == 4.0
    with pytest.raises(SessionError, match=r"rated_torque_nm 6 differs from the catalogue file's 5"):
        plan_session(plan_config(max_torque_nm=0.36, step_mass_kg=0.02, arm_radius_m=0.05, catalogue=cat,
                                 rated_torque_nm=6.0), tmp_path / "t", pdf=False)


def test_catalogue_conflicting_with_session_toml(tmp_path):
    cat = tmp_path / "c.toml"
    cat.write_text("[gear]\nratio = 100.0\n")
    df = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0,), rng=np.random.default_rng(2))
    cfg = config_from_dict({**BASE, "gear": {"ratio": 50.0}})
    with pytest.raises(SessionError, match=r"gear.ratio: session.toml gives 50.0, the catalogue file .* gives 100.0"):
        analyze_table(df, session=cfg, out_dir=tmp_path / "o", n_draws=30, catalogue=cat)


@pytest.mark.parametrize(("text", "match"), [
    ("[rig]\narm_radius_m = 1.0\n", r"rig: unknown key"),
    ("[spec]\nk1_min_nm_per_rad = 1.0\n", r"spec.k1_min_nm_per_rad: needs gear.t1_nm and gear.t2_nm"),
])
def test_catalogue_file_validation(tmp_path, text, match):
    from vision_torsion.session.config import load_catalogue

    cat = tmp_path / "c.toml"
    cat.write_text(text)
    with pytest.raises(SessionError, match=match):
        load_catalogue(cat)


def test_analyze_command_prints_the_verdict_and_the_report_to_send(tmp_path, capsys):
    from vision_torsion.cli import main

    cat = tmp_path / "csf17.toml"
    cat.write_text(CATALOGUE)
    table = tmp_path / "t.csv"
    simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0,),
                          rng=np.random.default_rng(2)).to_csv(table, index=False)
    assert main(["analyze", str(table), "--catalogue", str(cat), "-o", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    # lost motion here is tens of degrees against a 1 arcmin limit: the gear fails
    assert "verdict against the catalogue: FAIL: " in out and " 2 fail," in out
    assert f"report to send: {tmp_path / 'o' / 'CSF-17-100_report.html'}" in out


def test_the_ready_catalogue_is_found_by_name():
    from vision_torsion.session.config import load_catalogue

    gear, spec = load_catalogue("paper_demo")
    assert (gear.t1_nm, gear.t2_nm) == (0.15, 0.30)
    assert spec.k1_min_nm_per_rad == 0.28 and spec.hysteresis_loss_max_arcmin == 1800.0
