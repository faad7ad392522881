"""Are the figures right, or do they say why not? (issue 14)

    python benchmarks/bench_figures.py [--reps 50] [--jobs 2] [--cases ...] [--first-rep 0] [--out FILE]
    python benchmarks/bench_figures.py --merge RUN1.json RUN2.json [--out FILE]   # runs on other seeds, added up

Sessions from the benchmark's own generator (``truth_tables.py``: exact truth,
no code shared with the analysis), analysed by ``analyze_session`` with the rig's
weight-piece model, at 0.0005° and 0.005° of angle noise. Truth is
``truth_tables.figure_truth``: the **physical** (continuous) loop's value wherever a
figure has one (loop energy ∮τ dθ, loss factor, lost motion, the width at zero torque,
the generating K1–K3 and break torques; lost motion at ±3 %/±4 % of Tmax, the analysis'
reference without a rated torque), the figure's definition at the measured levels for
the rest (the largest width among the levels; secants and slopes read at measured
levels, where the sampled and the continuous loop agree). For every loop figure
that has a truth, a result is **ok** when it is within its u95 of the truth, or is
withheld (null with a reason) or flagged with a reason; a **miss** is a shown,
unflagged figure off by more than its u95. The session means of the report's budget
table are checked too, as figures ``mean:<figure>``, against the gear's value (the
loop model at each orientation's stiffness, without the cycle-to-cycle draw), and so
are each orientation's means over its cycles (``per_orientation``, the report's metrics
table), as ``orientation_mean:<figure>`` pooled over the orientations, against the
gear's value at that orientation (rated per figure; the case's totals count the loop
figures and session means). Per
case: the worst figure's rate with its Clopper–Pearson 95 % interval, and how many
figures fall below 93 % and how many of them significantly so (the interval counts
sessions, not loops: a session's 2–18 loops share its weight pieces and move together). Its last column
is the sample's own luck, from the generator alone: the share of sessions whose weight error at each
loop tip is within ±1.96σ, the most any analysis that knew σ could cover of a figure resting on that
tip's weights. Prints a table and writes ``benchmarks/results/figures.json``.

Cases: bilinear; three-segment stiffening loop (catalogue T1/T2 given); smooth
Masing loop; no orientation effect (1 and 3 cycles, 2 % cycle-to-cycle
repeatability) and a 10 % one (3 cycles); a failed zero-torque image; half a phase
failed; a 0.2° creep over the run (with the closing image). Plus: a straight line or
a bilinear model shown unflagged where it does not describe the loop ("misfit
shown"), K1–K3 within 1 % at the catalogue T1/T2, and the time of ``analyze`` on a
450-row table (one core).
"""

from __future__ import annotations

import argparse
import datetime
import functools
import json
import math
import os
import sys
import time
import zlib
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import truth_tables as T  # noqa: E402
from common import git_commit  # noqa: E402

NOISES = (0.0005, 0.005)
RIG = dict(step_mass_kg=T.STEP_MASS_KG, mass_std_kg=T.MASS_STD_KG, gravity_m_per_s2=T.G, arm_radius_m=T.R_M)
SIX = (0, 60, 120, 180, 240, 300)
CASES = {
    # name: (kind, table options), in the order they run (results are written as each case ends)
    "bilinear": ("bilinear", dict(orientations=(0, 60))),
    "failed_zero_image": ("bilinear", dict(orientations=(0, 60), fail="zero")),
    "half_phase_failed": ("bilinear", dict(orientations=(0, 60), fail="half_phase")),
    "creep_0p2deg": ("bilinear", dict(orientations=(0, 60), creep_deg=0.2)),
    "three_segment": ("three_segment", dict(orientations=(0, 60))),
    "masing": ("masing", dict(orientations=(0, 60))),
    "no_effect_1_cycle": ("bilinear", dict(orientations=SIX, cycles=1)),
    "effect_10pct_3_cycles": ("bilinear", dict(orientations=SIX, cycles=3, orientation_effect=0.10)),
    "no_effect_3_cycles": ("bilinear", dict(orientations=SIX, cycles=3)),
}
#: The orientation cases check the test, whose values need no Monte Carlo: fewest draws, breaks not fitted.
ORIENTATION_CASES = ("no_effect_1_cycle", "no_effect_3_cycles", "effect_10pct_3_cycles")
ORIENT_FIGURES = ("k_positive_unloading", "hysteresis", "k_negative_loading_secant")
# a straight line through these phases, or the bilinear model on these loops, is a misfit
MISFIT = {
    "bilinear": ("k_negative_loading", "k_positive_loading"),
    "masing": (
        "k_negative_loading",
        "k_positive_loading",
        "k_positive_unloading",
        "k_negative_unloading",
        "bilinear_k_u",
        "bilinear_k_l",
        "bilinear_tau_c",
    ),
    "three_segment": ("k_negative_loading", "k_positive_loading", "bilinear_k_u", "bilinear_k_l", "bilinear_tau_c"),
}


def run_one(task):
    case, noise, rep = task
    from vision_torsion.analysis import analyze_session

    kind, opts = CASES[case]
    # truth: the physical loop wherever a figure has a physical value (truth_tables.figure_truth); the analysis'
    # lost-motion reference is max_torque_nm (no rated torque given)
    df, truth = T.session_table(kind, angle_std_deg=noise, rng=_session_rng(case, noise, rep), rated_nm=T.T_MAX,
                                **opts)
    kw = dict(rig=RIG, max_torque_nm=T.T_MAX, n_draws=40, seed=rep)
    if case in ORIENTATION_CASES:
        kw.update(n_draws=10, fit_breaks=False)
    if kind == "three_segment":
        kw["catalogue_breaks_nm"] = (0.1, 0.25)
    a = analyze_session(df, **kw)
    f = a.figures
    res = {
        "ok": 0,
        "miss": 0,
        "covered": 0,
        "shown": 0,
        "withheld": 0,
        "flagged": 0,
        "misfit_shown": 0,
        "by_figure": {},
        "k_within_1pct": [],
        "orientation": {},
    }
    for r in f.itertuples(index=False):
        key = (float(r.orientation_deg), int(r.cycle))
        t = truth.get(key, {}).get(r.figure)
        if r.figure in MISFIT.get(kind, ()) and math.isfinite(r.value) and not r.flag:
            res["misfit_shown"] += 1
        if t is None:
            continue
        fig = res["by_figure"].setdefault(r.figure, {"ok": 0, "n": 0, "miss": 0})
        fig["n"] += 1
        if not math.isfinite(r.value):
            res["withheld"] += 1
            ok = True
        elif r.flag:
            res["flagged"] += 1
            ok = True
        else:
            res["shown"] += 1
            ok = abs(r.value - t) <= r.u95
            res["covered"] += ok
        res["ok" if ok else "miss"] += 1
        fig["ok"] += ok
        fig["miss"] += not ok
        if kind == "three_segment" and r.figure in ("k1", "k2", "k3") and math.isfinite(r.value):
            res["k_within_1pct"].append(abs(r.value / t - 1) <= 0.01)
    _check_means(res, a, kind, opts)
    for name in ORIENT_FIGURES:
        res["orientation"][name] = a.summary.get(name, {}).get("orientation_test", {}).get("significant")
    return case, noise, rep, res


def _session_rng(case, noise, rep):
    """The generator of one session (its seed: the case, the noise level and the session's number)."""
    return np.random.default_rng([zlib.crc32(case.encode()), int(noise * 1e5), rep])


@functools.lru_cache(maxsize=None)  # the table is written after every case: each row's share once
def _tip_draws_inside(case, noise, ranges):
    """Of the sessions (seed ranges ``[lo, hi)``), the fractions whose weight error at the +Tmax and at the
    −Tmax tip lies within ±1.96σ: what an analysis that knew σ exactly would cover of a figure that rests on
    that tip's weights alone. The session's one draw of its pieces moves every such figure of the session
    together, so this is the sample's own luck, independent of the analysis."""
    inside = []
    for lo, hi in ranges:
        for rep in range(lo, hi):
            d_top, d_bottom = T.tip_errors_nm(T.piece_masses(_session_rng(case, noise, rep)))
            inside.append((abs(d_top) <= 1.96 * T.TIP_STD_NM, abs(d_bottom) <= 1.96 * T.TIP_STD_NM))
    return [float(v) for v in np.mean(inside, axis=0)] if inside else None


def _gear_truth(kind, effect, orientation):
    """The gear's figures at one orientation (its stiffness scale, no cycle-to-cycle draw), as the loops'."""
    model = T.make_model(kind, 1.0 + effect * math.cos(math.radians(orientation)))
    return T.figure_truth(kind, model, rated_nm=T.T_MAX)


def _check_means(res, a, kind, opts):
    """Session means (the report's budget table) as figures ``mean:<figure>``: ok when within their u95 of
    the gear's value over the loops' orientations (no cycle-to-cycle scatter), or withheld or flagged."""
    effect = opts.get("orientation_effect", 0.0)
    # the gear's figure at each orientation: the generator's loop model at that orientation's stiffness scale
    # (the same formula as truth_tables.session_table), without the cycle's own repeatability draw
    gear = {}
    f = a.figures
    for fig, s in a.summary.items():
        rows = f[(f.figure == fig) & np.isfinite(f.value.to_numpy(float))]
        ts = []
        for o in rows.orientation_deg:
            if o not in gear:
                gear[o] = _gear_truth(kind, effect, o)
            ts.append(gear[o].get(fig))
        if not ts or any(t is None for t in ts):
            continue
        t = float(np.mean(ts))
        b = res["by_figure"].setdefault("mean:" + fig, {"ok": 0, "n": 0, "miss": 0})
        b["n"] += 1
        if s.get("mean") is None or s.get("mean_u95") is None:
            res["withheld"] += 1
            ok = True
        elif s.get("flag"):
            res["flagged"] += 1
            ok = True
        else:
            res["shown"] += 1
            ok = abs(s["mean"] - t) <= s["mean_u95"]
            res["covered"] += ok
        res["ok" if ok else "miss"] += 1
        b["ok"] += ok
        b["miss"] += not ok
    # each orientation's mean over its cycles (summary.json's per_orientation, the report's metrics table), as
    # ``orientation_mean:<figure>`` pooled over the orientations, against the gear's value at that orientation;
    # ok when within its u95, or withheld or flagged (a mean of one cycle is flagged)
    for r in a.per_orientation.itertuples(index=False):
        o = r.orientation_deg
        if o not in gear:
            gear[o] = _gear_truth(kind, effect, o)
        t = gear[o].get(r.figure)
        if t is None:
            continue
        # counted per figure only (the case's totals are the loop figures and session means, as in earlier runs)
        b = res["by_figure"].setdefault("orientation_mean:" + r.figure, {"ok": 0, "n": 0, "miss": 0})
        b["n"] += 1
        withheld = not (math.isfinite(r.mean) and math.isfinite(r.u95))
        ok = withheld or bool(r.flag) or abs(r.mean - t) <= r.u95
        b["ok"] += ok
        b["miss"] += not ok


def time_analyze(tmp: Path) -> float:
    """CPU seconds of ``analyze_table`` (one core) on a 450-row table, best of 3."""
    from vision_torsion.report.analyze import analyze_table

    df, _ = T.session_table("bilinear", orientations=SIX, rng=np.random.default_rng(0))
    path = tmp / "table.csv"
    df.to_csv(path, index=False)
    best = math.inf
    for _ in range(3):
        t0 = time.process_time()
        analyze_table(path, out_dir=tmp / "out")
        best = min(best, time.process_time() - t0)
    return best, len(df)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--reps", type=int, default=50, help="sessions per case and noise level (default 50)")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--cases", nargs="*", default=list(CASES))
    p.add_argument(
        "--first-rep", type=int, default=0, help="seed of the first session (default 0; another value: fresh sessions)"
    )
    p.add_argument("--out", type=Path, default=None, help="results file (default benchmarks/results/figures.json)")
    p.add_argument(
        "--merge",
        type=Path,
        nargs="+",
        default=None,
        metavar="FILE",
        help="run nothing: add up the results files of earlier runs (other seeds, the same analysis) into --out",
    )
    args = p.parse_args(argv)
    t0 = time.time()
    agg = {}
    out = args.out or Path(__file__).resolve().parent / "results" / "figures.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    if args.merge:
        return _merge(args.merge, out)
    from multiprocessing import Pool

    pool = Pool(args.jobs) if args.jobs > 1 else None
    for case in args.cases:
        tasks = [(case, n, r) for n in NOISES for r in range(args.first_rep, args.first_rep + args.reps)]
        results = pool.map(run_one, tasks, chunksize=2) if pool else [run_one(t) for t in tasks]
        _aggregate(agg, results)
        print(f"{case}: done at {time.time() - t0:.0f} s", flush=True)
        _write(agg, args, time.time() - t0, out, None, None)
    if pool:
        pool.close()
    wall = time.time() - t0
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        cpu, rows = time_analyze(Path(tmp))
    _write(agg, args, wall, out, cpu, rows, show=True)


def _merge(paths, out):
    """Add up results files of runs on other seeds into one table (their seed ranges must not overlap)."""
    agg, seeds, parts = {}, {}, []
    for path in paths:
        d = json.loads(path.read_text())
        first, reps = d.get("first_rep", 0), d["reps"]
        if first is None:
            raise SystemExit(f"{path}: already added up from {len(d.get('parts') or [])} runs; give those runs instead")
        parts.append(f"{path.name}: seeds {first}–{first + reps - 1}, run {d['date']}")
        for c in d["cases"]:
            key = (c["case"], c["noise_deg"])
            for lo, hi in seeds.get(key, []):
                if first < hi and lo < first + reps:
                    both = f"{max(lo, first)}–{min(hi, first + reps) - 1}"
                    raise SystemExit(f"{path}: {key[0]} at {key[1]:g}° repeats seeds {both}")
            seeds.setdefault(key, []).append((first, first + reps))
            if c.get("k_within_1pct") is not None and c.get("k_fits") is None:
                raise SystemExit(f"{path}: {key[0]} has a K1–K3 rate but no counts (k_fits); it cannot be added up")
            a = agg.setdefault(key, _empty())
            for k in _COUNTS:
                a[k] += c.get(k) or 0  # a run without K1–K3 fits has no k_fits
            for k, v in c["orient"].items():
                a["orient"][k] += v
            for fig, v in c["by_figure"].items():
                b = a["by_figure"].setdefault(fig, {"ok": 0, "n": 0, "sessions": 0})
                b["ok"] += v["ok"]
                b["n"] += v["n"]
                # runs before the count was kept had the figure in every session (the means of one loop were
                # flagged, not left out)
                b["sessions"] += v.get("sessions", c["sessions"])
    sessions = sorted({a["sessions"] for a in agg.values()})
    args = argparse.Namespace(
        reps=sessions[0] if len(sessions) == 1 else sessions, first_rep=None, parts=parts, seeds=seeds
    )
    _write(agg, args, None, out, None, None, show=True)


#: Counts of each session's result (``run_one``) that add up over its sessions.
_SESSION_COUNTS = ("ok", "miss", "shown", "covered", "withheld", "flagged", "misfit_shown")
#: Counts per case that add up over sessions (and over runs, by ``--merge``).
_COUNTS = ("sessions", "sessions_ok", *_SESSION_COUNTS, "k_fits", "k_fits_within_1pct")


def _empty():
    return {**{k: 0 for k in _COUNTS}, "orient": {k: 0 for k in ORIENT_FIGURES}, "by_figure": {}}


def _aggregate(agg, results):
    for case, noise, rep, res in results:
        a = agg.setdefault((case, noise), _empty())
        a["sessions"] += 1
        for k in _SESSION_COUNTS:
            a[k] += res[k]
        a["sessions_ok"] += res["miss"] == 0
        a["k_fits"] += len(res["k_within_1pct"])
        a["k_fits_within_1pct"] += sum(res["k_within_1pct"])
        for k, v in res["orientation"].items():
            a["orient"][k] += bool(v)
        for fig, v in res["by_figure"].items():
            b = a["by_figure"].setdefault(fig, {"ok": 0, "n": 0, "sessions": 0})
            b["ok"] += v["ok"]
            b["n"] += v["n"]
            b["sessions"] += 1


def _binomial_interval(k, n, level=0.95):
    """Clopper–Pearson interval of a rate k/n (exact, from the beta distribution)."""
    from scipy import special

    if n == 0:
        return 0.0, 1.0
    a = (1 - level) / 2
    lo = special.betaincinv(k, n - k + 1, a) if k > 0 else 0.0
    hi = special.betaincinv(k + 1, n - k, 1 - a) if k < n else 1.0
    return float(lo), float(hi)


def _session_interval(v, sessions):
    """Interval of a figure's rate counting sessions, not loops: the loops of a session share its weight
    pieces (the dominant error at 0.0005°), so they are not independent trials. Exact when they move together,
    conservative when they do not."""
    n = min(v["n"], v.get("sessions", sessions))
    return _binomial_interval(round(v["ok"] / v["n"] * n) if v["n"] else 0, n)


def _write(agg, args, wall, path, cpu, rows, show=False):
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    if args.first_rep is None:  # a merge
        head = [f"bench_figures: {args.reps} sessions per case and noise, added up {when} from:"]
        head += [f"- {part}" for part in args.parts]
    else:
        head = [
            f"bench_figures: {args.reps} sessions per case and noise (seeds {args.first_rep}–"
            f"{args.first_rep + args.reps - 1}), {when}, wall {wall:.0f} s, load {os.getloadavg()[0]:.1f}"
        ]
    lines = [
        *head,
        "",
        "| case | noise (°) | sessions | figures ok (covered/withheld/flagged of all) | sessions with no miss "
        "| worst figure: ok [95 % binomial interval] | figures below 93 % (of them: interval below 93 %) "
        "| shown unflagged: within u95 | misfit shown unflagged "
        "| orientation 'significant' (k_pu / hyst / k_nl secant) | K1–K3 within 1 % "
        "| sessions whose tip weight error is within ±1.96σ (+Tmax / −Tmax) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    out = []
    for (case, noise), a in agg.items():
        n_fig = a["ok"] + a["miss"]
        ranges = args.seeds[(case, noise)] if args.first_rep is None else [(args.first_rep, args.first_rep + args.reps)]
        tips = _tip_draws_inside(case, noise, tuple(map(tuple, ranges)))
        worst = min(((v["ok"] / v["n"]), fig) for fig, v in a["by_figure"].items()) if a["by_figure"] else (1.0, "-")
        lo, hi = _session_interval(a["by_figure"].get(worst[1], {"ok": 0, "n": 0}), a["sessions"])
        below = [v for v in a["by_figure"].values() if v["ok"] < 0.93 * v["n"]]
        sig = [v for v in below if _session_interval(v, a["sessions"])[1] < 0.93]
        orient = " / ".join(f"{100 * a['orient'][k] / a['sessions']:.0f} %" for k in ORIENT_FIGURES)
        k_rate = a["k_fits_within_1pct"] / a["k_fits"] if a["k_fits"] else None
        k_ok = f"{100 * k_rate:.0f} % of {a['k_fits']}" if k_rate is not None else "–"
        cov = f"{100 * a['covered'] / a['shown']:.1f} %" if a["shown"] else "–"
        lines.append(
            f"| {case} | {noise:g} | {a['sessions']} | {100 * a['ok'] / max(n_fig, 1):.1f} % "
            f"({a['covered']}/{a['withheld']}/{a['flagged']} of {n_fig}) | "
            f"{100 * a['sessions_ok'] / a['sessions']:.0f} % | {100 * worst[0]:.1f} % [{100 * lo:.1f}–{100 * hi:.1f}] "
            f"{worst[1]} | {len(below)} of {len(a['by_figure'])} ({len(sig)}) | "
            f"{cov} | {a['misfit_shown']} | {orient} | {k_ok} | {100 * tips[0]:.1f} % / {100 * tips[1]:.1f} % |"
        )
        out.append(
            {
                "case": case,
                "noise_deg": noise,
                **a,
                "k_within_1pct": k_rate,
                "tip_draws_within_1p96_sigma": tips,
            }
        )
    if cpu is not None:
        lines += ["", f"analyze_table of a {rows}-row table: {cpu:.2f} s CPU (one core, best of 3); target ≤ 3 s"]
    text = "\n".join(lines)
    if show:
        print(text)
    path.with_suffix(".md").write_text(text + "\n")
    path.write_text(
        json.dumps(
            {
                "date": when,
                "reps": args.reps,
                "first_rep": args.first_rep,
                "parts": getattr(args, "parts", None),
                "commit": git_commit(),
                "wall_s": wall,
                "analyze_cpu_s": cpu,
                "rows": rows,
                "cases": out,
            },
            indent=1,
            default=lambda o: o.item() if hasattr(o, "item") else str(o),
        )
    )


if __name__ == "__main__":
    main()
