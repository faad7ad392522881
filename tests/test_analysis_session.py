"""analyze_session on synthetic tables with known truth, and its bad-input contract."""

import math

import numpy as np
import pytest

from vision_torsion.analysis import (
    analyze_session,
    bilinear_loop_energy,
    bilinear_loop_width,
    lost_motion,
    orientation_test,
    validate_measurements,
)
from vision_torsion.errors import AnalysisError
from vision_torsion.synthetic import simulate_measurements

TRUTH = dict(k_u=4.4, k_l=0.3, tau_c=0.15)
T_MAX = 0.36
FAST = dict(n_draws=60, fit_bouc_wen=False)


@pytest.fixture(scope="module")
def session():
    df = simulate_measurements(**TRUTH, orientations_deg=(0, 60), n_cycles=2, rng=np.random.default_rng(11))
    return df, analyze_session(df, **FAST)


def test_recovers_truth(session):
    _, a = session
    s = a.summary
    # noise 0.001° and 0.1 g mass tolerance give ~0.1 % scatter: 1 % / 2 % / 0.01° are ~10x that
    assert s["bilinear_k_u"]["mean"] == pytest.approx(TRUTH["k_u"], rel=0.01)
    assert s["bilinear_k_l"]["mean"] == pytest.approx(TRUTH["k_l"], rel=0.01)
    assert s["bilinear_tau_c"]["mean"] == pytest.approx(TRUTH["tau_c"], rel=0.02)
    width = math.degrees(bilinear_loop_width(**TRUTH, max_torque_nm=T_MAX))
    assert s["hysteresis"]["mean"] == pytest.approx(width, abs=0.01)
    assert s["hysteresis_loss"]["mean"] == pytest.approx(width, abs=0.01)
    # the step grid cuts the kink at τ_c: the polygon area is 0.4 % above the smooth loop
    assert s["loop_energy"]["mean"] == pytest.approx(bilinear_loop_energy(**TRUTH, max_torque_nm=T_MAX), rel=0.01)
    assert s["k_positive_unloading"]["mean"] == pytest.approx(TRUTH["k_u"], rel=0.01)
    assert s["secant_stiffness"]["mean"] == pytest.approx(TRUTH["k_u"], rel=0.01)  # 0.5–1 Tmax is above τ_c
    # lost motion of the bilinear loop at ±x: x·(1/k_u + 1/k_l) when x is below the first step (linear interp.)
    x = 0.03 * T_MAX
    step = 2 * 0.02 * 9.81 * 0.05
    expected = math.degrees(x / step * step * (1 / TRUTH["k_u"] + 1 / TRUTH["k_l"]))
    assert s["lost_motion_3pct"]["mean"] == pytest.approx(expected, rel=0.01)


def test_no_orientation_effect_when_there_is_none(session):
    _, a = session
    for fig in ("bilinear_k_u", "hysteresis", "loop_energy"):
        assert a.summary[fig]["orientation_test"]["significant"] is False


def test_orientation_effect_detected():
    # two cycles per orientation: the effect (4.6 vs 4.4) is tested against the cycle-to-cycle scatter
    df = simulate_measurements(**TRUTH, orientations_deg=(0, 60, 120), orientation_k_u={60: 4.6}, n_cycles=2,
                               rng=np.random.default_rng(2))
    a = analyze_session(df, **FAST)
    assert a.summary["bilinear_k_u"]["orientation_test"]["significant"] is True
    assert a.summary["k_positive_unloading"]["orientation_test"]["p_value"] < 1e-6


def test_orientation_effect_with_one_cycle_is_not_tested():
    df = simulate_measurements(**TRUTH, orientations_deg=(0, 60, 120), orientation_k_u={60: 4.6},
                               rng=np.random.default_rng(2))
    t = analyze_session(df, **FAST).summary["k_positive_unloading"]["orientation_test"]
    assert t["significant"] is None and t["reason"].startswith("one cycle per orientation")
    # sd of (4.4, 4.6, 4.4) over their mean: 2.6 %
    assert t["effect_size"] == pytest.approx(np.std([4.4, 4.6, 4.4], ddof=1) / np.mean([4.4, 4.6, 4.4]), rel=0.05)


def test_orientation_test_reasons():
    assert orientation_test([1.0], [0.1])["reason"] == "fewer than two orientations with a value"
    assert "no positive finite uncertainty" in orientation_test([1.0, 2.0], [0.1, 0.0])["reason"]


def test_tables_and_to_dict(session):
    df, a = session
    d = a.to_dict()
    assert d["schema"] == "vision-torsion/analysis-summary/2"
    assert set(d) >= {"settings", "counts", "uncertainty", "summary", "per_orientation", "loops", "phases",
                      "issues", "failed_images"}
    assert d["counts"] == {"images": len(df), "images_failed": 0, "loops": 4, "orientations": 2,
                           "issues": len(a.issues)}
    assert {"hysteresis_deg", "hysteresis_std_deg", "loop_energy_j", "loss_factor", "loss_factor_std"} <= set(a.loops)
    assert len(a.phases) == 4 * 4
    # the input table is not modified
    assert "_phase_order" not in df.columns


def test_uncertainty_is_honest_for_hysteresis_and_energy():
    rng = np.random.default_rng(5)
    vals, stds = [], []
    for _ in range(12):
        df = simulate_measurements(**TRUTH, orientations_deg=(0,), angle_std_deg=0.01, rng=rng)
        a = analyze_session(df, **FAST)
        f = a.figures.set_index("figure")
        vals.append([f.loc["hysteresis", "value"], f.loc["loop_energy", "value"]])
        # the noise part (the energy's sampling term is a bias bound, which does not scatter)
        stds.append([np.hypot(f.loc[n, "std_angle"], f.loc[n, "std_torque"]) for n in ("hysteresis", "loop_energy")])
    vals, stds = np.array(vals), np.array(stds)
    # empirical scatter over 12 sessions vs mean reported noise std: ratio within [0.5, 2] (12 repeats)
    ratio = vals.std(axis=0, ddof=1) / stds.mean(axis=0)
    assert np.all((ratio > 0.5) & (ratio < 2.0)), ratio


def _drop(df, mask):
    return df.loc[~mask].reset_index(drop=True)


def test_missing_phase_is_reported_and_nothing_invented():
    df = simulate_measurements(**TRUTH, orientations_deg=(0, 60), rng=np.random.default_rng(1))
    df = _drop(df, (df.orientation_deg == 60) & (df.phase == "negative_unloading"))
    a = analyze_session(df, **FAST)
    msgs = [str(i) for i in a.issues]
    assert any("orientation 60°, cycle 1: k_negative_unloading: phase negative_unloading is missing" in m for m in msgs)
    assert any("60°" in m and "missing: the loop is not closed" in m for m in msgs)
    row = a.loops.set_index("orientation_deg").loc[60.0]
    assert np.isnan(row["hysteresis_deg"]) and np.isnan(row["loop_energy_j"])
    assert row["k_positive_unloading_nm_per_rad"] == pytest.approx(4.4, rel=0.01)  # what can be given is given
    assert a.summary["hysteresis"]["n"] == 1


def test_too_few_steps_and_failed_images():
    df = simulate_measurements(**TRUTH, orientations_deg=(0,), rng=np.random.default_rng(1))
    pl = df.index[df.phase == "positive_loading"]
    df.loc[pl[2:], "status"] = "failed"
    df.loc[pl[2:], "message"] = "marker not found"
    a = analyze_session(df, **FAST)
    msgs = [str(i) for i in a.issues]
    assert any("phase positive_loading: phase has 2 usable point(s); a stiffness needs at least 3" in m for m in msgs)
    assert len(a.failed_images) == len(pl) - 2
    assert set(a.failed_images["message"]) == {"marker not found"}
    assert any("excluded: marker not found" in m for m in msgs)
    # the loop still exists but lacks +Tmax: energy is not computed from a wrong polygon
    assert a.summary["loop_energy"]["n"] == 0
    # negative loading switches stiffness: given as its two stiffnesses, not one line
    assert a.summary["k_negative_loading"]["n"] == 0
    assert a.summary["k_negative_loading_below"]["mean"] == pytest.approx(TRUTH["k_l"], rel=0.01)


def test_torque_never_reverses():
    df = simulate_measurements(**TRUTH, orientations_deg=(0,), rng=np.random.default_rng(1))
    df["torque_nm"] = df["torque_nm"].abs()
    a = analyze_session(df, **FAST)
    assert any("torque never reverses sign in this cycle" in str(i) for i in a.issues)
    assert a.summary["hysteresis"]["n"] == 0 and a.summary["hysteresis"]["mean"] is None


def test_ok_row_with_nan_angle_becomes_failed():
    df = simulate_measurements(**TRUTH, orientations_deg=(0,), rng=np.random.default_rng(1))
    df.loc[3, "angle_deg"] = np.nan
    usable, failed = validate_measurements(df)
    assert failed["message"].tolist() == ["marked ok but angle_deg is not a finite number"]


@pytest.mark.parametrize("mutate, match", [
    (lambda d: d.drop(columns=["angle_deg"]), "missing column\\(s\\): angle_deg"),
    (lambda d: d.assign(phase="loading"), "unknown phase 'loading'"),
    (lambda d: d.assign(torque_nm="abc"), "column torque_nm is not a number"),
    (lambda d: d.assign(angle_std_deg=-1.0), "angle_std_deg is negative"),
    (lambda d: d.assign(status="failed"), "no usable rows"),
])
def test_invalid_tables_raise(mutate, match):
    df = simulate_measurements(**TRUTH, orientations_deg=(0,), mass_std_kg=0, rng=np.random.default_rng(0))
    with pytest.raises(AnalysisError, match=match):
        analyze_session(mutate(df), **FAST)


def test_invalid_options_raise():
    df = simulate_measurements(**TRUTH, orientations_deg=(0,), mass_std_kg=0, rng=np.random.default_rng(0))
    with pytest.raises(AnalysisError, match=r"n_draws must be a whole number >= 10, got 1"):
        analyze_session(df, n_draws=1)
    with pytest.raises(AnalysisError, match="secant_interval must be fractions"):
        analyze_session(df, secant_interval=(0.8, 0.2))
    with pytest.raises(AnalysisError, match=r"max_torque_nm must be a finite number > 0 \(N·m\)"):
        analyze_session(df, max_torque_nm=-1)
    with pytest.raises(AnalysisError, match="must be a pandas DataFrame"):
        analyze_session([1, 2])


def test_lost_motion_formula_on_a_parallelogram():
    # two parallel branches 2 rad apart: mid-points differ by the slope times 2x
    tau = np.linspace(-1, 1, 5)
    assert lost_motion(tau, tau + 1, tau, tau - 1, torque_nm=0.5) == pytest.approx(1.0)


def test_a_later_cycle_that_borrows_its_start_image_has_its_own_rows_torque_errors():
    # cycle 2 made a copy of cycle 1 (angles and torques) whose +Tmax start image is the last image of cycle 1,
    # as when the protocol does not photograph it twice; each level's torque 1σ differs (1 % of the torque)
    df = simulate_measurements(**TRUTH, orientations_deg=(0,), n_cycles=2, mass_std_kg=0.0,
                               rng=np.random.default_rng(4))
    c1, c2 = df[df.cycle == 1], df[df.cycle == 2]
    df.loc[c1.index[-1], "angle_deg"] = df.loc[c1.index[0], "angle_deg"]
    same = c2[["phase", "step"]].merge(df.loc[c1.index, ["phase", "step", "angle_deg"]], on=["phase", "step"])
    df.loc[c2.index, "angle_deg"] = same["angle_deg"].to_numpy()
    df = df.drop(index=c2.index[0]).reset_index(drop=True)
    df["torque_std_nm"] = 1e-5 + 0.01 * df["torque_nm"].abs()
    ph = analyze_session(df, **FAST).phases.set_index(["cycle", "phase"])
    for column in ("stiffness_std_nm_per_rad", "reduced_chi2", "residual_rms_deg"):
        np.testing.assert_allclose(ph.loc[2, column].to_numpy(), ph.loc[1, column].to_numpy(), rtol=1e-9)
