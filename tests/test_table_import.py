"""Tables from anywhere: separators, decimal commas, column maps, units from headers,
optional columns, and a plain torque/angle record whose phases come from its reversals."""

import numpy as np
import pandas as pd
import pytest

from vision_torsion.errors import MeasurementsError
from vision_torsion.measurements import MEASUREMENT_COLUMNS
from vision_torsion.report.analyze import analyze_table
from vision_torsion.synthetic import simulate_measurements
from vision_torsion.table_import import import_table, parse_column_map, phases_from_torque


@pytest.fixture(scope="module")
def table():
    return simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0, 60),
                                 rng=np.random.default_rng(11))


def foreign(df, *, angle_scale=60.0, angle_unit="arcmin"):
    """The table as another rig writes it: its own headers, the angle in another unit."""
    return pd.DataFrame({
        "Orientation [deg]": df["orientation_deg"], "Torque [N m]": df["torque_nm"],
        f"Angle [{angle_unit}]": df["angle_deg"] * angle_scale, "sT": df["torque_std_nm"],
        "sA": df["angle_std_deg"] * angle_scale, "Phase": df["phase"], "Cycle": df["cycle"], "Step": df["step"]})


MAP = "orientation=Orientation [deg],torque_std=sT,angle_std=sA,phase=Phase,cycle=Cycle,step=Step"


@pytest.mark.parametrize(("sep", "decimal"), [(",", "."), (";", ","), ("\t", "."), ("\t", ",")])
def test_separators_and_decimal_comma_give_the_measurements(tmp_path, table, sep, decimal):
    path = tmp_path / "t.csv"
    path.write_text(foreign(table).to_csv(sep=sep, decimal=decimal, index=False))
    got = import_table(path, column_map=parse_column_map(MAP)).frame
    assert list(got.columns[:len(MEASUREMENT_COLUMNS)]) == list(MEASUREMENT_COLUMNS)
    # arcmin back to degrees: equal to rounding of the float text (1e-12 relative)
    np.testing.assert_allclose(got["angle_deg"], table["angle_deg"], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(got["angle_std_deg"], table["angle_std_deg"], rtol=1e-12)
    np.testing.assert_allclose(got["torque_nm"], table["torque_nm"], rtol=1e-12, atol=1e-15)
    assert list(got["phase"]) == list(table["phase"])
    assert (got["status"] == "ok").all() and list(got.index[:2]) == [2, 3]  # CSV lines kept


@pytest.mark.parametrize(("unit", "scale"), [("deg", 1.0), ("°", 1.0), ("arcmin", 60.0), ("arcsec", 3600.0),
                                             ("rad", np.pi / 180), ("mrad", 1000 * np.pi / 180)])
def test_angle_units_from_the_header(tmp_path, table, unit, scale):
    path = tmp_path / "t.csv"
    foreign(table, angle_scale=scale, angle_unit=unit).to_csv(path, index=False)
    got = import_table(path, column_map=parse_column_map(MAP)).frame
    np.testing.assert_allclose(got["angle_deg"], table["angle_deg"], rtol=1e-12, atol=1e-12)


def test_torque_in_millinewton_metres_and_unit_in_the_name(tmp_path, table):
    df = pd.DataFrame({"torque_mNm": table["torque_nm"] * 1000, "angle_rad": np.radians(table["angle_deg"])})
    path = tmp_path / "t.csv"
    df.to_csv(path, index=False)
    got = import_table(path, angle_std_deg=0.001, torque_std_nm=1e-4).frame
    assert got["torque_nm"].abs().max() == pytest.approx(table["torque_nm"].abs().max())


def test_a_semicolon_file_missing_a_column_lists_the_columns_it_has(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("Zeit;Torque [N m];Winkel [deg]\n0;1,0;2,0\n")
    with pytest.raises(MeasurementsError, match=r"no angle column found among 'Zeit', 'Torque \[N m\]', 'Winkel"):
        import_table(path)


@pytest.mark.parametrize(
    ("text", "kw", "match"),
    [
        ("torque,angle [deg]\n1,2\n", {}, r"column 'torque' has no unit; write it in the header"),
        ("torque [lbf in],angle [deg]\n1,2\n", {}, r"unit 'lbf in' not known for torque; expected one of N·m"),
        ("torque [N m],angle [grad]\n1,2\n", {}, r"unit 'grad' not known for angle"),
        ("torque [N m],moment [N m],angle [deg]\n1,2,3\n", {},
         r"'torque \[N m\]', 'moment \[N m\]' could each be the torque"),
        ("torque [N m],angle [deg]\n1,2\n", {"column_map": {"torque": "T"}}, r"--columns torque='T': no such"),
        ("torque [N m],angle [deg]\n1,2\n", {}, r"no angle_std_deg column and no 1σ given"),
        ("torque [N m],angle [deg]\n1,2\n3\n", {}, r"line 3: 1 field\(s\), the header has 2 \(separator comma\)"),
        ("torque [N m],angle [deg]\n1,x\n", {"angle_std_deg": 0.1, "torque_std_nm": 0.1},
         r"line 2: column 'angle \[deg\]' is not a number \('x'\)"),
        ("torque [N m],angle [deg]\n0,0\n1,1\n2,2\n", {"angle_std_deg": 0.1, "torque_std_nm": 0.1},
         r"the torque never runs from one extreme to the other and back"),
        ("torque [N m],angle [deg],cycle\n0,0,1\n", {"angle_std_deg": 0.1, "torque_std_nm": 0.1},
         r"a cycle or step column without a phase column"),
        ("", {}, r"empty, or no header on line 1"),
    ],
)
def test_import_errors(tmp_path, text, kw, match):
    path = tmp_path / "t.csv"
    path.write_text(text)
    with pytest.raises(MeasurementsError, match=match):
        import_table(path, **kw)


def test_missing_file(tmp_path):
    with pytest.raises(MeasurementsError, match="no such file"):
        import_table(tmp_path / "none.csv")


@pytest.mark.parametrize(("text", "what", "match"), [
    ("torque", "--columns", r"--columns: 'torque' is not KEY=VALUE"),
    ("speed=v", "--columns", r"--columns: unknown key 'speed'"),
    ("torque=a,torque=b", "--columns", r"--columns: 'torque' given twice"),
    ("phase=deg", "--units", r"--units: unknown key 'phase'; expected one of torque, angle"),
])
def test_column_map_errors(text, what, match):
    with pytest.raises(MeasurementsError, match=match):
        parse_column_map(text, what=what)


def test_units_option_for_headers_without_one(tmp_path, table):
    path = tmp_path / "t.csv"
    pd.DataFrame({"T": table["torque_nm"], "A": table["angle_deg"] * 60}).to_csv(path, index=False)
    got = import_table(path, column_map={"torque": "T", "angle": "A"}, units={"torque": "N m", "angle": "arcmin"},
                       angle_std_deg=0.001, torque_std_nm=1e-4).frame
    assert got["angle_deg"].max() == pytest.approx(table["angle_deg"].max(), rel=1e-12)


def record(table, orientation=0.0):
    d = table[table["orientation_deg"] == orientation]
    return d, pd.DataFrame({"torque [N m]": d["torque_nm"].to_numpy(), "angle [deg]": d["angle_deg"].to_numpy()})


def test_two_column_record_phases_match_the_protocol(tmp_path, table):
    d, rec = record(table)
    path = tmp_path / "r.csv"
    rec.to_csv(path, index=False)
    got = import_table(path, angle_std_deg=0.001, torque_std_nm=1e-4)
    truth = dict(zip(range(2, len(d) + 2), d["phase"]))
    found = dict(zip(got.frame.index, got.frame["phase"]))
    assert len(found) == len(got.frame)  # each sample in one phase only, as a photograph of a plan is
    torque = dict(zip(range(2, len(d) + 2), d["torque_nm"]))
    other = [line for line, ph in found.items() if truth[line] != ph]
    # a sample of the protocol's other phase only at a turning point (±Tmax), where both phases hold one
    assert all(abs(abs(torque[line]) - 0.36) < 0.01 for line in other)
    assert len(other) <= 4 * len(set(d["cycle"]))
    assert any("runs to +Tmax first; ∮τ dθ > 0" in n for n in got.notes)


def test_record_run_the_other_way_is_detected(tmp_path, table):
    d, rec = record(table)
    rec["angle [deg]"] *= -1  # the loop runs the other way round in the torque-angle plane
    path = tmp_path / "r.csv"
    rec.to_csv(path, index=False)
    notes = import_table(path, angle_std_deg=0.001, torque_std_nm=1e-4).notes
    assert any("the loop runs the other way round" in n for n in notes)


def test_record_starting_negative_and_cycles_counted():
    tau = [0, -1, -2, -1, 0, 1, 2, 1, 0, -1, -2, -1, 0, 1, 2, 1, 0, -1, -2, -1, 0]
    r = phases_from_torque(tau)
    assert r.first == "negative"
    assert {c for _, _, c in r.rows} == {0, 1, 2}
    assert [ph for i, ph, c in r.rows if i == 5] == ["positive_loading"]
    assert [ph for i, ph, c in r.rows if i == 4] == ["negative_unloading"]  # zero: ends the unloading
    assert r.left_out == 3  # sample 1 of the first loading (0 is the reference), 19 and 20 of the last sweep


def test_noise_on_a_logged_torque_is_not_a_reversal():
    rng = np.random.default_rng(7)
    t = np.linspace(0, 2, 801)
    tau = np.sin(2 * np.pi * t) + rng.normal(0, 0.005, t.size)  # two periods with jitter
    tau[0] = 0.0
    r = phases_from_torque(tau)
    assert max(c for _, _, c in r.rows) == 1  # 0 -> +1 is the virgin quarter; one full loop, then a partial one
    names = [ph for _, ph, _ in r.rows if ph != "reference"]
    assert names[0] == "positive_unloading" and names[-1] == "positive_loading"


def test_analyze_a_two_column_record_gives_the_protocol_figures(tmp_path, table):
    d, rec = record(table)
    path = tmp_path / "r.tsv"
    rec.to_csv(path, sep="\t", index=False)
    res = analyze_table(path, out_dir=tmp_path / "o", n_draws=50, angle_std_deg=0.001, torque_std_nm=3e-4)
    ref = analyze_table(d.reset_index(drop=True), out_dir=tmp_path / "ref", n_draws=50)
    for fig in ("k_positive_unloading", "bilinear_k_u", "bilinear_tau_c", "hysteresis"):
        a, b = res.analysis.summary[fig], ref.analysis.summary[fig]
        # the same samples, plus the boundary ones in both phases: within one standard uncertainty
        assert a["mean"] == pytest.approx(b["mean"], abs=b["mean_std"]), fig
    assert "table import" in res.files.report_html.read_text()


def test_analyze_command_reads_a_semicolon_table_with_a_column_map(tmp_path, table, capsys):
    from vision_torsion.cli import main

    path = tmp_path / "t.csv"
    path.write_text(foreign(table).to_csv(sep=";", decimal=",", index=False))
    code = main(["analyze", str(path), "-o", str(tmp_path / "o"), "--columns", MAP])
    out = capsys.readouterr().out
    assert code == 0 and "table: separator semicolon, decimal comma" in out
    assert "angle_deg from 'Angle [arcmin]' (arcmin → deg)" in out
    code = main(["analyze", str(path), "-o", str(tmp_path / "o"), "--units", "phase=x"])
    assert code == 2 and "--units: unknown key 'phase'" in capsys.readouterr().err


def test_uncertainty_columns_found_by_name_in_the_value_unit(tmp_path, table):
    path = tmp_path / "t.csv"
    pd.DataFrame({"Torque [mN m]": table["torque_nm"] * 1000, "u(torque)": table["torque_std_nm"] * 1000,
                  "Angle [arcmin]": table["angle_deg"] * 60, "angle_std": table["angle_std_deg"] * 60,
                  "phase": table["phase"], "cycle": table["cycle"], "step": table["step"],
                  "orientation_deg": table["orientation_deg"]}).to_csv(path, index=False)
    got = import_table(path).frame
    np.testing.assert_allclose(got["torque_std_nm"], table["torque_std_nm"], rtol=1e-12)
    np.testing.assert_allclose(got["angle_std_deg"], table["angle_std_deg"], rtol=1e-12)
    assert list(got["phase"]) == list(table["phase"])


def test_two_candidate_uncertainty_columns_are_refused(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("torque [N m],angle [deg],angle_std [deg],sigma angle [deg]\n0,0,1,1\n")
    with pytest.raises(MeasurementsError, match=r"could each be the angle uncertainty; name one \(--columns angle_std"):
        import_table(path)


def test_a_labelled_loop_run_the_other_way_round_is_noted(tmp_path, table):
    d = table[table["orientation_deg"] == 0].copy()
    swap = {"positive_unloading": "positive_loading", "positive_loading": "positive_unloading",
            "negative_loading": "negative_unloading", "negative_unloading": "negative_loading"}
    path = tmp_path / "t.csv"
    foreign(d).to_csv(path, index=False)
    assert not any("other way round" in n for n in import_table(path, column_map=parse_column_map(MAP)).notes)
    # each branch labelled as its partner, in the reverse order: the same points, the loop run backwards
    d["step"] = d.groupby(["cycle", "phase"])["step"].transform(lambda st: st.max() - st)
    d["phase"] = d["phase"].map(lambda p: swap.get(p, p))
    foreign(d).to_csv(path, index=False)
    notes = import_table(path, column_map=parse_column_map(MAP)).notes
    assert any(n.startswith("orientation_deg 0, cycle 1: ∮τ dθ ≤ 0") for n in notes)
