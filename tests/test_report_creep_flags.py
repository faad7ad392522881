"""A creep/closure finding flags every figure of its orientation: in summary.json's loop records
(each figure's flag, beside its coverage factor), in the orientation means, and with † in the
report's tables (Table 1 and the catalogue figures)."""

import json

import numpy as np
import pandas as pd
import pytest

from vision_torsion.analysis import analyze_session
from vision_torsion.report import stiffness_table, write_report
from vision_torsion.report.tables import metrics_table, orientation_flags
from vision_torsion.synthetic import simulate_measurements

CREEP = "creep or drift in this orientation"


@pytest.fixture(scope="module")
def creeping():
    """Two cycles at 0° and 90°; at 0° the angle drifts by 0.2° over the run, which its closing image shows."""
    df = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0, 90), n_cycles=2,
                               rng=np.random.default_rng(8))
    at0 = (df.orientation_deg == 0) & (df.phase != "reference")
    df.loc[at0, "angle_deg"] += 0.2 * np.linspace(0, 1, int(at0.sum()))
    zero = df[(df.orientation_deg == 0) & (df.phase == "positive_unloading") & (df.cycle == 1)].iloc[-1]
    closing = zero.copy()
    closing["image"], closing["phase"], closing["angle_deg"] = "closing.png", "closing", zero["angle_deg"] + 0.2
    df = pd.concat([df, closing.to_frame().T], ignore_index=True)
    return df, analyze_session(df, n_draws=20)


def test_every_loop_record_carries_its_figures_flags_and_coverage_factors(creeping):
    _, creeping = creeping
    assert any(i.figure == "creep" and i.orientation_deg == 0.0 for i in creeping.issues)
    records = json.loads(json.dumps(creeping.to_dict(), default=str))["loops"]
    assert len(records) == 4
    for rec in records:
        shown = creeping.figures[(creeping.figures.orientation_deg == rec["orientation_deg"])
                                 & (creeping.figures.cycle == rec["cycle"]) & creeping.figures.value.notna()]
        assert set(rec["coverage_factors"]) == set(shown.figure)
        assert all(k >= 2.0 for k in rec["coverage_factors"].values())
        creep_flagged = {f for f, why in rec["flags"].items() if CREEP in why}
        # every shown figure of the creeping orientation, and none of the other
        assert creep_flagged == (set(shown.figure) if rec["orientation_deg"] == 0.0 else set())


def test_the_orientation_means_and_the_tables_mark_the_creeping_orientation(creeping, tmp_path):
    table, creeping = creeping
    flags = orientation_flags(creeping)
    means = creeping.per_orientation.dropna(subset=["mean"])
    for o, f in zip(means.orientation_deg, means.figure):
        assert (CREEP in flags.get((o, f), "")) == (o == 0.0), (o, f)
    table1 = stiffness_table(creeping)
    assert table1.loc[table1.orientation_deg == 0.0, "flag"].str.contains(CREEP).all()
    assert not table1.loc[table1.orientation_deg == 90.0, "flag"].str.contains(CREEP).any()
    catalogue = metrics_table(creeping)
    for cells, fl in zip(catalogue[0.0], catalogue["flags"]):
        assert (CREEP in fl.get(0.0, "")) == bool(np.isfinite(cells[0])) and CREEP not in fl.get(90.0, "")
    page = write_report(table, creeping, conditions={}, out_dir=tmp_path).report_html.read_text(encoding="utf-8")
    assert page.count("unloading†") == 2 and page.count("loading†") == 4  # the four 0° rows of Table 1
    assert "† A value of the row is shown with a flag" in page
