"""Stiffness curve, dead zone and meshing pairs against synthetic truth (issue 7).

Truth: :func:`synthetic_encoder_record` (saturating K(T) = Ks·n(T) law, Ks = 330
N·m/rad, 2..50 pairs; dead zone of known width and centre; friction hysteresis;
white torque noise; pulses quantised; sensor twist included in the drive).
"""

import numpy as np
import pytest

from vision_torsion.errors import AnalysisError
from vision_torsion.stiffness import (
    RigConstants,
    analyze_stiffness_curve,
    calibrate_tooth_stiffness,
    check_linearity,
    stiffness_section,
    wrap_angle_rad,
)
from vision_torsion.synthetic import SaturatingStiffness, synthetic_encoder_record, synthetic_measurements


def _middle(curve, max_torque):
    """Mask of the middle 80 % of the torque range (issue 7's accuracy window)."""
    t = np.abs(curve.torque_nm)
    return (t >= 0.1 * max_torque) & (t <= 0.9 * max_torque)


@pytest.fixture(scope="module", params=[("polynomial", 0.02, 0.1, 1), ("polynomial", 0.05, 0.2, 2),
                                        ("spline", 0.02, 0.1, 3)],
                ids=["poly-noise0.02-bl0.1", "poly-noise0.05-bl0.2", "spline-noise0.02"])
def analysed(request):
    method, noise, backlash, seed = request.param
    syn = synthetic_encoder_record(torque_noise_nm=noise, backlash_deg=backlash,
                                   backlash_centre_deg=0.03, seed=seed)
    return syn, analyze_stiffness_curve(syn.frame, rig=syn.rig, method=method)


def test_stiffness_within_3_percent_over_middle_80(analysed):
    # Issue 7's requirement: 3 %. Measured: < 1 % for the polynomial, < 2 % for
    # the spline at these noise levels (benchmarks/bench_stiffness_curve.py).
    syn, result = analysed
    assert {c.kind for c in result.curves} == {"positive_loading", "negative_loading"}
    for curve in result.curves:
        m = _middle(curve, syn.max_torque_nm)
        truth = syn.law.stiffness(curve.torque_nm[m])
        assert np.max(np.abs(curve.stiffness_nm_per_rad[m] / truth - 1)) < 0.03


def test_backlash_width_within_5_percent_and_position(analysed):
    # Issue 7's requirement: 5 % of the width. The centre must be within 5 % of the
    # width of the true centre too (it is where the dead zone sits).
    syn, result = analysed
    b = result.backlash
    assert b is not None, result.notes
    assert abs(b.width_deg / syn.backlash_deg - 1) < 0.05
    assert abs(b.centre_deg - syn.backlash_centre_deg) < 0.05 * syn.backlash_deg
    # The reported uncertainty is an honest size: the error is within 5 of its stds
    # or within 1 % of the width (noise-free model bias is not in the std).
    assert abs(b.width_deg - syn.backlash_deg) < max(5 * b.width_std_deg, 0.01 * syn.backlash_deg)


def test_meshing_pairs_within_one_pair(analysed):
    # Issue 7's requirement: one tooth pair (2 % of n at 50 pairs).
    syn, result = analysed
    frame = result.to_frame()
    m = (frame["torque_nm"].abs() >= 0.1 * syn.max_torque_nm) & (frame["torque_nm"].abs() <= 0.9 * syn.max_torque_nm)
    truth = syn.law.pairs(frame.loc[m, "torque_nm"].to_numpy())
    assert np.max(np.abs(frame.loc[m, "meshing_pairs_per_zone"].to_numpy() - truth)) < 1.0
    assert np.allclose(frame["meshing_pairs_total"], 2 * frame["meshing_pairs_per_zone"])
    assert result.meshing.max_pairs_per_zone == pytest.approx(syn.law.pairs(syn.max_torque_nm), abs=1.0)


def test_band_matches_scatter():
    # Over repeated noisy records the reported stiffness_std must match the scatter
    # of K at fixed torques: ratio within [0.55, 1.7] (8 repeats give the empirical
    # std to about ±25 %, 1σ). Noise 0.1 N·m, where noise dominates the fit bias.
    torques = np.array([6.0, 15.0, 24.0])
    estimates, stds = [], []
    for seed in range(8):
        syn = synthetic_encoder_record(torque_noise_nm=0.1, seed=100 + seed)
        curve = analyze_stiffness_curve(syn.frame, rig=syn.rig).curve("positive_loading")
        k, k_std = curve.at_torque(torques)
        estimates.append(k)
        stds.append(k_std)
    ratio = np.mean(stds, axis=0) / np.std(estimates, axis=0, ddof=1)
    assert np.all((ratio > 0.55) & (ratio < 1.7)), ratio


def test_paper_worked_numbers():
    # 35 and 50 effective pairs of a 160-tooth flexspline: 0.4375π and 0.625π (exact).
    assert wrap_angle_rad(35, teeth=160) == pytest.approx(0.4375 * np.pi, rel=1e-15)
    assert wrap_angle_rad(50, teeth=160) == pytest.approx(0.625 * np.pi, rel=1e-15)


def test_ks_from_reference_point_and_linearity():
    # Calibrating Ks from the truth's n at 10 N·m must give Ks within 1 % (the
    # stiffness there is within ~0.5 %); the independent pair counts of the law
    # at 4 torques must pass the linearity check with slope ≈ Ks.
    syn = synthetic_encoder_record(seed=21)
    law = syn.law
    check_t = (2.0, 5.0, 10.0, 25.0)
    rig = RigConstants(pulses_per_rev=syn.rig.pulses_per_rev, transmission_ratio=100,
                       sensor_stiffness_nm_per_rad=syn.rig.sensor_stiffness_nm_per_rad, teeth=160,
                       reference_torque_nm=10.0, reference_pairs=float(law.pairs(10.0)),
                       check_torque_nm=check_t, check_pairs=tuple(law.pairs(np.array(check_t))))
    result = analyze_stiffness_curve(syn.frame, rig=rig)
    m = result.meshing
    assert m.tooth_stiffness_source == "reference point"
    assert m.tooth_stiffness_nm_per_rad == pytest.approx(law.tooth_stiffness_nm_per_rad, rel=0.01)
    assert m.linearity.is_linear and m.linearity.r_squared > 0.999
    assert m.linearity.slope_nm_per_rad == pytest.approx(law.tooth_stiffness_nm_per_rad, rel=0.02)
    assert calibrate_tooth_stiffness(3300.0, pairs=10) == 330.0


def test_linearity_check_rejects_a_curve():
    n = np.array([5.0, 10.0, 20.0, 40.0])
    assert not check_linearity(50.0 * n**2, n).is_linear
    with pytest.raises(AnalysisError, match=">= 3"):
        check_linearity([1.0, 2.0], [1.0, 2.0])


def test_session_section_smooth_fit_per_loop_when_asked():
    # 20 load steps of 1.5 N·m per phase, order-5 fit per loop: within 3 % over the
    # middle 80 % as for the encoder rig (steps noise-free here; 10 steps with a
    # cubic reach only ~4 % at the low end, where the curve bends most). Two loops
    # with different zero offsets are fitted apart, never pooled.
    table = synthetic_measurements(steps=20, cycles=2)
    table.loc[table["cycle"] == 1, "angle_deg"] += 0.7  # loop 2's own reference: another zero
    section = stiffness_section(table, order=5, method="polynomial")
    curve = section.result.curve("positive_loading")
    assert curve.n_cycles == 2
    m = _middle(curve, 30.0)
    truth = SaturatingStiffness().stiffness(curve.torque_nm[m])
    assert np.max(np.abs(curve.stiffness_nm_per_rad[m] / truth - 1)) < 0.03
    assert "## Stiffness per load step" in section.markdown


def test_session_section_fit_failure_is_a_note_per_loop():
    # A cubic through 5 steps cannot be fitted (needs 6): said per loop, then an
    # error naming the loops when no loop could be fitted.
    with pytest.raises(AnalysisError, match=r"no loading branch could be fitted: loop 1: the positive_loading "
                                            r"branch has 4 usable points"):
        stiffness_section(synthetic_measurements(steps=4), method="polynomial")
