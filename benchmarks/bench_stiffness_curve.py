"""Benchmark of the stiffness-curve analysis (issue 7) on seeded synthetic records.

Run: ``python benchmarks/bench_stiffness_curve.py``

For each scenario (noise level, backlash width, fit method, seed) a synthetic
encoder/torque-sensor record with the saturating K(T) = Ks·n(T) law is analysed
and compared with its truth:

- max stiffness error over the middle 80 % of the torque range (%), both loading
  branches (issue 7 requires < 3 %);
- backlash width error (%) (requires < 5 %);
- max |n error| over the same range, tooth pairs (requires < 1);
- runtime of ``analyze_stiffness_curve`` (s).

Prints a table and writes ``benchmarks/results/stiffness_curve.json`` atomically.
"""

from __future__ import annotations

import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vision_torsion.fileio import write_json  # noqa: E402
from vision_torsion.stiffness import analyze_stiffness_curve, synthetic_encoder_record  # noqa: E402

SCENARIOS = [
    # (torque noise N·m, backlash deg, method)
    (0.005, 0.05, "polynomial"),
    (0.02, 0.05, "polynomial"),
    (0.02, 0.1, "polynomial"),
    (0.05, 0.1, "polynomial"),
    (0.1, 0.1, "polynomial"),
    (0.1, 0.2, "polynomial"),
    (0.02, 0.1, "spline"),
    (0.1, 0.1, "spline"),
]
SEEDS = (1, 2, 3)


def run_one(noise, backlash, method, seed):
    syn = synthetic_encoder_record(torque_noise_nm=noise, backlash_deg=backlash,
                                   backlash_centre_deg=0.02, seed=seed)
    start = time.perf_counter()
    result = analyze_stiffness_curve(syn.frame, rig=syn.rig, method=method)
    runtime = time.perf_counter() - start
    k_err, n_err = 0.0, 0.0
    for curve in result.curves:
        t = np.abs(curve.torque_nm)
        m = (t >= 0.1 * syn.max_torque_nm) & (t <= 0.9 * syn.max_torque_nm)
        truth = syn.law.stiffness(curve.torque_nm[m])
        k_err = max(k_err, float(np.max(np.abs(curve.stiffness_nm_per_rad[m] / truth - 1))) * 100)
        pairs = curve.stiffness_nm_per_rad[m] / syn.rig.tooth_stiffness_nm_per_rad
        n_err = max(n_err, float(np.max(np.abs(pairs - syn.law.pairs(curve.torque_nm[m])))))
    width_err = (result.backlash.width_deg / syn.backlash_deg - 1) * 100 if result.backlash else None
    return {
        "torque_noise_nm": noise, "backlash_deg": backlash, "method": method, "seed": seed,
        "samples": len(syn.frame), "max_stiffness_error_pct": k_err,
        "backlash_width_error_pct": width_err, "max_pairs_error": n_err, "runtime_s": runtime,
    }


def main() -> int:
    rows = [run_one(noise, bl, method, seed) for noise, bl, method in SCENARIOS for seed in SEEDS]
    header = (f"{'noise N·m':>9} {'backlash°':>9} {'method':>10} {'seed':>4} {'K err %':>8} "
              f"{'width err %':>11} {'|n err|':>8} {'time s':>7}")
    print(header)
    print("-" * len(header))
    for r in rows:
        width = "n/a" if r["backlash_width_error_pct"] is None else f"{r['backlash_width_error_pct']:+.2f}"
        print(f"{r['torque_noise_nm']:>9.3f} {r['backlash_deg']:>9.2f} {r['method']:>10} {r['seed']:>4} "
              f"{r['max_stiffness_error_pct']:>8.2f} {width:>11} {r['max_pairs_error']:>8.2f} "
              f"{r['runtime_s']:>7.2f}")
    worst = {
        "max_stiffness_error_pct": max(r["max_stiffness_error_pct"] for r in rows),
        "max_abs_backlash_width_error_pct": max(abs(r["backlash_width_error_pct"]) for r in rows
                                                if r["backlash_width_error_pct"] is not None),
        "max_pairs_error": max(r["max_pairs_error"] for r in rows),
    }
    print(f"worst: K {worst['max_stiffness_error_pct']:.2f} % (limit 3), width "
          f"{worst['max_abs_backlash_width_error_pct']:.2f} % (limit 5), "
          f"|n| {worst['max_pairs_error']:.2f} pairs (limit 1)")
    out = Path(__file__).resolve().parent / "results" / "stiffness_curve.json"
    write_json(out, {
        "benchmark": "stiffness_curve", "issue": 7,
        "limits": {"max_stiffness_error_pct": 3.0, "backlash_width_error_pct": 5.0, "max_pairs_error": 1.0},
        "worst": worst, "python": platform.python_version(), "rows": rows,
    })
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
