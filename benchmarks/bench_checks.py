"""Do the checks see what is wrong, and do the gates and the orientation test accept the truth? (issue 27)

    python benchmarks/bench_checks.py [--sessions 200] [--orientation-sessions 200] [--jobs 2]
                                      [--cases ...] [--noises 0.0005 0.005] [--out FILE]

Sessions from the benchmark's own generator (``truth_tables.py``: exact truth, the
weight pieces of a real rig, no code shared with the analysis), analysed by
``analyze_session`` with the rig. Per case and angle noise, the rate with its
Clopper–Pearson 95 % interval and the target it must reach:

- ``inverted_orientation``: three orientations, the angle sign of the middle one
  inverted (a camera flipped between orientations). A session counts when the
  ``angle sign`` issue names that orientation and no other, and none of its loop
  figures is shown. Target ≥ 95 % of sessions.
- ``zero_outlier_10sigma``: two orientations, a ±10σ angle error on the first
  orientation's zero-torque image after the first unloading. A session counts when
  the outlier list is exactly that image. Target ≥ 90 %.
- ``bilinear_gate``: the bilinear model's lack-of-fit gate on bilinear loops: the
  share of loops it rejects (the true model flagged). Target ≤ 5 %. Also the share
  of clean loops with any image listed as an outlier.
- ``preisach_gate``: the Preisach gate on smooth Masing loops. Target ≤ 5 %.
- ``no_effect_3x6``: 3 cycles × 6 orientations, 2 % cycle-to-cycle scatter, no
  orientation effect: sessions with any figure called significant (the Holm family).
  Target ≤ 7 %.
- ``effect_10pct_3x6``: the same with a 10 % orientation effect on every stiffness:
  sessions with at least one figure significant. Target ≥ 90 %.

Prints a table and writes ``benchmarks/results/checks.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import zlib
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's package, not an installed one
from common import git_commit, one_core  # noqa: E402

one_core()

import numpy as np  # noqa: E402
import truth_tables as T  # noqa: E402

RIG = dict(step_mass_kg=T.STEP_MASS_KG, mass_std_kg=T.MASS_STD_KG, gravity_m_per_s2=T.G, arm_radius_m=T.R_M)
SIX = (0, 60, 120, 180, 240, 300)
#: name: (loop kind, table options, "at least" or "at most", target rate, what is counted)
CASES = {
    "inverted_orientation": ("bilinear", dict(orientations=(0, 60, 120)), ">=", 0.95, "sessions"),
    "zero_outlier_10sigma": ("bilinear", dict(orientations=(0, 60)), ">=", 0.90, "sessions"),
    "bilinear_gate": ("bilinear", dict(orientations=(0, 60)), "<=", 0.05, "loops"),
    "preisach_gate": ("masing", dict(orientations=(0, 60)), "<=", 0.05, "loops"),
    "no_effect_3x6": ("bilinear", dict(orientations=SIX, cycles=3), "<=", 0.07, "sessions"),
    "effect_10pct_3x6": ("bilinear", dict(orientations=SIX, cycles=3, orientation_effect=0.10), ">=", 0.90,
                         "sessions"),
}
ORIENTATION_CASES = ("no_effect_3x6", "effect_10pct_3x6")


def _rng(case, noise, rep):
    return np.random.default_rng([zlib.crc32(case.encode()), int(round(noise * 1e7)), rep])


def run_one(task):
    """One session of one case: ``(case, noise, rep) -> {"hits": int, "n": int, ...}``."""
    from vision_torsion.analysis import analyze_session

    case, noise, rep = task
    kind, opts, *_ = CASES[case]
    rng = _rng(case, noise, rep)
    df, _ = T.session_table(kind, angle_std_deg=noise, rng=rng, **opts)
    kw = dict(rig=RIG, max_torque_nm=T.T_MAX, n_draws=10, seed=rep, fit_breaks=False)
    if case == "inverted_orientation":
        df.loc[df["orientation_deg"] == 60, "angle_deg"] *= -1.0
        a = analyze_session(df, fit_preisach=False, **kw)
        named = {i.orientation_deg for i in a.issues if i.figure == "angle sign"}
        shown = a.figures[(a.figures["orientation_deg"] == 60) & np.isfinite(a.figures["value"])]
        return {"hits": int(named == {60.0} and shown.empty), "n": 1}
    if case == "zero_outlier_10sigma":
        m = (df["orientation_deg"] == 0) & (df["phase"] == "positive_unloading") & (df["step"] == T.N_STEPS)
        image = str(df.loc[m, "image"].iloc[0])
        df.loc[m, "angle_deg"] += (1 if rng.random() < 0.5 else -1) * 10 * noise
        a = analyze_session(df, **kw)
        listed = [o["image"] for o in a.checks["outliers"]]
        return {"hits": int(listed == [image]), "n": 1, "listed": listed}
    if case in ORIENTATION_CASES:
        a = analyze_session(df, fit_preisach=False, **kw)
        sig = [f for f, s in a.summary.items() if s["orientation_test"].get("significant")]
        tested = sum(1 for s in a.summary.values() if s["orientation_test"].get("p_value") is not None)
        return {"hits": int(bool(sig)), "n": 1, "tested": tested}
    model = "bilinear" if case == "bilinear_gate" else "preisach"
    a = analyze_session(df, **kw)
    checks = [f["checks"][model] for f in a.fits.values() if model in f["checks"]]
    return {"hits": sum(c.rejected for c in checks), "n": len(checks),
            "outlier_loops": len({(o["orientation_deg"], o["cycle"]) for o in a.checks["outliers"]})}


def clopper_pearson(k, n, level=0.95):
    """Exact binomial interval of a rate ``k/n``."""
    from scipy import stats

    a = 1 - level
    lo = stats.beta.ppf(a / 2, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(1 - a / 2, k + 1, n - k) if k < n else 1.0
    return float(lo), float(hi)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sessions", type=int, default=200, help="sessions per case and noise (two-orientation cases)")
    ap.add_argument("--orientation-sessions", type=int, default=200,
                    help="sessions per noise of the 3 cycles x 6 orientations cases")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--cases", nargs="*", default=list(CASES), choices=list(CASES))
    ap.add_argument("--noises", nargs="*", type=float, default=[0.0005, 0.005])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results" / "checks.json"))
    args = ap.parse_args(argv)
    tasks = [
        (case, noise, rep)
        for case in args.cases
        for noise in args.noises
        for rep in range(args.orientation_sessions if case in ORIENTATION_CASES else args.sessions)
    ]
    if args.jobs > 1:
        from multiprocessing import Pool

        with Pool(args.jobs) as pool:
            results = pool.map(run_one, tasks, chunksize=1)
    else:
        results = [run_one(t) for t in tasks]
    rows = []
    for case in args.cases:
        kind, _, sense, target, unit = CASES[case]
        for noise in args.noises:
            rs = [r for t, r in zip(tasks, results) if t[0] == case and t[1] == noise]
            k, n = sum(r["hits"] for r in rs), sum(r["n"] for r in rs)
            lo, hi = clopper_pearson(k, n)
            rate = k / n if n else math.nan
            ok = rate >= target if sense == ">=" else rate <= target
            row = {"case": case, "noise_deg": noise, "sessions": len(rs), "counted": unit, "k": k, "n": n,
                   "rate": rate, "ci95": [lo, hi], "target": f"{sense} {target:.0%}", "reached": bool(ok)}
            if case in ("bilinear_gate", "preisach_gate"):
                row["loops_with_an_outlier_listed"] = sum(r["outlier_loops"] for r in rs)
            if case == "zero_outlier_10sigma":
                row["wrong_listings"] = [r["listed"] for r in rs if not r["hits"]][:10]
            rows.append(row)
    print(f"{'case':24s} {'noise':>7s} {'count':>12s} {'rate':>7s} {'95% CI':>15s} {'target':>8s}  reached")
    for r in rows:
        print(f"{r['case']:24s} {r['noise_deg']:7.4f} {r['k']:5d}/{r['n']:<4d}{r['counted'][0]} {r['rate']:7.1%} "
              f"{r['ci95'][0]:6.1%}–{r['ci95'][1]:6.1%} {r['target']:>8s}  {'yes' if r['reached'] else 'NO'}")
    out = {"commit": git_commit(), "command": " ".join(["python benchmarks/bench_checks.py", *(argv or sys.argv[1:])]),
           "rows": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
