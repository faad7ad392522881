"""Side-by-side accuracy and speed: our pipeline, the library peers, the physical limit.

Run (one command; about 6-8 minutes on 2 cores)::

    python benchmarks/bench_peers.py                 # all scenes, 3 repeats: 63 angles per scene
    python benchmarks/bench_peers.py --quick         # 1 repeat, every third angle, no files written
    python benchmarks/bench_peers.py --scenes standard,jpeg --repeats 5

For every scene of ``synthetic/`` listed below and each repeat it renders, for
every angle of the scene's ``[sweep]``, a reference image at 0° and the image at
that angle (every image a fresh noise realisation, seeded from (scene, repeat,
image) so a run is reproducible bit for bit), measures both with every method of
:mod:`peers`, and computes the angle of the rotated image against its reference.
An angle's error therefore contains both images' errors, exactly like the
Cramér–Rao bound it is compared with (:func:`vision_torsion.synthetic.bounds.angle_bound_deg`
of the same two rotations, combined over the sweep as an RMS). Each angle has its
own reference so that the errors are independent: with one reference shared by a
whole sweep, its error would be common to every angle and the RMS would rest on a
handful of reference images.

Per scene and method the table gives:

- ``RMS`` and ``max |err|`` of the angle error (deg) over the angles whose two images
  both gave the right marker pair; ``bias``: the mean error;
- ``failed``: angles lost because the method raised on either image;
- ``wrong``: angles where the method returned a centre more than 3 px from every true
  marker centre in either image (a wrong object), kept out of RMS and max;
- ``CPU ms/img`` and ``wall ms/img``: median CPU and wall time per image of the
  method on the decoded image array (decoding excluded: images are rendered in
  memory; JPEG images are decoded by the renderer before timing), each worker
  process single-threaded (BLAS and OpenCV limited to one thread). The CPU time is
  the better estimate of the time on an idle core when the machine is shared; the
  speed target is judged on it;
- ``RMS/CRB``: RMS over the RMS Cramér–Rao bound of the sweep. The bound knows no
  JPEG (not Gaussian noise), and on the tilted scene errors are against the disk's
  true rotation, which the uncorrected image line does not follow (the plane
  correction is another module's job): those ratios are not "efficiency".

For our default the honesty check is printed too: the mean reported
``angle_std_deg`` over the empirical RMS (target 0.7-1.3).

Results: ``benchmarks/results/peers.json`` (every number, the date and the machine)
and ``benchmarks/results/peers.md`` (the tables, ready for docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:  # run as a script from anywhere, or imported by tests
    sys.path.insert(0, str(HERE))

from common import machine_info, one_core  # noqa: E402

one_core()  # before NumPy loads its BLAS; workers inherit the environment

import numpy as np  # noqa: E402
from peers import PEERS, PeerFailure  # noqa: E402

ROOT = HERE.parent
SCENE_DIR = ROOT / "vision_torsion" / "synthetic" / "scenes"
RESULTS = HERE / "results"

#: Scenes in table order, with the file stem in ``synthetic/`` and whether the
#: Cramér-Rao target (within 1.5x) applies (no JPEG, no tilt).
SCENES = (
    ("standard", "Standard", True),
    ("small_target", "Small target (r = 15 px)", True),
    ("low_contrast", "Low contrast, noisy, uneven lighting", True),
    ("distractors", "Distractors (bolt holes, wire, dust)", True),
    ("jpeg", "JPEG quality 90", False),
    ("twelve_bit", "12-bit", True),
    ("tilted", "Tilted 3° + barrel distortion (uncorrected)", False),
)
#: One line per method for the markdown file.
PEER_NOTES = {
    "hough_alt": "`cv2.HoughCircles(HOUGH_GRADIENT_ALT)` after a σ = 1.5 px blur, dp 1.5, "
                 "centres as returned (on the accumulator grid)",
    "otsu_ellipse": "blur σ = 1 px, global Otsu, 5 px opening, `findContours`, `fitEllipse`",
    "moments": "background plane subtracted, negative weights clipped, intensity centroid within r + 3 px",
    "canny_circle": "`skimage.feature.canny` (σ = 2) edge pixels near each blob, "
                    "`CircleModel.from_estimate`, one 3σ outlier pass",
    "ml_disc": "least-squares (Gaussian ML) fit of an exact Gaussian-blurred disc with lighting plane, "
               "8 parameters, `scipy.optimize.least_squares`",
    "ours_algebraic": "`measure_pair(..., MeasureSettings(fit=\"algebraic\"))`: the paper's Kasa fit on our "
                      "sub-pixel edge points",
    "ours_default": "`measure_pair(image)` with default settings",
}
WRONG_PX = 3.0  # a returned centre farther than this from every true centre is a wrong object
BASE_SEED = 20240808


def _wrap180(x):
    return (x + 90.0) % 180.0 - 90.0


def _direction_deg(c) -> float:
    """Direction of the line between two centres (deg, CCW as displayed), in (-90, 90]."""
    from vision_torsion.angle import line_direction_deg

    return float(line_direction_deg(c[0], c[1]))


def _is_wrong(centres, truth) -> bool:
    d = np.hypot(centres[:, None, 0] - truth[None, :, 0], centres[:, None, 1] - truth[None, :, 1])
    return bool((d.min(axis=1) > WRONG_PX).any())


_WARM: set = set()


def _measure_all(image, truth):
    """Every method on one image: {name: (Detection|None, seconds, status)}."""
    out = {}
    for peer in PEERS:
        if peer.name not in _WARM:  # first call in a process pays imports and caches
            try:
                peer.func(image)
            except PeerFailure:
                pass
            _WARM.add(peer.name)
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            det = peer.func(image)
            cpu, wall = time.process_time() - c0, time.perf_counter() - t0
            status = "wrong" if _is_wrong(det.centres, truth) else "ok"
        except PeerFailure as exc:
            cpu, wall = time.process_time() - c0, time.perf_counter() - t0
            det, status = None, f"failed: {exc}"
        out[peer.name] = (det, (cpu, wall), status)
    return out


def run_repeat(stem: str, scene_index: int, repeat: int, angles) -> dict:
    """One pass over the sweep: per angle a fresh 0° reference and the rotated image,
    every method on both. Runs in a worker."""
    from vision_torsion.angle import pair_angle
    from vision_torsion.synthetic import load_scene, render

    scene = load_scene(SCENE_DIR / f"{stem}.toml")

    def rng(k):
        return np.random.default_rng(np.random.SeedSequence([BASE_SEED, scene_index, repeat, k]))

    rows = []
    times = {p.name: [] for p in PEERS}
    for k, angle in enumerate(angles):
        ref = render(scene, 0.0, seed=rng(2 * k))
        cur = render(scene, float(angle), seed=rng(2 * k + 1))
        ref_m = _measure_all(ref.image, ref.centres)
        cur_m = _measure_all(cur.image, cur.centres)
        for peer in PEERS:
            (rd, rt, rs), (cd, ct, cs) = ref_m[peer.name], cur_m[peer.name]
            times[peer.name] += [rt, ct]  # (cpu, wall) pairs
            row = {"method": peer.name, "repeat": repeat, "angle_true_deg": float(angle),
                   "angle_deg": None, "error_deg": None, "angle_std_deg": None}
            if rs.startswith("failed") or cs.startswith("failed"):
                row["status"] = "failed"
                row["reason"] = ("reference " + rs) if rs.startswith("failed") else cs
            else:
                row["status"] = "wrong" if "wrong" in (rs, cs) else "ok"
                if rd.pair is not None:
                    res = pair_angle(rd.pair, cd.pair)
                    a, std = res.angle_deg, res.angle_std_deg
                else:
                    a, std = _wrap180(_direction_deg(cd.centres) - _direction_deg(rd.centres)), None
                row.update(angle_deg=a, error_deg=a - float(angle), angle_std_deg=std)
            rows.append(row)
    return {"scene": stem, "repeat": repeat, "rows": rows, "times_s": times}


def scene_bound(stem: str, angles) -> dict:
    """Cramér-Rao bound (deg) of each sweep angle against the 0° reference. Runs in a worker."""
    from vision_torsion.synthetic import load_scene
    from vision_torsion.synthetic.bounds import angle_bound_deg

    scene = load_scene(SCENE_DIR / f"{stem}.toml")
    b = [angle_bound_deg(scene, float(a), reference_deg=0.0) for a in angles]
    return {"scene": stem, "bounds_deg": b, "crb_rms_deg": float(np.sqrt(np.mean(np.square(b))))}


def summarise(rows, times, crb_rms) -> dict:
    """Per-method statistics of one scene."""
    out = {}
    for peer in PEERS:
        mine = [r for r in rows if r["method"] == peer.name]
        ok = [r for r in mine if r["status"] == "ok"]
        err = np.array([r["error_deg"] for r in ok], dtype=np.float64)
        rms = float(np.sqrt(np.mean(err**2))) if err.size else float("nan")
        s = {
            "label": peer.label,
            "library_peer": peer.library_peer,
            "n_angles": len(mine),
            "n_ok": len(ok),
            "n_failed": sum(r["status"] == "failed" for r in mine),
            "n_wrong": sum(r["status"] == "wrong" for r in mine),
            "rms_deg": rms,
            "max_abs_deg": float(np.max(np.abs(err))) if err.size else float("nan"),
            "bias_deg": float(np.mean(err)) if err.size else float("nan"),
            "cpu_ms_per_image_median": 1e3 * float(np.median([t[0] for t in times[peer.name]])),
            "wall_ms_per_image_median": 1e3 * float(np.median([t[1] for t in times[peer.name]])),
            "wall_ms_per_image_mean": 1e3 * float(np.mean([t[1] for t in times[peer.name]])),
            "rms_over_crb": rms / crb_rms,
            "failure_reasons": sorted({r.get("reason", "") for r in mine if r["status"] == "failed"})[:5],
        }
        stds = [r["angle_std_deg"] for r in ok if r["angle_std_deg"] is not None]
        if stds and rms > 0:
            s["mean_reported_std_deg"] = float(np.mean(stds))
            s["reported_std_over_rms"] = float(np.mean(stds)) / rms
        out[peer.name] = s
    return out


def _columns(rows) -> dict:
    """Per-method measurement columns (compact JSON): true angle, error, reported std, status."""
    out = {}
    for peer in PEERS:
        mine = [r for r in rows if r["method"] == peer.name]
        out[peer.name] = {
            "angle_true_deg": [r["angle_true_deg"] for r in mine],
            "error_deg": [None if r["error_deg"] is None else round(r["error_deg"], 8) for r in mine],
            "angle_std_deg": [None if r["angle_std_deg"] is None else round(r["angle_std_deg"], 8) for r in mine],
            "status": [r["status"] for r in mine],
        }
    return out


def _fmt(x, spec):
    return "—" if x is None or not np.isfinite(x) else format(x, spec)


def scene_table(label, summary, crb_rms, n_images) -> str:
    """Markdown table of one scene."""
    lines = [
        f"**{label}** — Cramér–Rao bound (RMS over the sweep) {crb_rms:.5f}°; "
        f"{n_images} images per method",
        "",
        "| Method | RMS (°) | max abs (°) | bias (°) | failed | wrong | CPU ms/img | wall ms/img | RMS / CRB |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for peer in PEERS:
        s = summary[peer.name]
        lines.append(
            f"| {s['label']} | {_fmt(s['rms_deg'], '.5f')} | {_fmt(s['max_abs_deg'], '.5f')} | "
            f"{_fmt(s['bias_deg'], '+.5f')} | {s['n_failed']}/{s['n_angles']} | {s['n_wrong']} | "
            f"{_fmt(s['cpu_ms_per_image_median'], '.1f')} | {_fmt(s['wall_ms_per_image_median'], '.1f')} | "
            f"{_fmt(s['rms_over_crb'], '.2f')} |"
        )
    d = summary["ours_default"]
    if "reported_std_over_rms" in d:
        lines += ["", f"Honesty of our default: mean reported angle_std_deg {d['mean_reported_std_deg']:.5f}° "
                      f"÷ RMS {d['rms_deg']:.5f}° = {d['reported_std_over_rms']:.2f} (target 0.70–1.30)"]
    return "\n".join(lines)


def _ratio_ci(results_scene: dict, ours: str, other: str, n_boot: int = 2000) -> str:
    """95 % interval of RMS(ours) / RMS(other) by a paired bootstrap over the angles.

    Both methods measured the same images, so their errors are correlated and the
    ratio is known far better than either RMS alone (±9 % for 63 angles)."""
    cols = results_scene["measurements"]
    a = np.array([np.nan if e is None else e for e in cols[ours]["error_deg"]], dtype=np.float64)
    b = np.array([np.nan if e is None else e for e in cols[other]["error_deg"]], dtype=np.float64)
    both = np.isfinite(a) & np.isfinite(b)
    a, b = a[both], b[both]
    if a.size < 5:
        return ""
    idx = np.random.default_rng(12345).integers(0, a.size, size=(n_boot, a.size))
    ratio = np.sqrt(np.mean(a[idx] ** 2, axis=1) / np.mean(b[idx] ** 2, axis=1))
    lo, hi = np.percentile(ratio, [2.5, 97.5])
    return f", 95 % CI {lo:.2f}-{hi:.2f} (paired bootstrap, {a.size} angles)"


def check_targets(results: dict, scene_meta) -> list[dict]:
    """The "Must reach" items of issues 2 and 8, each with the numbers behind it."""
    checks = []
    for stem, _, crb_target in scene_meta:
        if stem not in results:
            continue
        s = results[stem]["methods"]
        ours = s["ours_default"]
        note = (" (uncorrected tilt: every method carries the same bias, so the order is not about noise)"
                if stem == "tilted" else "")
        for scope, keep in (("method", lambda k: True), ("method but the ML reference", lambda k: k != "ml_disc")):
            others = {k: v for k, v in s.items()
                      if k != "ours_default" and keep(k) and np.isfinite(v["rms_deg"])}
            best = min(others.items(), key=lambda kv: kv[1]["rms_deg"]) if others else None
            checks.append({
                "target": f"{stem}: our default more accurate than every other {scope}",
                "met": bool(best is None or (ours["rms_deg"] <= best[1]["rms_deg"] and not ours["n_failed"])),
                "detail": (f"ours {ours['rms_deg']:.5f}° ({ours['n_failed']} failed, {ours['n_wrong']} wrong); "
                           f"best other {best[0]} {best[1]['rms_deg']:.5f}° "
                           f"(ours / best = {ours['rms_deg'] / best[1]['rms_deg']:.2f}"
                           f"{_ratio_ci(results[stem], 'ours_default', best[0])})" + note)
                if best else "no other method measured",
            })
        if crb_target:
            checks.append({
                "target": f"{stem}: our default within 1.5x the Cramér-Rao bound",
                "met": bool(ours["rms_over_crb"] <= 1.5),
                "detail": f"RMS/CRB = {ours['rms_over_crb']:.2f}",
            })
        if "reported_std_over_rms" in ours and stem != "tilted":  # tilted: uncorrected bias dominates
            q = ours["reported_std_over_rms"]
            checks.append({
                "target": f"{stem}: reported angle_std within ±30% of the RMS",
                "met": bool(0.7 <= q <= 1.3),
                "detail": f"mean reported std / RMS = {q:.2f}",
            })
        ml = s.get("ml_disc")
        if ml and np.isfinite(ml["rms_deg"]):
            speed = ml["cpu_ms_per_image_median"] / ours["cpu_ms_per_image_median"]
            ratio = ours["rms_deg"] / ml["rms_deg"]
            checks.append({
                "target": f"{stem}: >= 4x faster than the ML reference at <= 1.2x its error",
                "met": bool(speed >= 4 and ratio <= 1.2),
                "detail": f"speed-up {speed:.1f}x (CPU time), error ratio {ratio:.2f}"
                          f"{_ratio_ci(results[stem], 'ours_default', 'ml_disc')}",
            })
    if "standard" in results:
        s = results["standard"]["methods"]
        ours = s["ours_default"]
        lib = {k: v for k, v in s.items() if v["library_peer"]}
        worst = min(lib.items(), key=lambda kv: kv[1]["rms_deg"] if np.isfinite(kv[1]["rms_deg"]) else np.inf)
        checks.append({
            "target": "standard: >= 3x more accurate than every library peer",
            "met": bool(worst[1]["rms_deg"] / ours["rms_deg"] >= 3),
            "detail": f"closest library peer {worst[0]} {worst[1]['rms_deg']:.5f}° = "
                      f"{worst[1]['rms_deg'] / ours['rms_deg']:.1f}x ours",
        })
        checks.append({
            "target": "standard: RMS angle error <= 0.0007° (issue 2)",
            "met": bool(ours["rms_deg"] <= 0.0007),
            "detail": f"RMS {ours['rms_deg']:.5f}°",
        })
    return checks


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true",
                    help="1 repeat and every third sweep angle; prints only (writes no result files)")
    ap.add_argument("--scenes", default=",".join(s for s, _, _ in SCENES),
                    help="comma-separated scene names from synthetic/ (default: all seven)")
    ap.add_argument("--repeats", type=int, default=None,
                    help="reference + sweep renders per scene (default 3, --quick 1)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--no-write", action="store_true", help="print only, do not write results/")
    args = ap.parse_args(argv)

    from common import write_result

    from vision_torsion.synthetic import load_scene

    known = {s: (label, crb) for s, label, crb in SCENES}
    wanted = [s.strip() for s in args.scenes.split(",") if s.strip()]
    unknown = [s for s in wanted if s not in known]
    if unknown:
        ap.error(f"unknown scene(s) {unknown}; choose from {list(known)}")
    meta = [(s, known[s][0], known[s][1]) for s in wanted]
    repeats = args.repeats or (1 if args.quick else 3)
    write = not (args.quick or args.no_write)

    angles = {}
    for stem, *_ in meta:
        a = list(load_scene(SCENE_DIR / f"{stem}.toml").sweep.angles_deg)
        angles[stem] = a[::3] if args.quick else a
    index = {s: i for i, (s, _, _) in enumerate(SCENES)}

    info = machine_info()
    t_start = time.perf_counter()
    print(f"bench_peers: {len(meta)} scene(s), {repeats} repeat(s), {args.jobs} worker(s); "
          f"load average {info['load_average_1_5_15min']}", flush=True)
    with ProcessPoolExecutor(max_workers=args.jobs, initializer=one_core) as pool:
        bound_f = {s: pool.submit(scene_bound, s, angles[s]) for s, *_ in meta}
        rep_f = [(s, pool.submit(run_repeat, s, index[s], r, angles[s])) for s, *_ in meta for r in range(repeats)]
        reps: dict = {s: [] for s, *_ in meta}
        for s, f in rep_f:
            reps[s].append(f.result())
        bounds = {s: f.result() for s, f in bound_f.items()}
    wall = time.perf_counter() - t_start

    results, tables = {}, []
    for stem, label, _ in meta:
        rows = [r for rep in reps[stem] for r in rep["rows"]]
        times = {p.name: [t for rep in reps[stem] for t in rep["times_s"][p.name]] for p in PEERS}
        crb = bounds[stem]["crb_rms_deg"]
        summary = summarise(rows, times, crb)
        n_images = 2 * repeats * len(angles[stem])
        results[stem] = {"label": label, "crb_rms_deg": crb, "crb_by_angle_deg": bounds[stem]["bounds_deg"],
                         "angles_deg": angles[stem], "repeats": repeats, "n_images": n_images,
                         "methods": summary, "measurements": _columns(rows)}
        table = scene_table(label, summary, crb, n_images)
        tables.append(table)
        print("\n" + table, flush=True)

    checks = check_targets(results, meta)
    print("\nTargets (issues 2 and 8):")
    for c in checks:
        print(f"  [{'met' if c['met'] else 'MISSED'}] {c['target']}: {c['detail']}")
    load_end = [round(x, 2) for x in os.getloadavg()]
    print(f"\nwall time {wall:.0f} s on {args.jobs} worker(s); load average at the end {load_end}")

    if write:
        payload = {
            "benchmark": "peers",
            "command": "python benchmarks/bench_peers.py " + " ".join(argv if argv is not None else sys.argv[1:]),
            "machine": info,
            "load_average_end": load_end,
            "wall_time_s": wall,
            "jobs": args.jobs,
            "repeats": repeats,
            "wrong_pair_threshold_px": WRONG_PX,
            "base_seed": BASE_SEED,
            "methods": {p.name: p.label for p in PEERS},
            "targets": checks,
            "scenes": results,
        }
        RESULTS.mkdir(parents=True, exist_ok=True)
        write_result(RESULTS / "peers.json", payload)
        m = info
        header = [
            "### Benchmark: vision-torsion against the methods a user would pick instead",
            "",
            f"Run {m['date']} on {m['cpu_model']} ({m['cores']} cores, load average "
            f"{m['load_average_1_5_15min'][0] if m['load_average_1_5_15min'] else '?'} at the start), "
            f"Python {m['python']}, NumPy {m['numpy']}, OpenCV {m['opencv']}, scikit-image "
            f"{m['scikit_image']}; `python benchmarks/bench_peers.py` "
            f"({repeats} repeat(s) × sweep angles, each angle with its own 0° reference image, {args.jobs} workers, "
            f"{wall:.0f} s wall).",
            "",
            "Errors are angle errors against the scene's reference image at 0°, so they include both "
            "images' errors, as does the Cramér–Rao bound (CRB). RMS, max and bias exclude failed and "
            "wrong-pair angles, which are counted separately. ms/img: median CPU and wall time per image, "
            "decoding excluded, one thread per worker process, two workers sharing the machine.",
            "",
        ]
        methods = [
            "Methods (all get the same prior knowledge: dark markers, radius 10 px to a fifth of the "
            "shorter image side; every peer picks the two largest round objects itself, none is told "
            "where the true markers are; details in `benchmarks/peers.py`):",
            "",
        ] + [f"- {p.label}: {PEER_NOTES[p.name]}" for p in PEERS] + [""]
        targets = ["", "Targets (issues 2 and 8):", ""] + [
            f"- [{'x' if c['met'] else ' '}] {c['target']}: {c['detail']}" for c in checks]
        text = "\n".join(header + methods) + "\n" + "\n\n".join(tables) + "\n" + "\n".join(targets) + "\n"
        write_result(RESULTS / "peers.md", text)
        print(f"wrote {RESULTS / 'peers.json'} and {RESULTS / 'peers.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
