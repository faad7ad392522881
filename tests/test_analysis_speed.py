"""The fast paths of the analysis give what the plain ones gave (issue 14: `analyze` in
<= 3 s). The timing itself is in benchmarks/bench_analyze.py, never here."""

import numpy as np
import pytest

from vision_torsion.analysis import catalogue, models
from vision_torsion.synthetic import simulate_measurements


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
    ref = np.array([models.bilinear_linear_solve(*models.bilinear_increments(tau, tc), th, w)[1] for tc in grid])
    fast = models.bilinear_profile_sse(tau, th, w, grid)
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
    chi2 = catalogue.BreakChi2(tau, th, sign, sa, st)
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


def _branches(seed, n_levels=12):
    # three-segment loading branches with noise (the catalogue's model, breaks between levels)
    rng = np.random.default_rng(seed)
    x = np.arange(n_levels) * 0.03
    t1, t2 = rng.uniform(0.05, 0.12), rng.uniform(0.18, 0.28)
    k = rng.uniform(800.0, 1200.0), rng.uniform(1800.0, 2500.0), rng.uniform(3500.0, 4500.0)
    h = np.minimum(x, t1) / k[0] + np.clip(x - t1, 0, t2 - t1) / k[1] + np.maximum(x - t2, 0) / k[2]
    tau = np.concatenate([x, -x])
    th = np.concatenate([h, -h]) + rng.normal(0.0, 2e-6, 2 * n_levels)
    sign = np.repeat([1.0, -1.0], n_levels)
    return catalogue.BreakChi2(tau, th, sign, np.full(tau.size, 2e-6), np.full(tau.size, 1e-3)), x


@pytest.mark.parametrize("seed", range(5))
def test_break_grid_search_picks_what_the_plain_loop_picks(seed):
    # The plain loop (the previous code path): χ² of every placement by lstsq, the first
    # least one kept. The stacked ranking must give the same placement and the same χ²
    # to the last bit; its own values are within 1e-6 of the exact ones.
    chi2, x = _branches(seed)
    mids = 0.5 * (x[1:] + x[:-1])
    for cands in ([[m] for m in mids[1:-1]],
                  [[mids[i], mids[j]] for i in range(1, mids.size - 1) for j in range(i + 1, mids.size - 1)],
                  [[0.001, 0.002], [0.2, 0.1], [mids[3], mids[7]]]):  # two invalid placements first
        exact = np.array([chi2(c)[0] for c in cands])
        best_k = int(np.argmin(exact))                   # argmin: the first of equal minima
        assert catalogue.first_best_placement(chi2, cands) == (exact[best_k], list(cands[best_k]))
        approx = chi2.many(cands)
        valid = np.isfinite(exact)
        np.testing.assert_allclose(approx[valid], exact[valid], rtol=1e-6)
        assert np.all(np.isinf(approx[~np.isfinite(exact)]))
    assert catalogue.first_best_placement(chi2, [[0.2, 0.1]]) == (np.inf, None)


def _phase(seed):
    # a loading phase whose stiffness switches: x = torque taken since the start, y = angle (rad)
    rng = np.random.default_rng(100 + seed)
    x = np.arange(19) * 0.0196
    ts, c1, c2 = rng.uniform(0.08, 0.25), 1.0 / rng.uniform(0.2, 0.5), 1.0 / rng.uniform(3.0, 6.0)
    y = 0.01 + c1 * np.minimum(x, ts) + c2 * np.maximum(x - ts, 0.0) + rng.normal(0.0, 3e-4, x.size)
    return x, y, 1.0 / rng.uniform(2e-4, 4e-4, x.size) ** 2


def _hinge(x):
    return lambda t: np.column_stack([np.ones_like(x), np.minimum(x, t), np.maximum(x - t, 0.0)])


@pytest.mark.parametrize("seed", range(8))
def test_switch_grid_picks_what_the_plain_loop_picks(seed):
    from vision_torsion.analysis.fitcheck import least_midpoint
    from vision_torsion.numerics import weighted_lstsq

    x, y, w = _phase(seed)
    cands = (0.5 * (x[1:] + x[:-1]))[1:-1]
    sse = [weighted_lstsq(_hinge(x)(c), y, w)[1] for c in cands]
    assert least_midpoint(x, y, w, cands, _hinge(x)) == int(np.argmin(sse))


@pytest.mark.parametrize("seed", range(4))
def test_switch_between_two_levels_is_the_least_squares_optimum(seed):
    # Truth independent of the closed form: the weighted sum of squares scanned on 2001
    # switch torques across the bracket, and the Nelder-Mead refinement the closed form
    # replaced (numerics.fit_breakpoints to 1e-9 of the torque range). Every bracket of
    # the phase is tried, so both an interior crossing and an optimum at an end occur.
    from vision_torsion.analysis.fitcheck import switch_in_bracket
    from vision_torsion.numerics import fit_breakpoints, weighted_lstsq

    x, y, w = _phase(seed)
    design = _hinge(x)
    levels = np.unique(x)
    kinds = set()
    for lo, hi in zip(levels[1:-2], levels[2:-1]):
        ts = switch_in_bracket(x, y, w, lo, hi, design)
        assert lo <= ts <= hi
        kinds.add("end" if ts in (lo, hi) else "interior")
        got = weighted_lstsq(design(ts), y, w)[1]
        scan = np.linspace(lo, hi, 2001)
        a = np.stack([np.ones((scan.size, x.size)), np.minimum(x, scan[:, None]), np.maximum(x - scan[:, None], 0)], 2)
        coef = np.linalg.solve(np.einsum("bnk,n,bnl->bkl", a, w, a), np.einsum("bnk,n,n->bk", a, w, y)[:, :, None])
        sse = np.sum(w * (y - np.einsum("bnk,bk->bn", a, coef[:, :, 0])) ** 2, axis=1)
        assert got <= sse.min() * (1 + 1e-9)
        assert abs(ts - scan[np.argmin(sse)]) <= (hi - lo) / 2000
        nm = fit_breakpoints(lambda t: design(t[0]), y, [[0.5 * (lo + hi)]], weights=w,
                             feasible=lambda t: lo <= t[0] <= hi, xatol=levels[-1] * 1e-9, fatol_rel=1e-12)
        assert got <= nm.sse * (1 + 1e-12)
        assert ts == pytest.approx(nm.breakpoints[0], abs=levels[-1] * 1e-8)
    assert kinds == {"end", "interior"}


def _relays_loop(h):
    # the previous code path, written out: a Python loop with a set of rounded tuple keys
    a_list, b_list, a_mir, b_mir, seen = [], [], [], [], set()
    for i, al in enumerate(h):
        for be in h[: i + 1]:
            key = tuple(sorted([(round(al, 12), round(be, 12)), (round(-be, 12), round(-al, 12))]))
            if key in seen:
                continue
            seen.add(key)
            a_list.append(al)
            b_list.append(be)
            a_mir.append(-be)
            b_mir.append(-al)
    return np.array(a_list), np.array(b_list), np.array(a_mir), np.array(b_mir)


@pytest.mark.parametrize("seed", range(4))
def test_preisach_relay_pairs_are_the_loops(seed):
    from vision_torsion.analysis import preisach

    rng = np.random.default_rng(seed)
    step = 2 * 0.02 * 9.81 * 0.05 * rng.uniform(0.5, 2.0)
    levels = np.arange(-18, 19) * step                      # symmetric levels, as a loop's are
    tau = np.concatenate([levels, levels[::-1] + rng.normal(0, 1e-15, levels.size)])  # mirror images within rounding
    thresholds = preisach.relay_thresholds
    for h in (thresholds(tau, 64), thresholds(tau, 10), thresholds(tau[:30], 64), np.array([-0.0, 0.0, 0.1, -0.1])):
        for got, want in zip(preisach.relay_pairs(h), _relays_loop(h)):
            np.testing.assert_array_equal(got, want)


def test_analyze_command_in_process_leaves_the_garbage_collector_alone(tmp_path, capsys):
    # Only the process's own command line switches the collector off and freezes its
    # objects at the end; a program that calls main([...]) in-process keeps its settings.
    import gc
    import logging

    from vision_torsion.cli import main

    own = logging.getLogger("vision_torsion")
    level, handlers = own.level, list(own.handlers)
    (tmp_path / "bad.csv").write_text("image,angle_deg\na.png,1.0\n")
    before, frozen = gc.get_threshold(), gc.get_freeze_count()
    try:
        gc.set_threshold(500, 7, 9)
        assert main(["analyze", str(tmp_path / "bad.csv"), "-o", str(tmp_path / "out")]) == 2
        assert gc.isenabled() and gc.get_threshold() == (500, 7, 9) and gc.get_freeze_count() == frozen
    finally:
        gc.set_threshold(*before)
        own.setLevel(level)
        for h in list(own.handlers):
            if h not in handlers:
                own.removeHandler(h)
    assert "bad.csv" in capsys.readouterr().err


def _interp_rows_by_counting(xq, x, y, *, tol=0.0):
    # the comparison-count form interp_rows had (every row value against every query)
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    xq = np.broadcast_to(np.asarray(xq, float), (x.shape[0],) + np.shape(xq)[-1:])
    idx = np.clip(np.sum(x[:, None, :] <= xq[:, :, None], axis=-1) - 1, 0, x.shape[1] - 2)
    x0, x1 = np.take_along_axis(x, idx, 1), np.take_along_axis(x, idx + 1, 1)
    y0, y1 = np.take_along_axis(y, idx, 1), np.take_along_axis(y, idx + 1, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = y0 + (xq - x0) / (x1 - x0) * (y1 - y0)
    return np.where((xq < x[:, :1] - tol) | (xq > x[:, -1:] + tol), np.nan, out)


@pytest.mark.parametrize("seed", range(4))
def test_interp_rows_bisection_equals_counting(seed):
    # Rows with repeated values (a torque level measured twice), a NaN sorted last, queries
    # on, between and beyond the knots, and a shared query row: the same bits as counting.
    from vision_torsion.analysis.metrics import interp_rows

    rng = np.random.default_rng(seed)
    for _ in range(300):
        n_rows, m, q = int(rng.integers(1, 6)), int(rng.integers(2, 40)), int(rng.integers(1, 9))
        x = np.sort(rng.choice(np.round(rng.normal(size=3 * m), 1), size=(n_rows, m)), axis=1)
        if rng.random() < 0.3:
            x[rng.integers(n_rows), -1] = np.nan
        y = rng.normal(size=(n_rows, m))
        xq = np.round(rng.normal(scale=1.5, size=(1 if rng.random() < 0.3 else n_rows, q)), 1)
        xq[0, 0] = np.nan if rng.random() < 0.2 else xq[0, 0]
        np.testing.assert_array_equal(interp_rows(xq, x, y, tol=0.1), _interp_rows_by_counting(xq, x, y, tol=0.1))


def test_analyze_as_its_own_process_writes_and_prints_everything(tmp_path):
    # The process's own command line runs analyze with the collector off and freezes its
    # objects at the end (the interpreter's shutdown then skips walking them): every file
    # and line is still there.
    import json
    import os
    import subprocess
    import sys

    table = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0,), rng=np.random.default_rng(2))
    table.to_csv(tmp_path / "m.csv", index=False)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run([sys.executable, "-m", "vision_torsion", "analyze", str(tmp_path / "m.csv"), "-o",
                           str(tmp_path / "out")], capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300)
    assert done.returncode == 0, done.stderr
    assert f"report: {tmp_path / 'out' / 'report.html'}" in done.stdout
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["counts"]["images"] == len(table)
    assert (tmp_path / "out" / "report.html").read_text().rstrip().endswith("</html>")
