"""Does every shown figure's u95 cover the PHYSICAL truth? (issue 27)

    python benchmarks/bench_coverage.py [--sessions 100] [--jobs 2] [--cases ...] [--draws 100] [--keep-errors]

(from the repository root; ``PYTHONPATH=.`` when the installed ``vision_torsion`` is another checkout)

Sessions from the benchmark's own generator (``truth_tables.py``), scored against
:func:`truth_tables.physical_truth`: the continuous loop's ``∮τ dθ`` and loss factor, lost
motion at exactly ±3 %/±4 % of T_R on the continuous branches, the width at zero torque,
and the generating K1–K3 and break torques T1/T2 (bilinear: K1 = k_l below T1 = τ_c,
K2 = k_u). Each session has two orientations of one cycle (two loops), at 0.0005° and
0.005° of angle noise; the default 100 sessions per case and noise are 200 loops.

Cases:

- ``fitted_breaks_bilinear``, ``fitted_breaks_three_segment``: no catalogue T1/T2, the
  breaks fitted (the default and the demo's case);
- ``masing_tr_0p5``: a smooth Masing loop with T_R = 0.5 N·m, so ±4 % T_R = ±0.02 N·m
  falls between the levels 0.0196 and 0.0392 N·m;
- ``coarse_rig_masing``, ``coarse_rig_bilinear``: 0.04 kg pieces, levels 0.039 N·m
  apart (no level between 0 and ±0.04 N·m), T_R = 0.5 N·m;
- ``no_rig``: the bilinear tables analysed without a rig (``torque_model_declared=False``,
  what ``vision-torsion analyze TABLE.csv`` does without ``--session`` or rig options):
  every figure must be flagged.

Per figure: loops, shown unflagged, of them within u95 (rate and its Clopper–Pearson 95 %
interval counted over loops, and over sessions — a session's two loops share its weight
pieces, so the session count is the conservative one), withheld, flagged. The target
(issue 27): every figure shown unflagged within its u95 in ≥ 93 % of loops, Clopper–Pearson
lower bound ≥ 90 %. The Preisach fit (the outlier check, not scored here) is off to keep
the run short. Per figure also how wide its u95 are: the median of u95/|error| and the
factor all its u95 would need to cover exactly 95 % of the loops (the 95th percentile of
|error|/u95: 1 honest, below 1 wide, above 1 narrow). Prints the table and writes
``benchmarks/results/coverage.json`` and ``.md`` (``--keep-errors``: each loop's
``(|error|, u95, std)`` too).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import sys
import time
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import truth_tables as T  # noqa: E402
from bench_figures import NOISES, _binomial_interval, _session_rng  # noqa: E402
from common import git_commit  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results" / "coverage.json"
#: name: (loop kind, rig, rated torque T_R (N·m), analysed with the rig)
CASES = {
    "fitted_breaks_bilinear": ("bilinear", "fine", T.T_MAX, True),
    "fitted_breaks_three_segment": ("three_segment", "fine", T.T_MAX, True),
    "masing_tr_0p5": ("masing", "fine", 0.5, True),
    "coarse_rig_masing": ("masing", "coarse", 0.5, True),
    "coarse_rig_bilinear": ("bilinear", "coarse", 0.5, True),
    "no_rig": ("bilinear", "fine", T.T_MAX, False),
}
FIGURES = ("k1", "k2", "k3", "t1", "t2", "loop_energy", "loss_factor", "lost_motion_3pct", "lost_motion_4pct",
           "hysteresis_loss")
TARGET, TARGET_LOWER = 0.93, 0.90


def run_one(task):
    """Analyse one session of a case; per figure ``[loops, shown, covered, withheld, flagged, session_ok]``."""
    case, noise, rep, draws = task
    from vision_torsion.analysis import analyze_session

    kind, rig_name, rated, with_rig = CASES[case]
    rig = T.Rig.coarse() if rig_name == "coarse" else T.Rig()
    df, truth = T.session_table(kind, orientations=(0, 60), angle_std_deg=noise, rig=rig, rated_nm=rated,
                                rng=_session_rng(case, noise, rep))
    kw = dict(max_torque_nm=rig.t_max, rated_torque_nm=rated, n_draws=draws, seed=rep, fit_preisach=False)
    if with_rig:
        kw["rig"] = rig.as_analysis_rig()
    else:
        kw["torque_model_declared"] = False
    a = analyze_session(df, **kw)
    out = {f: [0, 0, 0, 0, 0, 1] for f in FIGURES}
    errs = {f: [] for f in FIGURES}  # (|value − truth|, u95, std) of each shown, unflagged figure
    for r in a.figures.itertuples(index=False):
        t = truth.get((float(r.orientation_deg), int(r.cycle)), {}).get(r.figure)
        if r.figure not in out or t is None:
            continue
        c = out[r.figure]
        c[0] += 1
        if not math.isfinite(r.value):
            c[3] += 1
        elif r.flag:
            c[4] += 1
        else:
            c[1] += 1
            ok = bool(abs(r.value - t) <= r.u95)
            errs[r.figure].append((abs(r.value - t), float(r.u95), float(r.std)))
            c[2] += ok
            c[5] = int(c[5] and ok)
    return case, noise, out, errs


def _widths(pairs):
    """How wide the u95 are for the errors they cover: ``(median u95 / |error|, u95 scale)``.

    The scale is the factor the u95 would need (all multiplied by it) to cover exactly
    95 % of the loops: the 95th percentile of ``|error|/u95``; 1 is an honest u95,
    below 1 a wide one, above 1 a narrow one."""
    if not pairs:
        return None, None
    e, u = np.array(pairs, float)[:, :2].T
    with np.errstate(divide="ignore"):
        ratio = float(np.median(u / e))
    return ratio, float(np.quantile(e / u, 0.95))


def _table(agg, sessions, draws, wall):
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"bench_coverage: {sessions} sessions (2 loops each) per case and noise, {draws} Monte Carlo/bootstrap "
        f"draws, {when}, wall {wall:.0f} s; truth: the physical loop (truth_tables.physical_truth)",
        "",
        "| case | noise (°) | figure | loops | shown unflagged | within u95 | rate [CP 95 %, loops] "
        "| CP lower, sessions | withheld | flagged | target | median u95/|err| | u95 scale for 95 % |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|",
    ]
    rows = []
    for (case, noise), figs in agg.items():
        for fig, (n, shown, cov, withheld, flagged, sess_ok, sess_n, pairs) in figs.items():
            if n == 0:
                continue
            rate = cov / shown if shown else None
            lo, hi = _binomial_interval(cov, shown) if shown else (None, None)
            s_lo = _binomial_interval(sess_ok, sess_n)[0] if shown else None
            verdict = "–" if not shown else ("met" if rate >= TARGET and lo >= TARGET_LOWER else "NOT met")
            txt = f"{100 * rate:.1f} % [{100 * lo:.1f}–{100 * hi:.1f}]" if shown else "–"
            s_txt = f"{100 * s_lo:.1f} %" if shown else "–"
            ratio, scale = _widths(pairs)
            w_txt = f"{ratio:.2f} | {scale:.2f}" if shown else "– | –"
            lines.append(f"| {case} | {noise:g} | {fig} | {n} | {shown} | {cov} | {txt} | {s_txt} | {withheld} | "
                         f"{flagged} | {verdict} | {w_txt} |")
            rows.append(dict(case=case, noise_deg=noise, figure=fig, loops=n, shown=shown, covered=cov, rate=rate,
                             cp_low=lo, cp_high=hi, sessions=sess_n, sessions_all_covered=sess_ok,
                             cp_low_sessions=s_lo, withheld=withheld, flagged=flagged, verdict=verdict,
                             median_u95_over_error=ratio, u95_scale_for_95pct=scale,
                             errors=[[float(f"{v:.4g}") for v in p] for p in pairs]))
    return "\n".join(lines), rows, when


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sessions", type=int, default=100, help="sessions per case and noise (2 loops each; default 100)")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--draws", type=int, default=100, help="Monte Carlo / bootstrap draws per loop (default 100)")
    p.add_argument("--cases", nargs="*", default=list(CASES), choices=list(CASES))
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument("--keep-errors", action="store_true",
                   help="keep each loop's (|error|, u95, std) in the JSON (about 1 MB at 150 sessions)")
    args = p.parse_args(argv)
    t0 = time.time()
    tasks = [(c, n, r, args.draws) for c in args.cases for n in NOISES for r in range(args.sessions)]
    if args.jobs > 1:
        from multiprocessing import Pool

        with Pool(args.jobs) as pool:
            results = []
            for res in pool.imap_unordered(run_one, tasks, chunksize=2):
                results.append(res)
                if len(results) % 20 == 0:
                    print(f"{len(results)}/{len(tasks)} sessions, {time.time() - t0:.0f} s", file=sys.stderr,
                          flush=True)
    else:
        results = [run_one(t) for t in tasks]
    agg = {}
    for case, noise, out, errs in sorted(results, key=lambda r: (list(CASES).index(r[0]), r[1])):
        figs = agg.setdefault((case, noise), {f: [0] * 7 + [[]] for f in FIGURES})
        for f, c in out.items():
            acc = figs[f]
            acc[7].extend(errs[f])
            for i in range(5):
                acc[i] += c[i]
            if c[1]:  # a session counts for the figure when it showed it
                acc[5] += c[5]
                acc[6] += 1
    text, rows, when = _table(agg, args.sessions, args.draws, time.time() - t0)
    if not args.keep_errors:
        for r in rows:
            r.pop("errors")
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".md").write_text(text + "\n")
    args.out.write_text(json.dumps({"date": when, "commit": git_commit(), "sessions": args.sessions,
                                    "draws": args.draws, "wall_s": time.time() - t0, "rows": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
