"""Issue 14: the uncertainty of the loop figures carries what moves them.

Truth from closed forms written here (a Masing loop, the bilinear loop, a stop-type
play), independent of the analysis' models; seeded noise; tolerances stated.
"""

import math

import numpy as np
import pytest

from vision_torsion.analysis import analyze_session, bilinear_response
from vision_torsion.analysis.checks import flat_top
from vision_torsion.analysis.uncertainty import tip_amplitude_response
from vision_torsion.synthetic import simulate_measurements

K0, A, S = 4.4, 0.4, 0.05  # Masing virgin curve θ = τ/k0 + a·(u − ln(1 + u))·sign τ, u = |τ|/s
T = 0.36
DESC = np.linspace(T, -T, 37)  # the descending run, then the ascending one (the runs of a loop)
ASC = np.linspace(-T + 0.02, T, 36)


def _f(x):
    u = np.abs(x) / S
    return x / K0 + A * (u - np.log1p(u)) * np.sign(x)


def _df(x):
    u = np.abs(x) / S
    return 1 / K0 + A / S * u / (1 + u)


def _masing_runs():
    th_d = _f(T) - 2 * _f((T - DESC) / 2)
    th_a = -_f(T) + 2 * _f((ASC + T) / 2)
    return np.concatenate([DESC, ASC]), np.concatenate([th_d, th_a]), np.r_[np.ones(37, bool), np.zeros(36, bool)]


def test_a_tip_error_moves_a_masing_branch_by_the_masing_rule():
    tau, th, is_desc = _masing_runs()
    resp = tip_amplitude_response(tau, th, is_desc)
    d = np.zeros((1, tau.size))
    d[0, 0] = 1.0  # the +Tmax tip is 1 N·m too high (linear response: per N·m)
    out = resp(d)[0]
    zero = int(np.flatnonzero(is_desc & (np.abs(tau) < 1e-12))[0])
    # closed form: θ_desc(0) = θ(T) − 2f(T/2) moves by f'(T) − f'(T/2) per N·m of T; the rule takes the
    # slopes from secants over ±0.02 N·m of the data (and f'(T) from the last step): 3 % covers that
    truth = _df(T) - _df(T / 2)
    assert out[zero] == pytest.approx(truth, rel=0.03)
    # the bottom tip of a symmetric loop forgets the top one (wiping out): nothing carried to the ascending run
    assert np.max(np.abs(out[~is_desc])) < 0.03 * truth


def test_a_bilinear_loop_has_no_amplitude_effect():
    tau = np.concatenate([DESC, ASC])
    th = bilinear_response(np.concatenate([[T], tau]), k_u=4.4, k_l=0.3, tau_c=0.15)[1:]
    resp = tip_amplitude_response(tau, th, np.r_[np.ones(37, bool), np.zeros(36, bool)])
    d = np.random.default_rng(0).standard_normal((5, tau.size))
    # the arriving and the departing slope at each tip are both 1/k_u: nothing hysteretic switches there
    # (to rounding: 1e-12 rad per N·m is 1e-16 rad for this rig's 1e-4 N·m tip errors)
    held = resp.held
    assert np.flatnonzero(held).tolist() == [0, 36]  # the two tip images: +Tmax (start) and −Tmax
    assert np.max(np.abs(resp(d)[:, ~held])) < 1e-12
    # a held tip's angle answers its own torque along the arriving branch, 1/k_u on both tips here (+Tmax:
    # its own torque only; −Tmax: its own, and nothing from +Tmax)
    assert resp(d)[:, held] == pytest.approx(d[:, held] / 4.4, rel=1e-9)


def test_a_tip_image_answers_along_the_arriving_branch_in_the_loop_energy():
    """Masing loop energy's torque part: the bottom tip, read by the polygon as a vertex of both runs.

    The energy ``W(τ₊ − τ₋)`` of a Masing loop depends on its amplitude only; its
    derivative by the bottom tip's torque, from the closed form by central differences,
    against the Monte Carlo's linear response (one unit draw at the −Tmax image).
    Before the tip images were held, the shifted torque axis added ``δ·w(Δ)/2`` there
    and the response was 7 % short.
    """
    from vision_torsion.analysis.metrics import loop_energy
    from vision_torsion.analysis.uncertainty import monte_carlo_std

    tau, th, is_desc = _masing_runs()

    def energy(bottom):  # the periodic Masing loop between +T and `bottom`, on the same nominal levels
        th_bottom = _f(T) - 2 * _f((T - bottom) / 2)  # the bottom image, taken at the true bottom torque
        d = np.concatenate([_f(T) - 2 * _f((T - DESC[:-1]) / 2), [th_bottom]])
        a = th_bottom + 2 * _f((ASC - bottom) / 2)  # the ascending branch leaves the true bottom
        return loop_energy(np.concatenate([DESC, ASC]), np.concatenate([d, a]))

    h = 1e-5
    truth = (energy(-T - h) - energy(-T + h)) / (2 * h)  # per N·m of a more negative bottom torque
    ev = lambda t2, y2: {"w": loop_energy(t2, y2)}  # noqa: E731
    L = np.zeros((tau.size, 1))
    L[36, 0] = -1e-4  # one source: the bottom tip's torque, 1σ = 1e-4 N·m (this rig's scale), more negative
    # the Monte Carlo's std of a single source is |dW/dδ|·σ: 4000 draws of ξ give it to ≈ 1 %
    _, st = monte_carlo_std(ev, tau, th, angle_std_rad=np.full(tau.size, 1e-12), torque_sources=L, n_draws=4000,
                            seed=1, torque_response=tip_amplitude_response(tau, th, is_desc))
    # the slopes are secants over the 0.02 N·m steps (the arriving one over the last step): 3 % covers that
    assert st["w"] / 1e-4 == pytest.approx(abs(truth), rel=0.03)


def _table(kind, *, noise_deg, rng):
    """One orientation, one cycle, on the weight-piece rig, angles from the closed forms above."""
    df = simulate_measurements(
        k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0,), torque_model="pieces", angle_std_deg=noise_deg, rng=rng
    )
    loop = df["phase"].isin(["positive_unloading", "negative_loading", "negative_unloading", "positive_loading"])
    tau = df.loc[loop, "torque_nm"].to_numpy(float)
    if kind == "play":  # a slip element of width 0.1 N·m (1 rad/N·m while it slips) on a linear spring
        # (the play operator's output: it lags the torque, so the loop runs anticlockwise and dissipates)
        p, z = tau[0] - 0.05, []
        for t in np.concatenate([tau, tau]):  # one cycle to reach the periodic state
            p = max(t - 0.05, min(t + 0.05, p))
            z.append(p)
        th = tau / 4.4 + np.array(z[tau.size :])
        df.loc[loop, "angle_deg"] = np.degrees(th) + rng.normal(0, noise_deg, tau.size)
    return df


RIG = dict(step_mass_kg=0.02, mass_std_kg=1e-4, gravity_m_per_s2=9.81, arm_radius_m=0.05)


def test_a_flat_topped_loop_flags_its_largest_width():
    rng = np.random.default_rng(3)
    a = analyze_session(_table("play", noise_deg=0.0005, rng=rng), rig=RIG, n_draws=40, fit_preisach=False)
    f = a.figures.set_index("figure")
    assert "flat-topped loop" in f.loc["hysteresis", "flag"] and "upward" in f.loc["hysteresis", "flag"]
    assert f.loc["hysteresis_loss", "flag"] == ""
    # the element slips up to each tip and sticks after it: a tip's own angle answers its torque along the
    # arriving branch,
    # so the two unloading secants (mirror images) carry the same torque part; 40 draws: ±16 % each (1σ)
    ratio = f.loc["k_positive_unloading_secant", "std_torque"] / f.loc["k_negative_unloading_secant", "std_torque"]
    assert 0.6 < ratio < 1.6
    b = analyze_session(_table("bilinear", noise_deg=0.0005, rng=rng), rig=RIG, n_draws=40, fit_preisach=False)
    assert b.figures.set_index("figure").loc["hysteresis", "flag"] == ""  # a peaked loop: one level at the top


def test_flat_top_counts_levels_within_the_noise():
    t = np.linspace(0.2, -0.2, 9)
    sig = np.full(9, 1e-3)
    peaked = np.abs(np.linspace(-1, 1, 9)) * -0.1 + 0.2
    assert flat_top(t, peaked, sig, t[::-1], np.zeros(9), sig) is None
    r = flat_top(t, np.full(9, 0.2), sig, t[::-1], np.zeros(9), sig)
    # 9 equal widths, σ_w = √2·1e-3: Blom's expected maximum of 9 normals is 1.49σ
    assert r["levels"] == 9 and r["bias_rad"] == pytest.approx(1.49 * math.sqrt(2) * 1e-3, rel=0.01)


def test_a_loading_secant_moves_only_with_its_tip():
    """Bilinear loading phase 0 → +T: only the tip's torque error moves its angle (by δ/k_u)."""
    rng = np.random.default_rng(4)
    a = analyze_session(_table("bilinear", noise_deg=0.0005, rng=rng), rig=RIG, n_draws=400, fit_preisach=False)
    r = a.figures.set_index("figure").loc["k_positive_loading_secant"]
    tmax = 2 * 18 * 0.02 * 9.81 * 0.05
    dth = 0.15 / 0.3 + (tmax - 0.15) / 4.4
    k = tmax / dth
    sigma_tip = 9.81 * 0.05 * math.sqrt(2 * 18) * RIG["mass_std_kg"]  # 18 pieces on each of two pans
    truth = k * sigma_tip / 4.4 / dth
    # 400 draws: the Monte Carlo std is known to ≈ 3.5 % (1σ); 12 % is > 3σ
    assert r["std_torque"] == pytest.approx(truth, rel=0.12)
