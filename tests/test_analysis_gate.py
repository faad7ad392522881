"""Issue 14: a figure is shown only if it fits; checks on the data; test/catalogue inputs.

Truth comes from closed forms (bilinear, three-segment, Masing loops written here,
independent of the analysis' models) with seeded noise.
"""

import math

import numpy as np
import pandas as pd
import pytest

from vision_torsion.analysis import (
    analyze_session,
    fit_catalogue_breaks,
    fit_fixed_breaks,
    fit_preisach,
    fit_switch,
    lack_of_fit,
    orientation_anova,
)
from vision_torsion.analysis.checks import angle_sign_inverted, closure_checks
from vision_torsion.errors import SessionError
from vision_torsion.session.config import config_from_dict
from vision_torsion.synthetic import simulate_measurements

TRUTH = dict(k_u=4.4, k_l=0.3, tau_c=0.15)
FAST = dict(n_draws=40)
LOOP = np.concatenate([np.linspace(0.36, -0.36, 37), np.linspace(-0.34, 0.36, 36)])


def _masing(tau, branch):
    """Masing loop of a virgin curve `branch` (odd), started on the major loop at tau[0] = max."""
    out, d, prev = [], -1.0, tau[0]
    rev, th_rev = tau[0], branch(tau[0])
    for t in tau:
        s = np.sign(t - prev)
        if s != 0 and s != d:
            rev, th_rev, d = prev, out[-1], s
        out.append(th_rev + 2 * branch((t - rev) / 2))
        prev = t
    return np.array(out)


def test_gate_accepts_noise_and_rejects_a_switch():
    rng = np.random.default_rng(0)
    tau = np.linspace(0, 0.36, 19)
    sigma = 1e-4
    line = tau / 4.4 + rng.normal(0, sigma, tau.size)
    fit = np.polyval(np.polyfit(tau, line, 1), tau)
    ok = lack_of_fit(line - fit, angle_std_rad=sigma, torque_std_nm=0.0, compliance_rad_per_nm=1 / 4.4, n_params=2)
    assert not ok.rejected and 0.3 < ok.reduced_chi2 < 2.5  # χ²_17/17: 99.9 % within these bounds
    bent = np.where(tau < 0.15, tau / 0.3, 0.15 / 0.3 + (tau - 0.15) / 4.4) + rng.normal(0, sigma, tau.size)
    fit = np.polyval(np.polyfit(tau, bent, 1), tau)
    bad = lack_of_fit(bent - fit, angle_std_rad=sigma, torque_std_nm=0.0, compliance_rad_per_nm=1.0, n_params=2)
    assert bad.rejected and bad.inflation > 10


def test_switch_gives_the_two_stiffnesses():
    rng = np.random.default_rng(1)
    tau = -np.linspace(0, 0.36, 19)  # a negative loading phase, from its starting image
    th = -np.where(-tau < 0.15, -tau / 0.3, 0.5 + (-tau - 0.15) / 4.4) + rng.normal(0, 1e-5, tau.size)
    r = fit_switch(tau, th, angle_std_rad=np.full(tau.size, 1e-5), torque_std_nm=np.zeros(tau.size))
    # 1e-5 rad noise on a 0.5 rad span: the stiffnesses to 0.1 %
    assert r["k_below"] == pytest.approx(0.3, rel=1e-3) and r["k_above"] == pytest.approx(4.4, rel=1e-3)
    assert 0.137 < r["switch_nm"] < 0.157  # between the levels bracketing the true switch


@pytest.mark.parametrize("name", ["bilinear", "masing", "stiffening"])
def test_preisach_fits_the_loops_it_should(name):
    from vision_torsion.analysis import bilinear_response

    if name == "bilinear":
        th = bilinear_response(LOOP, **TRUTH)
    elif name == "masing":  # softening after each reversal (Iwan / Maxwell-slip)
        th = _masing(LOOP, lambda x: x / 4.4 + 0.05 * (np.abs(x) / 0.1 - np.log1p(np.abs(x) / 0.1)) * np.sign(x))
    else:  # a gear that stiffens with torque (reversible), with the bilinear hysteresis on top
        th = bilinear_response(LOOP, **TRUTH) + 0.04 * np.tanh(LOOP / 0.08)
    rng = np.random.default_rng(2)
    noisy = th + rng.normal(0, 1e-5, th.size)
    f = fit_preisach(LOOP, noisy, angle_std_rad=1e-5, torque_std_nm=0.0)
    assert not f.check.rejected, f.check
    assert np.all(f.weight_rad >= 0)


def test_preisach_rejects_a_creeping_loop():
    from vision_torsion.analysis import bilinear_response

    th = bilinear_response(LOOP, **TRUTH) + np.radians(0.2) * np.linspace(0, 1, LOOP.size)
    f = fit_preisach(LOOP, th, angle_std_rad=np.radians(0.001), torque_std_nm=0.0)
    assert f.check.rejected


def _three_segment(x):
    return np.minimum(x, 0.1) / 1000 + np.clip(x - 0.1, 0, 0.15) / 2500 + np.maximum(x - 0.25, 0) / 4000


def test_catalogue_stiffness_with_fixed_and_fitted_breaks():
    x = np.arange(0, 19) * 0.02
    rng = np.random.default_rng(3)
    tau = np.concatenate([x, -x])
    th = np.concatenate([_three_segment(x), -_three_segment(x)]) + rng.normal(0, 1e-7, 2 * x.size)
    branch = np.repeat([1, -1], x.size)
    r = fit_fixed_breaks(tau, th, branch=branch, breaks_nm=(0.1, 0.25), angle_std_rad=1e-7, torque_std_nm=0.0)
    assert r["k"] == pytest.approx([1000, 2500, 4000], rel=0.01)  # the benchmark's 1 % target
    assert not r["check"].rejected
    two = fit_catalogue_breaks(tau, th, branch=branch, angle_std_rad=1e-7, torque_std_nm=0.0)
    assert two["n_breaks"] == 2 and two["breaks_nm"] == pytest.approx([0.1, 0.25], abs=0.01)
    lin2 = np.concatenate([np.minimum(x, 0.15) / 1000 + np.maximum(x - 0.15, 0) / 4000] * 1)
    th2 = np.concatenate([lin2, -lin2]) + rng.normal(0, 1e-7, 2 * x.size)
    one = fit_catalogue_breaks(tau, th2, branch=branch, angle_std_rad=1e-7, torque_std_nm=0.0)
    assert one["n_breaks"] == 1 and len(one["k"]) == 2  # "two segments", not a failure


def test_orientation_anova_false_alarms_and_one_cycle():
    rng = np.random.default_rng(4)
    hits = [orientation_anova(rng.normal(1.0, 0.02, (6, 3)))["significant"] for _ in range(400)]
    assert np.mean(hits) <= 0.08  # nominal 5 %; 400 draws: sd 1.1 %
    effect = 1 + 0.1 * np.cos(np.radians([0, 60, 120, 180, 240, 300]))[:, None]
    found = [orientation_anova(effect * rng.normal(1.0, 0.02, (6, 3)))["significant"] for _ in range(100)]
    assert np.mean(found) >= 0.9
    assert orientation_anova([[1.0], [1.1]])["significant"] is None


@pytest.fixture(scope="module")
def bilinear_table():
    return simulate_measurements(**TRUTH, orientations_deg=(0, 60), rng=np.random.default_rng(5))


def test_phase_ranges_start_at_the_starting_image_and_switches_are_split(bilinear_table):
    a = analyze_session(bilinear_table, **FAST)
    ph = a.phases.set_index(["orientation_deg", "phase"])
    nl = ph.loc[(0.0, "negative_loading")]
    assert nl["torque_from_nm"] == 0.0 and nl["torque_to_nm"] == pytest.approx(-0.36, abs=0.01)
    assert np.isnan(nl["stiffness_nm_per_rad"])  # one line through a switch is withheld ...
    assert nl["stiffness_below_nm_per_rad"] == pytest.approx(0.3, rel=0.01)  # ... its two stiffnesses are given
    assert nl["stiffness_above_nm_per_rad"] == pytest.approx(4.4, rel=0.01)
    assert nl["secant_nm_per_rad"] == pytest.approx(0.36 / (0.15 / 0.3 + 0.21 / 4.4), rel=0.02)
    assert ph.loc[(0.0, "positive_unloading")]["stiffness_nm_per_rad"] == pytest.approx(4.4, rel=0.01)
    assert not any("bilinear" in i.figure for i in a.issues)  # the right model is not flagged


def test_a_failed_zero_torque_image_withholds_what_would_interpolate(bilinear_table):
    df = bilinear_table.copy()
    # the zero after unloading (this simulator photographs it twice: end of one phase, start of the next)
    i = df.index[(df.orientation_deg == 0) & df.phase.isin(["positive_unloading", "negative_loading"])
                 & (df.torque_nm == 0)]
    assert len(i) == 2
    df.loc[i, ["status", "message"]] = ["failed", "marker not found"]
    a = analyze_session(df, **FAST)
    row = a.loops.set_index("orientation_deg").loc[0.0]
    assert np.isnan(row["hysteresis_deg"]) and np.isnan(row["hysteresis_loss_deg"])
    reasons = [i.reason for i in a.issues if i.orientation_deg == 0.0 and i.figure == "hysteresis_loss"]
    assert reasons and "not bracketed" in reasons[0]
    assert np.isfinite(a.loops.set_index("orientation_deg").loc[60.0, "hysteresis_deg"])


def test_inverted_angle_sign_is_said_and_nothing_is_invented(bilinear_table):
    df = bilinear_table.assign(angle_deg=-bilinear_table["angle_deg"])
    assert angle_sign_inverted(df["torque_nm"], df["angle_deg"])
    a = analyze_session(df, **FAST)
    assert any(i.reason.startswith("angle_sign looks inverted; set angle_sign = -1") for i in a.issues)
    assert a.figures["value"].isna().all()


def test_creep_is_caught_by_the_closing_image(bilinear_table):
    df = bilinear_table[bilinear_table.orientation_deg == 0].copy()
    loop = df.phase != "reference"
    df.loc[loop, "angle_deg"] += 0.2 * np.linspace(0, 1, loop.sum())  # 0.2° of creep over the run
    zero = df[df.phase == "positive_unloading"].iloc[-1]
    closing = zero.copy()
    closing["image"], closing["phase"], closing["angle_deg"] = "closing.png", "closing", zero["angle_deg"] + 0.2
    df = pd.concat([df, closing.to_frame().T], ignore_index=True)
    a = analyze_session(df, **FAST)
    creep = [c for c in a.checks["closure"] if c["creep"]]
    assert {c["check"].split(":")[0] for c in creep} >= {"zero torque after unloading"}
    assert any(i.figure == "creep" for i in a.issues)
    assert (a.figures.dropna(subset=["value"])["flag"] != "").all()


def test_closure_without_creep_is_quiet(bilinear_table):
    from vision_torsion.analysis.loops import validate_measurements

    usable, _, closing = validate_measurements(bilinear_table, with_closing=True)
    assert not any(c["creep"] for c in closure_checks(usable, closing))


def test_gear_and_test_tables_are_read_and_checked():
    base = {"rig": {"arm_radius_m": 0.05, "mass_std_kg": 1e-4},
            "protocol": {"orientations_deg": [0], "max_torque_nm": 0.36, "step_mass_kg": 0.02}}
    cfg = config_from_dict({**base, "gear": {"name": "CSF-14", "ratio": 100, "rated_torque_nm": 5.4, "t1_nm": 0.1,
                                             "t2_nm": 0.25},
                            "test": {"operator": "A", "temperature_c": 21.5, "lost_motion_fractions": [0.03, 0.04]}})
    assert cfg.gear.ratio == 100 and cfg.test.lost_motion_fractions == (0.03, 0.04)
    with pytest.raises(SessionError, match="gear.colour: unknown key"):
        config_from_dict({**base, "gear": {"colour": "red"}})
    with pytest.raises(SessionError, match="give both catalogue break torques"):
        config_from_dict({**base, "gear": {"t1_nm": 0.1}})
    with pytest.raises(SessionError, match="test.lost_motion_fractions: expected a list of fractions"):
        config_from_dict({**base, "test": {"lost_motion_fractions": [3, 4]}})


def test_analyze_command(tmp_path, capsys, cli_logging):
    from vision_torsion.cli import main

    # a table whose torques follow the weight pieces of the session's rig
    bilinear_table = simulate_measurements(**TRUTH, orientations_deg=(0, 60), torque_model="pieces",
                                           rng=np.random.default_rng(6))
    table = tmp_path / "m.csv"
    bilinear_table.to_csv(table, index=False)
    (tmp_path / "s.toml").write_text(
        '[rig]\narm_radius_m = 0.05\nmass_std_kg = 0.0001\n[protocol]\norientations_deg = [0, 60]\n'
        'max_torque_nm = 0.35316\nstep_mass_kg = 0.02\n[gear]\nrated_torque_nm = 0.5\nt1_nm = 0.15\nt2_nm = 0.25\n'
        'ratio = 50\n[test]\noperator = "J. Doe"\n')
    assert main(["analyze", str(table), "--session", str(tmp_path / "s.toml"), "-o", str(tmp_path / "out")]) == 0
    import json

    d = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert d["gear"]["rated_torque_nm"] == 0.5 and d["test"]["operator"] == "J. Doe"
    assert d["settings"]["lost_motion_reference"] == "rated torque T_R"
    assert d["summary"]["k1"]["mean"] == pytest.approx(0.3, rel=0.01)  # K1 at the catalogue T1 = τ_c
    assert d["summary"]["k1"]["output_side"]["mean_nm_per_rad"] == pytest.approx(0.3 * 2500, rel=0.01)
    assert "J. Doe" in (tmp_path / "out" / "report.html").read_text()
    bilinear_table.drop(columns=["torque_nm"]).to_csv(tmp_path / "bad.csv", index=False)
    assert main(["analyze", str(tmp_path / "bad.csv"), "-o", str(tmp_path / "o2")]) == 2
    assert "bad.csv: no torque column found among 'image'" in capsys.readouterr().err
    assert math.isfinite(d["summary"]["hysteresis"]["mean"])


def test_a_planned_session_photographs_each_state_once(bilinear_table):
    # plan's protocol: the only step 0 is +Tmax at the start; the turning images (0, −Tmax, 0) belong to the
    # phase that ends there. Nothing may be withheld for a "missing" start of the next phase.
    df = bilinear_table[(bilinear_table.step != 0) | (bilinear_table.phase.isin(["reference", "positive_unloading"]))]
    a = analyze_session(df.reset_index(drop=True), **FAST)
    row = a.loops.set_index("orientation_deg").loc[0.0]
    width = math.degrees(0.15 * (1 / 0.3 - 1 / 4.4))
    assert row["hysteresis_deg"] == pytest.approx(width, abs=0.02)  # 1e-3° noise; 0.02° is 20x that
    assert np.isfinite(row["loop_energy_j"]) and np.isfinite(row["k_negative_loading_secant_nm_per_rad"])
    nl = a.phases.set_index(["orientation_deg", "phase"]).loc[(0.0, "negative_loading")]
    assert nl["torque_from_nm"] == 0.0  # its starting image is positive unloading's last
