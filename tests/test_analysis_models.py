"""Models against closed-form truth: the bilinear loop and its fit, Bouc–Wen basics."""

import numpy as np
import pytest

from vision_torsion.analysis import (
    bilinear_loop_energy,
    bilinear_loop_width,
    bilinear_response,
    bouc_wen_response,
    fit_bilinear,
    fit_bouc_wen,
    loop_energy,
)
from vision_torsion.errors import AnalysisError
from vision_torsion.synthetic import torque_levels

K_U, K_L, TAU_C, T_MAX = 4.4, 0.3, 0.15, 0.36
STEP = 2 * 0.02 * 9.81 * 0.05


def cycle(levels=None, n=1):
    lv = torque_levels(T_MAX, STEP) if levels is None else levels
    one = np.concatenate([lv[::-1], -lv, -lv[::-1], lv])
    return np.tile(one, n)


def test_bilinear_closed_periodic_loop_and_closed_forms():
    tau = cycle(n=3)
    th = bilinear_response(tau, k_u=K_U, k_l=K_L, tau_c=TAU_C)
    n = tau.size // 3
    # several cycles repeat exactly: the model has no drift (to float rounding)
    np.testing.assert_allclose(th[:n], th[n:2 * n], atol=1e-12)
    assert th[0] == pytest.approx(-th[n // 2 - 1], abs=1e-12)  # centred: θ(+T) = −θ(−T)
    # loop width at zero torque: end of positive unloading minus end of negative unloading
    width = th[n // 4 - 1] - th[3 * n // 4 - 1]
    assert width == pytest.approx(bilinear_loop_width(k_u=K_U, k_l=K_L, tau_c=TAU_C, max_torque_nm=T_MAX), rel=1e-12)


def test_bilinear_segment_slopes_follow_the_switch_rule():
    tau = np.array([T_MAX, 0.2, 0.0, -0.1, -0.2, -T_MAX])
    th = bilinear_response(tau, k_u=K_U, k_l=K_L, tau_c=TAU_C, theta_start=0.0)
    slopes = np.diff(tau) / np.diff(th)
    # unloading, unloading, loading below τ_c, loading crossing τ_c (mixed), loading above τ_c
    assert slopes[0] == pytest.approx(K_U) and slopes[1] == pytest.approx(K_U)
    assert slopes[2] == pytest.approx(K_L)
    assert slopes[3] == pytest.approx(0.1 / (0.05 / K_L + 0.05 / K_U))
    assert slopes[4] == pytest.approx(K_U)


def test_bilinear_exact_for_any_sampling():
    coarse = np.array([T_MAX, -T_MAX, T_MAX])
    fine = cycle(levels=np.linspace(0, T_MAX, 97))
    a = bilinear_response(coarse, k_u=K_U, k_l=K_L, tau_c=TAU_C)
    b = bilinear_response(fine, k_u=K_U, k_l=K_L, tau_c=TAU_C)
    assert a[1] == pytest.approx(b[fine.size // 2 - 1], abs=1e-12)


def test_loop_energy_of_fine_bilinear_loop_matches_closed_form():
    tau = cycle(levels=np.linspace(0, T_MAX, 2001))
    th = bilinear_response(tau, k_u=K_U, k_l=K_L, tau_c=TAU_C)
    # exact up to the one kink step split by trapezoids: 1e-4 relative at 2001 levels
    assert loop_energy(tau, th) == pytest.approx(
        bilinear_loop_energy(k_u=K_U, k_l=K_L, tau_c=TAU_C, max_torque_nm=T_MAX), rel=1e-4)


@pytest.mark.parametrize("kwargs, match", [
    (dict(k_u=0.0, k_l=K_L, tau_c=TAU_C), r"k_u must be a finite number > 0 \(N·m/rad\), got 0\.0"),
    (dict(k_u=K_U, k_l=-1, tau_c=TAU_C), r"k_l must be a finite number > 0 \(N·m/rad\), got -1"),
    (dict(k_u=K_U, k_l=K_L, tau_c=-0.1), r"tau_c must be a finite number >= 0 \(N·m\), got -0\.1"),
    (dict(k_u=K_U, k_l=K_L, tau_c=TAU_C, theta_start="middle"), "theta_start must be a number"),
    (dict(k_u=K_U, k_l=K_L, tau_c=TAU_C, theta_start=np.nan), r"theta_start must be a finite number \(rad\), got nan"),
])
def test_bilinear_response_rejects_bad_parameters(kwargs, match):
    with pytest.raises(AnalysisError, match=match):
        bilinear_response([0.1, 0.0], **kwargs)


def test_bilinear_response_rejects_bad_torque():
    with pytest.raises(AnalysisError, match="torque sequence is empty"):
        bilinear_response([], k_u=K_U, k_l=K_L, tau_c=TAU_C)
    with pytest.raises(AnalysisError, match="non-finite"):
        bilinear_response([0.1, np.nan], k_u=K_U, k_l=K_L, tau_c=TAU_C)


def test_fit_bilinear_recovers_truth_and_uncertainty_is_honest():
    tau = cycle()
    truth = bilinear_response(tau, k_u=K_U, k_l=K_L, tau_c=TAU_C)
    sigma = np.radians(0.001)
    rng = np.random.default_rng(7)
    z = []
    for _ in range(30):
        fit = fit_bilinear(tau, truth + rng.normal(0, sigma, tau.size), angle_std_rad=sigma, n_grid=80)
        z.append([(fit.k_u_nm_per_rad - K_U) / fit.std("k_u"), (fit.k_l_nm_per_rad - K_L) / fit.std("k_l"),
                  (fit.tau_c_nm - TAU_C) / fit.std("tau_c")])
        # 0.1 % is ~10x the statistical scatter at 0.001° noise
        assert fit.k_u_nm_per_rad == pytest.approx(K_U, rel=1e-3)
        assert fit.k_l_nm_per_rad == pytest.approx(K_L, rel=1e-3)
        assert fit.tau_c_nm == pytest.approx(TAU_C, rel=1e-3)
    # reported std vs empirical scatter: RMS of z within [0.6, 1.5] for 30 repeats
    rms = np.sqrt(np.mean(np.square(z), axis=0))
    assert np.all((rms > 0.6) & (rms < 1.5)), rms


def test_fit_bilinear_failure_messages():
    with pytest.raises(AnalysisError, match="at least 6 samples"):
        fit_bilinear([0.1, 0.0, -0.1], [0.0, 0.0, 0.0])
    tau = np.abs(cycle())
    with pytest.raises(AnalysisError, match="never reverses"):
        fit_bilinear(tau, tau / K_U)
    with pytest.raises(AnalysisError, match="differ in length"):
        fit_bilinear(cycle(), np.zeros(3))
    # a purely linear spring: no switch inside the range
    lin = cycle()
    with pytest.raises(AnalysisError, match="edge of the sampled|non-positive compliance|not identified"):
        fit_bilinear(lin, lin / K_U)


def test_bouc_wen_periodic_closure_and_fit_residual_reported():
    tau = cycle(levels=np.linspace(0, T_MAX, 10))
    th = bouc_wen_response(tau, k_e=4.0, z_s=0.2, a=15.0, rho=0.05, n=2.0)
    assert th[0] == pytest.approx(th[-1], abs=1e-9)
    fit = fit_bouc_wen(tau, th + np.random.default_rng(3).normal(0, 1e-5, tau.size), angle_std_rad=1e-5)
    # data from the model itself: the fit reproduces it to well below 0.01°
    assert np.degrees(fit.residual_rms_rad) < 0.01
    with pytest.raises(AnalysisError, match="rho must lie in"):
        bouc_wen_response(tau, k_e=4.0, z_s=0.2, a=15.0, rho=0.7, n=2.0)
    with pytest.raises(AnalysisError, match="u0 must lie in"):
        bouc_wen_response(tau, k_e=4.0, z_s=0.2, a=15.0, rho=0.1, n=2.0, u0=1.5)
