"""The campaign database: records, versions, immutability, concurrency, a killed add,
bad input, and the statistics against independent computations."""

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from vision_torsion.campaign import (
    CampaignDB,
    add_reports,
    capability,
    catalogue_limits,
    compare_serials,
    control_limits,
    difference,
    export_campaign,
    figure_trend,
    fit_trend,
    list_reports,
    read_report,
    write_campaign_report,
)
from vision_torsion.cli import main
from vision_torsion.errors import CampaignError
from vision_torsion.synthetic.campaign import base_summary, campaign_summary, write_campaign_folders


@pytest.fixture(scope="module")
def base():
    return base_summary(seed=3, n_cycles=1)


@pytest.fixture()
def folders(tmp_path, base):
    return write_campaign_folders(tmp_path / "reports", n_reports=24, seed=5, life_test_every=3, base=base)


def _cli(*args):
    return main([*map(str, args)])


def test_add_then_readd_is_a_noop_and_a_changed_report_is_a_new_version(tmp_path, folders):
    db = tmp_path / "c.db"
    out = add_reports(db, folders[:5])
    assert (out.added, out.present, out.failures) == (5, 0, ())
    again = add_reports(db, folders[:5])
    assert (again.added, again.present) == (0, 5)
    summary = json.loads((folders[0] / "summary.json").read_text())
    summary["summary"]["k1"]["mean"] *= 1.01
    (folders[0] / "summary.json").write_text(json.dumps(summary))
    changed = add_reports(db, [folders[0]])
    assert changed.results[0].status == "added" and changed.results[0].version == 2
    with CampaignDB(db) as c:
        assert c.count() == 6
        assert len(c.reports(latest_only=True)) == 5
        stored = c.summary_of(changed.results[0].report_id)
    assert stored["summary"]["k1"]["mean"] == pytest.approx(summary["summary"]["k1"]["mean"], rel=0, abs=0)


def test_a_record_keeps_identity_figures_and_input_hashes(tmp_path, folders):
    db = tmp_path / "c.db"
    add_reports(db, folders[1:2])
    record = read_report(folders[1])
    truth = json.loads((folders[1] / "summary.json").read_text())
    with CampaignDB(db) as c:
        row = c.reports().iloc[0]
        figures = c.figures().set_index("figure")
    assert (row.model, row.serial) == (truth["identity"]["gear"], truth["identity"]["serial"])
    assert row.test_date == truth["identity"]["date"]
    decisions = {v["figure"]: v["decision"] for v in truth["conformity"]["verdicts"]}
    assert figures.loc["k1", "verdict"] == decisions["k1"]
    assert figures.loc["k1", "limit_kind"] == "min"
    assert row.verdict in ("pass", "fail", "not_decided")
    assert figures.loc["k1", "value"] == truth["summary"]["k1"]["mean"]
    assert figures.loc["k1", "u95"] == truth["summary"]["k1"]["mean_u95"]
    assert bool(figures.loc["k3", "withheld"]) is (truth["summary"]["k3"]["mean"] is None)
    assert len(figures) == len(truth["summary"])
    import hashlib

    assert record.inputs["summary.json"] == hashlib.sha256((folders[1] / "summary.json").read_bytes()).hexdigest()


def test_records_are_immutable(tmp_path, folders):
    db = tmp_path / "c.db"
    add_reports(db, folders[:1])
    conn = sqlite3.connect(db)
    with pytest.raises(sqlite3.IntegrityError, match="immutable"):
        conn.execute("UPDATE figures SET value = 0")
    with pytest.raises(sqlite3.IntegrityError, match="immutable"):
        conn.execute("DELETE FROM reports")
    conn.close()


def test_a_folder_that_is_not_a_report_is_named_and_the_rest_added(tmp_path, folders):
    empty = tmp_path / "empty"
    empty.mkdir()
    out = add_reports(tmp_path / "c.db", [folders[0], empty, folders[1]])
    assert out.added == 2
    assert out.failures == ((str(empty), f"{empty}: not a vision-torsion report (no summary.json)"),)


@pytest.mark.parametrize(
    "content, message",
    [
        ("{", r"summary.json: not JSON \(line 1, column 2"),
        ("[1, 2]", r"summary.json: not a report's summary \(a JSON object is expected\)"),
        ('{"schema": "something/else"}', r"not a vision-torsion analysis summary \(schema 'something/else'\)"),
        ('{"schema": "vision-torsion/analysis-summary/9"}', r"a report of summary schema version 9; this vision"),
        ('{"schema": "vision-torsion/analysis-summary/2"}', r"no 'summary' table of figures"),
    ],
)
def test_bad_summaries_are_refused_by_name(tmp_path, content, message):
    folder = tmp_path / "r"
    folder.mkdir()
    (folder / "summary.json").write_text(content)
    with pytest.raises(CampaignError, match=message):
        read_report(folder)


def test_not_a_folder(tmp_path):
    with pytest.raises(CampaignError, match=r"missing: not a folder"):
        read_report(tmp_path / "missing")


def test_a_file_that_is_not_a_database_is_refused_and_left_as_it_was(tmp_path, folders):
    db = tmp_path / "notes.db"
    db.write_text("my notes\n" * 100)
    before = db.read_bytes()
    with pytest.raises(CampaignError, match=r"notes.db: not a campaign database \(not an SQLite file\)"):
        add_reports(db, folders[:1])
    assert db.read_bytes() == before


def test_another_applications_sqlite_file_is_refused(tmp_path, folders):
    db = tmp_path / "other.db"
    conn = sqlite3.connect(db)
    conn.execute("CREATE TABLE t(x)")
    conn.commit()
    conn.close()
    with pytest.raises(CampaignError, match=r"not a campaign database \(an SQLite file of another application\)"):
        add_reports(db, folders[:1])


def test_a_newer_schema_is_refused(tmp_path, folders):
    db = tmp_path / "c.db"
    add_reports(db, folders[:1])
    conn = sqlite3.connect(db)
    conn.execute("PRAGMA user_version = 7")
    conn.close()
    with pytest.raises(CampaignError, match=r"schema version 7, made by a newer vision-torsion"):
        list_reports(db)


def test_a_missing_database_is_named_when_reading(tmp_path):
    with pytest.raises(CampaignError, match=r"nothing.db: no such campaign database"):
        list_reports(tmp_path / "nothing.db")


@pytest.fixture()
def read_only():
    """Makes a file read-only for this process, root included (root writes a file
    whatever its mode bits, but not an immutable one)."""
    made = []

    def make(path):
        if os.geteuid() != 0:
            os.chmod(path, 0o444)
            return
        if subprocess.run(["chattr", "+i", str(path)], capture_output=True).returncode != 0:
            pytest.skip("root, and this file system has no immutable attribute to make a file read-only")
        made.append(path)

    yield make
    for path in made:
        subprocess.run(["chattr", "-i", str(path)], check=True)


def test_a_read_only_database_is_one_clear_line_and_unchanged(tmp_path, folders, read_only, capsys):
    db = tmp_path / "c.db"
    add_reports(db, folders[:1])
    read_only(db)
    before = db.read_bytes()
    with pytest.raises(CampaignError, match=r"c.db: read-only: the database cannot be written") as info:
        add_reports(db, folders[1:2])
    assert info.value.reason == "read_only"
    assert _cli("campaign", "add", db, folders[1]) == 2
    assert capsys.readouterr().err.strip() == f"error: {db}: read-only: the database cannot be written"
    assert db.read_bytes() == before
    assert len(list_reports(db)) == 1  # still readable


_ADDER = """
import sys
from vision_torsion.campaign import add_reports
add_reports(sys.argv[1], sys.argv[2:])
"""


def test_four_processes_adding_at_once_lose_nothing(tmp_path, base):
    folders = write_campaign_folders(tmp_path / "reports", n_reports=40, seed=1, base=base)
    db = tmp_path / "c.db"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    procs = [subprocess.Popen([sys.executable, "-c", _ADDER, str(db), *map(str, folders[i::4])], env=env,
                              stderr=subprocess.PIPE, text=True) for i in range(4)]
    errors = [p.communicate(timeout=180)[1] for p in procs]  # every process waited for before judging
    assert [p.returncode for p in procs] == [0, 0, 0, 0], errors
    with CampaignDB(db) as c:
        assert c.count() == 40
        assert c.integrity() == "ok"
        assert set(c.reports()["source"]) == {str(f.resolve()) for f in folders}


def test_kill_9_during_an_add_leaves_a_consistent_database(tmp_path, base):
    folders = write_campaign_folders(tmp_path / "reports", n_reports=150, seed=2, base=base)
    db = tmp_path / "c.db"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    proc = subprocess.Popen([sys.executable, "-c", _ADDER, str(db), *map(str, folders)], env=env)
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline:  # kill it once it has committed something, mid-run
            time.sleep(0.05)
            if db.exists():
                try:
                    with CampaignDB(db) as c:
                        if c.count() >= 5:
                            break
                except CampaignError:
                    pass
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    with CampaignDB(db, write=True) as c:
        assert c.integrity() == "ok"
        n = c.count()
        per_report = c.figures().groupby("report_id").size()
    assert 5 <= n <= 150
    assert len(per_report) == n and (per_report == per_report.iloc[0]).all()  # no report half-written
    out = add_reports(db, folders)
    assert out.added == 150 - n and out.present == n


def test_compare_gives_differences_with_en(tmp_path, base):
    rng = np.random.default_rng(0)
    a = tmp_path / "a"
    b = tmp_path / "b"
    for folder, serial, factor in ((a, "A1", 1.0), (b, "B2", 1.1)):
        folder.mkdir()
        summary = campaign_summary(base, model="M", serial=serial, test_date="2026-03-01", stiffness_factor=factor,
                                   rng=rng)
        (folder / "summary.json").write_text(json.dumps(summary))
    db = tmp_path / "c.db"
    add_reports(db, [a, b])
    table = compare_serials(db, ["A1", "B2"]).set_index(["figure", "serial"])
    ka, kb = table.loc[("k1", "A1")], table.loc[("k1", "B2")]
    assert kb["diff"] == pytest.approx(kb["value"] - ka["value"])
    assert kb["en"] == pytest.approx(abs(kb["diff"]) / np.hypot(ka["u95"], kb["u95"]))
    assert bool(kb["significant"]) is bool(kb["en"] > 1)
    with pytest.raises(CampaignError, match="no report of serial ZZ"):
        compare_serials(db, ["A1", "ZZ"])


def test_trend_of_a_life_test_recovers_its_drift(tmp_path, base):
    folders = write_campaign_folders(tmp_path / "reports", n_reports=30, seed=4, life_test_every=2,
                                     life_drift_per_1000h=-0.05, base=base)
    db = tmp_path / "c.db"
    add_reports(db, folders)
    points, trend = figure_trend(db, "k1", by="test-hours", serial="LT-1")
    assert len(points) == 15
    k1 = base["summary"]["k1"]["mean"]
    # truth: k1 * (1 - 0.05 h / 1000); the slope within 3 of its std
    assert abs(trend.slope - (-0.05 * k1 / 1000)) < 3 * trend.slope_std
    line, half = trend.band(points["x"].to_numpy(float))
    assert np.allclose(points["trend"], line) and np.allclose(points["trend_band95"], half)
    assert (points["trend_band95"] > 0).all()
    with pytest.raises(CampaignError, match="expected 'time' or 'test-hours'"):
        figure_trend(db, "k1", by="weeks")


def test_fit_trend_matches_numpy_weighted_polyfit():
    rng = np.random.default_rng(7)
    x = np.linspace(0, 10, 12)
    std = rng.uniform(0.5, 2.0, x.size)
    y = 3.0 - 0.4 * x + rng.normal(0, std)
    trend = fit_trend(x, y, std)
    coef, cov = np.polyfit(x, y, 1, w=1 / std, cov="unscaled")
    assert trend.slope == pytest.approx(coef[0], rel=1e-10)
    assert trend.intercept == pytest.approx(coef[1], rel=1e-10)
    scale = max(1.0, trend.chi2_red)
    assert trend.slope_std == pytest.approx(np.sqrt(cov[0, 0] * scale), rel=1e-8)
    line, half = trend.band(np.array([0.0, 10.0]))
    assert line == pytest.approx(coef[1] + coef[0] * np.array([0.0, 10.0]))
    assert (half > 0).all()
    assert fit_trend([1, 2], [1, 2], [1, 1]).reason == "2 value(s) with an uncertainty: a trend needs 3"


def test_difference_rules():
    d = difference(10.0, 1.0, 12.0, 1.0)
    assert d.value == -2.0 and d.en == pytest.approx(2 / np.sqrt(2)) and d.significant
    assert difference(float("nan"), 1.0, 1.0, 1.0).reason == "a value is withheld"
    assert difference(1.0, None, 1.0, 1.0).reason == "a value has no uncertainty"


def test_control_limits_from_the_moving_range():
    values = [10.0, 12.0, 11.0, 13.0, 12.0, 11.0, 10.0, 12.0, 30.0]
    limits = control_limits(values)
    sigma = np.mean(np.abs(np.diff(values))) / 1.128
    assert limits.sigma == pytest.approx(sigma)
    assert limits.upper == pytest.approx(np.mean(values) + 3 * sigma)
    assert limits.out_of_control == (8,)
    assert control_limits(values[:7]).reason == "7 report(s): control limits need 8"


def test_capability_against_a_lower_limit():
    rng = np.random.default_rng(11)
    values = rng.normal(10.0, 0.5, 40)
    cap = capability(values, lower=8.5)
    assert cap.ppk == pytest.approx((values.mean() - 8.5) / (3 * values.std(ddof=1)))
    assert cap.ppk_lower95 < cap.ppk
    assert cap.conforming == pytest.approx(np.mean(values >= 8.5))
    assert capability(values, lower=None, upper=None).reason == "no specification limit"
    assert capability(values[:5], lower=8.5).reason == "5 report(s): a capability index needs 10"


def test_campaign_report_page(tmp_path, folders):
    db = tmp_path / "c.db"
    add_reports(db, folders)
    catalogue = tmp_path / "type.toml"
    catalogue.write_text("[gear]\nname = 'M'\nt1_nm = 0.07\nt2_nm = 0.25\nrated_torque_nm = 6.0\n"
                         "[spec]\nk1_min_nm_per_rad = 0.28\nlost_motion_max_arcmin = 180\n")
    limits = catalogue_limits(catalogue)
    assert {(limit.figure, limit.kind, limit.value) for limit in limits} >= {
        ("k1", "min", 0.28), ("lost_motion_4pct", "max", 3.0)}
    rep = write_campaign_report(db, tmp_path / "out", limits=limits)
    page = rep.path.read_text()
    assert rep.n_reports == 24 and "k1" in rep.figures
    for heading in ("Verdicts", "Conformity per figure", "Capability", "Control charts", "Batch"):
        assert f"<h2>{heading}</h2>" in page
    assert "≥ 0.28" in page and "≤ 3" in page
    # without a catalogue, the limits the reports were judged against
    default = write_campaign_report(db, tmp_path / "out2").path.read_text()
    stored = json.loads((folders[-1] / "summary.json").read_text())["conformity"]["verdicts"]
    assert f"≥ {stored[0]['limit']:g}" in default
    assert "ISO 14253-1 guard bands" in default
    with CampaignDB(db) as c:
        charted = c.figures(figure=list(rep.figures)).query("not withheld")["figure"].nunique()
    assert page.count("<img") == charted == len(rep.figures) - 1  # k3 is withheld in every report
    assert "k3: withheld in every report, nothing to chart." in page


def test_markup_in_a_serial_is_escaped(tmp_path, base):
    folder = tmp_path / "r"
    folder.mkdir()
    summary = campaign_summary(base, model="M", serial="<script>x</script>", test_date="2026-01-02",
                               stiffness_factor=1.0, rng=np.random.default_rng(0))
    (folder / "summary.json").write_text(json.dumps(summary))
    db = tmp_path / "c.db"
    add_reports(db, [folder])
    page = write_campaign_report(db, tmp_path / "out").path.read_text()
    assert "<script>" not in page and "&lt;script&gt;" in page


def test_export_csv_and_parquet(tmp_path, folders):
    db = tmp_path / "c.db"
    add_reports(db, folders[:4])
    n = export_campaign(db, tmp_path / "all.csv")
    table = pd.read_csv(tmp_path / "all.csv")
    assert len(table) == n == 4 * len(json.loads((folders[0] / "summary.json").read_text())["summary"])
    assert {"serial", "figure", "value", "u95", "report_verdict", "figure_verdict"} <= set(table.columns)
    pytest.importorskip("pyarrow")
    export_campaign(db, tmp_path / "all.parquet", fmt="parquet")
    assert pd.read_parquet(tmp_path / "all.parquet").shape == table.shape


def test_a_bad_catalogue_names_its_key(tmp_path):
    from vision_torsion.errors import SessionError

    path = tmp_path / "type.toml"
    path.write_text("[spec]\nk1_min_nm_per_rad = 'a'\n")
    with pytest.raises(SessionError, match=r"spec.k1_min_nm_per_rad"):
        catalogue_limits(path)


def test_cli_round_trip(tmp_path, folders, capsys):
    db = tmp_path / "c.db"
    assert _cli("campaign", "add", db, *folders[:6]) == 0
    assert "6 added, 0 already there, 0 not a usable report" in capsys.readouterr().out
    assert _cli("campaign", "add", db, tmp_path) == 1
    captured = capsys.readouterr()
    assert f"failed: {tmp_path}: not a vision-torsion report (no summary.json)" in captured.err
    assert _cli("campaign", "list", db, "--since", "2026-01-03") == 0
    assert len(capsys.readouterr().out.strip().splitlines()) == 1 + 4
    assert _cli("campaign", "trend", db, "--figure", "k1") == 0
    assert "trend:" in capsys.readouterr().out
    assert _cli("campaign", "report", db, "-o", tmp_path / "out") == 0
    assert (tmp_path / "out" / "campaign_report.html").is_file()
    assert _cli("campaign", "list", tmp_path / "none.db") == 2
    assert "no such campaign database" in capsys.readouterr().err


def test_analyze_adds_its_report_to_a_campaign(tmp_path, capsys):
    from vision_torsion.synthetic import simulate_measurements

    table = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, angle_std_deg=0.001, mass_std_kg=5e-5,
                                  rng=np.random.default_rng(2), n_cycles=1, torque_model="pieces")
    table.to_csv(tmp_path / "m.csv", index=False)
    db = tmp_path / "c.db"
    assert _cli("analyze", tmp_path / "m.csv", "-o", tmp_path / "out", "--campaign", db) == 0
    assert f"campaign {db}: added as version 1 (record 1)" in capsys.readouterr().out
    assert _cli("analyze", tmp_path / "m.csv", "-o", tmp_path / "out", "--campaign", db) == 0
    assert f"campaign {db}: already there (record 1)" in capsys.readouterr().out


def test_a_table_not_as_the_schema_has_it_is_a_clear_error(tmp_path, folders, capsys):
    db = tmp_path / "c.db"
    add_reports(db, folders[:1])
    conn = sqlite3.connect(db)
    conn.execute("DROP TRIGGER figures_kept")
    conn.execute("ALTER TABLE figures DROP COLUMN limit_kind")
    conn.commit()
    conn.close()
    assert _cli("campaign", "report", db, "-o", tmp_path / "out") == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {db}: ") and "limit_kind" in err and "internal error" not in err
