"""The checks that see what is wrong in a table, the gates that accept the truth, and one test
family for the orientation effect (issue 27). Seeded synthetic tables; tolerances stated."""

import math

import numpy as np
import pandas as pd
import pytest

from vision_torsion.analysis import analyze_session, fit_bilinear
from vision_torsion.analysis.checks import angle_sign_by_run, backward_outliers, loop_direction
from vision_torsion.analysis.fitcheck import side_compliance, spike_scores
from vision_torsion.analysis.preisach import torque_sensitivity
from vision_torsion.analysis.summary import holm_adjust, mean_uncertainty, summarise_figures
from vision_torsion.errors import MeasurementsError
from vision_torsion.synthetic import simulate_measurements

TRUTH = dict(k_u=4.4, k_l=0.3, tau_c=0.15)
RIG = dict(step_mass_kg=0.02, mass_std_kg=1e-4, gravity_m_per_s2=9.81, arm_radius_m=0.05)
FAST = dict(rig=RIG, n_draws=20, fit_breaks=False)
NOISE = 0.0005


def _table(seed, *, orientations=(0, 60), **kw):
    return simulate_measurements(**TRUTH, orientations_deg=orientations, torque_model="pieces",
                                 angle_std_deg=NOISE, rng=np.random.default_rng(seed), **kw)


def _zero_image(df, orientation=0):
    """The zero-torque image that ends the first positive unloading of an orientation."""
    m = (df["orientation_deg"] == orientation) & (df["phase"] == "positive_unloading") & (df["cycle"] == 1)
    return df.index[m][-1]


# ------------------------------------------------------------------ the angle sign ---
def test_one_inverted_orientation_is_named_and_its_figures_withheld():
    df = _table(1, orientations=(0, 60, 120))
    df.loc[df["orientation_deg"] == 60, "angle_deg"] *= -1.0  # a camera flipped for this orientation only
    a = analyze_session(df, fit_preisach=False, **FAST)
    named = [i for i in a.issues if i.figure == "angle sign"]
    assert [i.orientation_deg for i in named] == [60.0]
    assert "inverted" in named[0].reason and "multiply this orientation's angle_deg by -1" in named[0].reason
    assert not a.checks["angle_sign_inverted"] and a.checks["angle_sign_inverted_orientations"] == [60.0]
    f = a.figures
    assert not np.isfinite(f.loc[f["orientation_deg"] == 60, "value"]).any()
    # the other orientations keep their figures, and the session mean is theirs (no −26° hysteresis)
    assert np.isfinite(f.loc[(f["orientation_deg"] == 0) & (f["figure"] == "hysteresis"), "value"]).all()
    assert a.summary["hysteresis"]["n"] == 2 and a.summary["hysteresis"]["mean"] > 0


def test_a_run_whose_angle_falls_alone_is_reported_as_mislabelled():
    t = [0.3, 0.1, -0.1, -0.3]
    d = pd.DataFrame({"orientation_deg": 0.0, "phase": ["positive_unloading"] * 4 + ["positive_loading"] * 4,
                      "torque_nm": t + t[::-1], "angle_deg": [3.0, 1.1, -0.9, -3.0, 3.1, 1.0, -1.0, -2.9]})
    r = angle_sign_by_run(d)[0]
    assert r["falls"] == ["ascending"] and r["rises"] == ["descending"]


def test_a_loop_running_clockwise_is_withheld_with_its_reason():
    df = _table(2, orientations=(0,))
    loop = df["phase"] != "reference"
    tau = df.loc[loop, "torque_nm"].to_numpy(float)
    # a slip element read the wrong way round: the loop's descending run lies below its ascending one
    p, z = tau[0] - 0.05, []
    for t in np.concatenate([tau, tau]):
        p = max(t - 0.05, min(t + 0.05, p))
        z.append(t - p)
    th = tau / 4.4 + np.array(z[tau.size:])
    df.loc[loop, "angle_deg"] = np.degrees(th) + np.random.default_rng(3).normal(0, NOISE, tau.size)
    a = analyze_session(df, fit_preisach=False, **FAST)
    why = [i for i in a.issues if i.figure == "loop figures"]
    assert len(why) == 1 and "runs the other way round (clockwise" in why[0].reason
    f = a.figures.set_index("figure")
    for name in ("loop_energy", "loss_factor", "hysteresis", "hysteresis_loss", "lost_motion_3pct"):
        assert not np.isfinite(f.loc[name, "value"]), name


def test_loop_direction_decides_by_the_area_and_its_u95():
    assert loop_direction(0.07, 0.001) == "anticlockwise"
    assert loop_direction(-0.07, 0.001) == "clockwise"
    assert loop_direction(-1e-5, 1e-4) == "unresolved"
    assert loop_direction(float("nan"), 1e-4) == "unresolved"


# ------------------------------------------------------------------ outliers ---
@pytest.mark.parametrize("seed", [3, 4, 5])
def test_a_10_sigma_zero_torque_image_is_listed_alone(seed):
    df = _table(seed)
    i = _zero_image(df)
    df.loc[i, "angle_deg"] += 10 * NOISE
    a = analyze_session(df, **FAST)
    assert [o["image"] for o in a.checks["outliers"]] == [df.loc[i, "image"]]
    issue = [x for x in a.issues if x.figure == "outlier"]
    assert len(issue) == 1 and "bilinear fit" in issue[0].reason and df.loc[i, "image"] in issue[0].reason


def test_a_30_sigma_image_in_the_stiff_zone_is_caught():
    df = _table(6)
    m = (df["orientation_deg"] == 60) & (df["phase"] == "positive_unloading") & (df["step"] == 3)
    df.loc[m, "angle_deg"] -= 30 * NOISE
    a = analyze_session(df, **FAST)
    assert [o["image"] for o in a.checks["outliers"]] == df.loc[m, "image"].tolist()


def test_clean_loops_list_no_outlier():
    a = analyze_session(_table(7), **FAST)
    assert a.checks["outliers"] == []


def test_spike_scores_see_a_spike_through_shared_noise():
    """A common offset of half the samples (a shared torque error) hides nothing: the spike is the max,
    and its score is its size over the angle noise (11 samples, a line fitted: √(1 − h) ≈ 0.95)."""
    x = np.linspace(-1.0, 1.0, 11)
    src = np.zeros((11, 1))
    src[6:, 0] = 1.0  # one source shared by the upper half, 1 rad per unit (compliance 1)
    r = np.zeros(11)
    r[6:] = 0.5  # that source's draw, not a lack of fit
    r[3] += 0.01  # a 10σ spike
    t = spike_scores(r, angle_std_rad=np.full(11, 1e-3), compliance_rad_per_nm=1.0, torque_sources=src,
                     jacobian=np.column_stack([np.ones(11), x]))
    assert int(np.nanargmax(np.abs(t))) == 3
    assert t[3] == pytest.approx(10.0, rel=0.1)
    assert np.nanmax(np.abs(np.delete(t, 3))) < 4.0


def test_backward_outliers_refit_after_each_and_stop_below_k():
    z = np.array([0.5, 12.0, 6.0, -1.0])

    def scores(keep):  # the neighbour shares the spike until the spike is taken out
        return np.where(keep, z if keep[1] else np.array([0.5, 0.0, 1.0, -1.0]), np.nan)

    assert backward_outliers(["a", "b", "c", "d"], scores) == [("b", 12.0)]
    assert backward_outliers(["a", "b", "c", "d"], lambda keep: np.zeros(4)) == []


# ------------------------------------------------------------------ bad rows ---
def test_a_zero_angle_std_is_rejected_with_its_line():
    df = _table(8, orientations=(0,))
    df.loc[5, "angle_std_deg"] = 0.0
    with pytest.raises(MeasurementsError, match=r"line 7: angle_std_deg is 0 for a measured image"):
        analyze_session(df, **FAST)


def test_a_duplicated_row_is_rejected_with_both_lines():
    df = _table(8, orientations=(0,))
    dup = pd.concat([df, df.iloc[[9]]], ignore_index=True)
    with pytest.raises(MeasurementsError, match=rf"line {len(df) + 2}: repeats line 11 \(the same image\)"):
        analyze_session(dup, **FAST)
    renamed = dup.copy()
    renamed.loc[len(df), "image"] = "another.png"
    with pytest.raises(MeasurementsError, match=r"repeats line 11 \(the same orientation, cycle, phase and step\)"):
        analyze_session(renamed, **FAST)


# ------------------------------------------------------------------ gates ---
def test_side_compliance_of_a_bilinear_fit_is_its_stiffness_on_each_side():
    df = _table(9, orientations=(0,))
    loop = df[df["phase"] != "reference"]
    tau = loop["torque_nm"].to_numpy(float)
    bil = fit_bilinear(tau, np.radians(loop["angle_deg"].to_numpy(float)))
    c = side_compliance(bil.predict, tau)
    # the first sample (+Tmax, where the fit is anchored) answers its torque as the unloading does
    assert c[0] == pytest.approx(1 / bil.k_u_nm_per_rad, rel=1e-4)
    soft = (np.abs(tau) < 0.1) & (np.abs(tau) > 0.03) & (loop["phase"].isin(["negative_loading",
                                                                           "positive_loading"])).to_numpy()
    assert c[soft] == pytest.approx(1 / bil.k_l_nm_per_rad, rel=1e-4)


def test_the_tip_torque_moves_a_masing_branch_but_not_a_bilinear_one():
    """Masing branch ``θ = θ_r + 2f((τ − τ_r)/2)``: a wrong tip torque moves the branch by
    ``f′(0) − f′((τ − τ_r)/2)`` per N·m (> 0 where it has softened); the bilinear branch leaves
    its tip as stiff as it arrived, so the tip's error does not reach it."""
    tau = np.concatenate([np.linspace(0.36, -0.36, 37), np.linspace(-0.34, 0.36, 36)])
    s, a = 0.05, 0.4

    def f(x):
        u = np.abs(x) / s
        return x / 4.4 + a * (u - np.log1p(u)) * np.sign(x)

    bottom = f(0.36) - 2 * f(0.36)
    masing = np.concatenate([f(0.36) - 2 * f((0.36 - tau[:37]) / 2), bottom + 2 * f((tau[37:] + 0.36) / 2)])
    A = torque_sensitivity(tau, masing)
    assert np.all(A[5:36, 0] > 0)  # the descending branch remembers +Tmax
    from vision_torsion.analysis.models import bilinear_response

    B = torque_sensitivity(tau, bilinear_response(tau, **TRUTH))
    assert np.allclose(B[1:36, 0], 0.0)


# ------------------------------------------------------------------ one test family ---
def test_holm_adjusts_in_step_down_order():
    assert holm_adjust([0.01, 0.04, float("nan"), 0.03]).round(6).tolist()[:2] == [0.03, 0.06]
    assert np.isnan(holm_adjust([0.01, 0.04, float("nan"), 0.03])[2])
    assert holm_adjust([]).size == 0


def test_the_orientation_family_is_holm_and_fit_statistics_are_not_tested():
    a = analyze_session(_table(10, orientations=(0, 60, 120), n_cycles=2), fit_preisach=True, **FAST)
    tested = {f: s["orientation_test"] for f, s in a.summary.items() if s["orientation_test"]["p_value"] is not None}
    assert tested and all("Holm" in t["family"] for t in tested.values())
    assert all(t["significant"] == (t["p_value_holm"] < 0.05) for t in tested.values())
    assert all(t["p_value_holm"] >= t["p_value"] for t in tested.values())
    for stat in ("preisach_residual_rms", "bilinear_residual_rms"):
        assert a.summary[stat]["orientation_test"]["reason"] == "a fit statistic, not a figure: not tested"


def test_a_flagged_single_loop_counts_its_lack_of_fit_once():
    """std² = std₀² + lof² for a flagged figure; the mean of that one loop has the same std, not √2×."""
    std0_a, std0_t, infl = 3e-3, 4e-3, 3.0
    std0 = math.hypot(std0_a, std0_t)
    row = {"value": np.array([1.0]), "std_angle": np.array([std0_a * infl]), "std_torque": np.array([std0_t * infl]),
           "std_lack_of_fit": np.array([std0 * math.sqrt(infl**2 - 1)])}
    assert mean_uncertainty(row)["std"] == pytest.approx(std0 * infl, rel=1e-12)


def test_one_cycle_per_orientation_spread_is_not_called_repeatability():
    fig = pd.DataFrame({"orientation_deg": [0.0, 60.0], "cycle": [1, 1], "figure": "k", "unit": "nm_per_rad",
                        "value": [1.0, 1.1], "std_angle": 0.01, "std_torque": 0.01, "method": "first-order",
                        "flag": ""})
    summary, _ = summarise_figures(fig)
    assert "between_orientations" in summary["k"]["budget"] and "repeatability" not in summary["k"]["budget"]


def _masing_table(seed):
    """One orientation of the pieces rig, angles of a smooth Masing loop on the nominal torques (a branch
    after a reversal at (τ_r, θ_r) is θ_r + 2f((τ − τ_r)/2)), angle noise 0.0005°."""
    df = _table(seed, orientations=(0,))
    loop = df["phase"] != "reference"
    tau = df.loc[loop, "torque_nm"].to_numpy(float)

    def f(x):
        u = np.abs(x) / 0.05
        return x / 4.4 + 0.4 * (u - np.log1p(u)) * np.sign(x)

    rev, th_rev, d, prev, out = tau.max(), float(f(tau.max())), -1.0, tau[0], []
    for t in tau:
        s = np.sign(t - prev)
        if s != 0 and s != d:
            rev, th_rev, d = prev, out[-1], s
        out.append(th_rev + 2 * float(f((t - rev) / 2)))
        prev = t
    df.loc[loop, "angle_deg"] = np.degrees(out) + np.random.default_rng(seed).normal(0, NOISE, tau.size)
    df.loc[~loop, "angle_deg"] = df.loc[loop, "angle_deg"].iloc[-1]  # the reference: zero, unloaded from +Tmax
    return df


def test_a_smooth_loop_the_bilinear_model_misses_lists_no_innocent_image():
    """The Preisach fit judges these loops (the bilinear one does not fit them): no image of a clean
    loop is listed."""
    for seed in (11, 12):
        a = analyze_session(_masing_table(seed), **FAST)
        assert a.fits[(0.0, 1)]["checks"]["bilinear"].rejected
        assert a.checks["outliers"] == []


def test_a_negative_area_within_its_u95_is_flagged_never_shown_as_an_energy():
    """A loop without hysteresis (k_l = k_u): its area is noise about zero; a negative one is flagged."""
    negatives = 0
    for seed in range(4):
        df = simulate_measurements(k_u=4.4, k_l=4.4, tau_c=0.15, orientations_deg=(0,), torque_model="pieces",
                                   angle_std_deg=NOISE, rng=np.random.default_rng(seed))
        f = analyze_session(df, fit_preisach=False, **FAST).figures.set_index("figure")
        if f.loc["loop_energy", "value"] < 0:
            negatives += 1
            assert "no dissipation is resolved" in f.loc["loop_energy", "flag"]
            assert "no dissipation is resolved" in f.loc["loss_factor", "flag"]
    assert negatives >= 1  # seed 0 draws a negative area
