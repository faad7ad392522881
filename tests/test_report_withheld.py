"""What the report and the command line say about withheld figures (issue 14: no
"not computable" for a figure that is computable, no rejected model shown as valid, no
traceback for an inverted angle sign)."""

import numpy as np
import pytest

from vision_torsion.analysis import analyze_session
from vision_torsion.report import stiffness_table, write_report
from vision_torsion.report.analyze import describe_withheld, withheld_by_kind
from vision_torsion.synthetic import simulate_measurements

# the demo's kind of loop: a stiffness switch at tau_c inside each loading phase
TRUTH = dict(k_u=4.4, k_l=0.3, tau_c=0.15)


@pytest.fixture(scope="module")
def switching():
    df = simulate_measurements(**TRUTH, orientations_deg=(0, 60), rng=np.random.default_rng(21))
    return df, analyze_session(df, n_draws=30)


def test_withheld_figures_are_counted_by_what_the_reader_is_told(switching):
    _, a = switching
    counts = withheld_by_kind(a)
    # per loop: the straight lines through the two loading phases do not fit (given another way), and
    # K3/T2 do not apply to a curve with one break (two segments); nothing is "not computable"
    assert counts == {"rejected": 4, "not_applicable": 4, "not_computable": 0}
    assert {i.figure for i in a.issues if i.kind == "rejected"} == {"k_negative_loading", "k_positive_loading"}
    assert {i.figure for i in a.issues if i.kind == "not_applicable"} == {"k3", "t2"}
    line = describe_withheld(counts, 0)
    assert line.startswith("8 figure(s) withheld: 4 do not fit their data (given another way), "
                           "4 not applicable to these data, 0 not computable")


def test_table1_gives_a_switching_phase_as_its_two_stiffnesses_and_secant(switching, tmp_path):
    df, a = switching
    t = stiffness_table(a).set_index(["orientation_deg", "phase"])
    nl = t.loc[(0.0, "negative_loading")]
    assert np.isnan(nl["stiffness_nm_per_rad"])                     # the straight line is withheld ...
    assert nl["stiffness_below_nm_per_rad"] == pytest.approx(0.3, rel=0.01)   # ... given as below/above
    assert nl["stiffness_above_nm_per_rad"] == pytest.approx(4.4, rel=0.01)
    assert nl["switch_torque_nm"] == pytest.approx(0.15, rel=0.05)
    assert np.isfinite(nl["secant_nm_per_rad"]) and nl["n_cycles"] == 1
    page = write_report(df, a, conditions={}, out_dir=tmp_path).report_html.read_text()
    import re

    table1 = page[page.index("Stiffness per phase and orientation"):]
    table1 = table1[:table1.index("</table>")]
    rows = [re.findall(r"<td[^>]*>(.*?)</td>", r) for r in re.findall(r"<tr>(.*?)</tr>", table1)]
    nl_row = next(r for r in rows if r and r[1] == "negative loading")
    # one number per cell: the straight line withheld, the two stiffnesses and the switch in their columns
    assert nl_row[3] == "—" and nl_row[4].startswith(("0.29", "0.30")) and nl_row[5].startswith(("4.3", "4.4"))
    assert float(nl_row[6]) == pytest.approx(0.15, rel=0.05)
    assert all(len(cell) <= 24 for r in rows for cell in r)  # no prose in Table 1
    assert "could not be computed" not in page and "not computed" not in page
    assert "does not fit its data" in page and "not applicable to these data" in page


def test_inverted_angle_sign_on_the_command_line(tmp_path, capsys):
    import logging

    from vision_torsion.cli import main

    df = simulate_measurements(**TRUTH, orientations_deg=(0,), rng=np.random.default_rng(22))
    df.assign(angle_deg=-df["angle_deg"]).to_csv(tmp_path / "m.csv", index=False)
    own = logging.getLogger("vision_torsion")
    level, handlers = own.level, list(own.handlers)
    try:
        code = main(["analyze", str(tmp_path / "m.csv"), "-o", str(tmp_path / "out")])
    finally:  # the command line configures the package's logger: give it back
        own.setLevel(level)
        for h in [h for h in own.handlers if h not in handlers]:
            own.removeHandler(h)
    out = capsys.readouterr()
    assert code == 0 and "Traceback" not in out.err
    assert "angle_sign looks inverted; set angle_sign = -1" in out.out
    page = (tmp_path / "out" / "report.html").read_text()
    assert "angle_sign looks inverted; set angle_sign = -1" in page[:page.index("<h2>")]  # said at the top


def test_orientation_means_of_one_cycle_are_flagged_in_the_report(switching, tmp_path):
    """One cycle per orientation: every orientation mean is a mean of one loop (issue 14)."""
    df, a = switching
    po = a.per_orientation
    with_u = np.isfinite(po["u95"].to_numpy(float))  # T1 (a profiled break) has no u95 to qualify
    assert (po["n_cycles"] == 1).all() and with_u.sum() >= 40
    assert po["flag"][with_u].str.contains("mean of one loop").all() and (po["flag"][~with_u] == "").all()
    page = write_report(df, a, conditions={}, out_dir=tmp_path).report_html.read_text()
    # said once for the table (issue 28: a † on every value said nothing), not on every cell
    assert page.count("One loop per orientation: each orientation mean is that loop's value") == 1
    assert "repeatability between loops is not observed" in page
    from vision_torsion.report.tables import metrics_table

    flagged_cells = sum(len(fl) for fl in metrics_table(a)["flags"])
    table = page[page.index("Catalogue metrics and model fits"):]
    table = table[:table.index("</table>")]
    assert table.count("†</td>") == flagged_cells < with_u.sum()  # † only where the loop value is flagged
