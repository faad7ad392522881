"""The fast paths of the analysis give what the plain ones gave (issue 14: `analyze` in
<= 3 s). The timing itself is in benchmarks/bench_analyze.py, never here."""

import numpy as np
import pytest

from vision_torsion.analysis import catalogue, models, simulate_measurements


def _loop(seed):
    rng = np.random.default_rng(seed)
    df = simulate_measurements(k_u=rng.uniform(2.0, 6.0), k_l=rng.uniform(0.1, 1.0), tau_c=rng.uniform(0.05, 0.25),
                               orientations_deg=(0,), rng=rng)
    return (df["torque_nm"].to_numpy(float), np.radians(df["angle_deg"].to_numpy(float)),
            np.radians(df["angle_std_deg"].to_numpy(float)))


@pytest.mark.parametrize("seed", range(6))
def test_bilinear_profile_in_one_pass_equals_one_lstsq_per_candidate(seed):
    # The reference is numpy's lstsq on each candidate switch torque (the previous code
    # path). 1e-9 relative: normal equations of a 3-column, well-scaled design lose a few
    # digits against the SVD; the profile only picks the bracket that is then refined.
    tau, th, sa = _loop(seed)
    w = 1.0 / sa**2
    grid = np.linspace(0.0, np.max(np.abs(tau)), 401)[1:-1]
    ref = np.array([models._bilinear_linear_solve(*models._bilinear_increments(tau, tc), th, w)[1] for tc in grid])
    fast = models._bilinear_profile_sse(tau, th, w, grid)
    np.testing.assert_allclose(fast, ref, rtol=1e-9)
    assert np.argmin(fast) == np.argmin(ref)


def test_break_search_chi2_is_the_plain_weighted_fit():
    # The search's χ² against the fit written out from the model's definition: θ = θ0± ±
    # Σ c_j · (part of |τ| in segment j), two effective-variance passes, lstsq each time.
    rng = np.random.default_rng(3)
    x = np.arange(0, 10) * 0.035
    h = np.minimum(x, 0.1) / 1000 + np.clip(x - 0.1, 0, 0.15) / 2000 + np.maximum(x - 0.25, 0) / 4000
    tau = np.concatenate([x, -x])
    th = np.concatenate([h, -h]) + rng.normal(0.0, 2e-6, 20)
    sign = np.repeat([1.0, -1.0], 10)
    sa, st = np.full(20, 2e-6), np.full(20, 1e-3)
    chi2 = catalogue._BreakChi2(tau, th, sign, sa, st)
    for brk in ([0.1], [0.12, 0.26], [0.05, 0.2]):
        edges = [0.0, *brk, np.inf]
        cols = [np.clip(np.abs(tau) - lo, 0.0, hi - lo) * sign for lo, hi in zip(edges[:-1], edges[1:])]
        a = np.column_stack([(sign > 0).astype(float), (sign < 0).astype(float), *cols])
        w = 1.0 / sa**2
        for _ in range(2):
            coef = np.linalg.lstsq(a * np.sqrt(w)[:, None], th * np.sqrt(w), rcond=None)[0]
            w_fit = w
            w = 1.0 / (sa**2 + (coef[2:][np.searchsorted(brk, np.abs(tau), side="right")] * st) ** 2)
        expected = float(np.sum(w_fit * (th - a @ coef) ** 2))
        assert chi2(brk)[0] == pytest.approx(expected, rel=1e-12)
    assert chi2([0.2, 0.1])[0] == np.inf          # unordered breaks
    assert chi2([0.001, 0.002])[0] == np.inf      # a segment with fewer than two measured levels
