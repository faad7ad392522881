"""Session throughput: is ``process`` bound by reading the images, and is it resumable?

Run (one command; about 3-4 minutes on 2 cores for the default 1000 images)::

    python benchmarks/bench_session_throughput.py            # N = 1000
    python benchmarks/bench_session_throughput.py --n 100    # quick

It renders an N-image session (1400x1000 8-bit PNGs of the default synthetic scene:
two dark markers, 2 DN read noise, every image a distinct noise realisation, so no
two files are identical and the content-hash cache cannot share results), then
measures, each ``process`` run in a fresh child process with an empty cache:

- decode-only time: reading and decoding every file (``cv2.imdecode``), one core;
- ``process`` wall time with 1 job (measured in the calling process), 2 jobs
  forced into threads (two threads read and decode, the calling thread measures:
  the path of fewer than ``PROCESS_MIN_IMAGES`` images to measure) and 2 jobs in 2
  worker processes (the default on two cores for this many images), each run
  between two decode-only runs with as many processes (this VM's
  speed drifts by tens of percent over minutes, and its two vCPUs do not give two
  processes twice the speed of one), and the ratios ``process / (decode with as
  many processes)`` and ``process / (1-core decode / jobs)`` (issue 4 asks for
  <= 1.3);
- peak resident memory of the main process (and of the largest worker process),
  at N and at N/4 (streaming means it should not grow with N);
- kill-and-resume: a run SIGKILLed (whole process group) after about a third of the
  images, then resumed; the resumed measurements.csv must equal an uninterrupted
  run's byte for byte, and the resumed run must measure only the images not cached.

Results are printed as a table and written to
``benchmarks/results/session_throughput.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from vision_torsion.session.cache import CACHE_DIRNAME

RESULTS = Path(__file__).resolve().parent / "results" / "session_throughput.json"
#: (name, jobs, mode) of the timed runs; the third is the default on two cores.
CONFIGS = (("1 job", 1, "default"), ("2 jobs, threads", 2, "threads"),
           ("2 jobs, processes", 2, "processes"))
ANGLE_GRID_DEG = 0.25  # ideal renders are shared between images on this grid


def _truth_angle(orientation: float, torque_nm: float, phase: str) -> float:
    """A plausible hysteretic response: ~25°/N·m, unloading lagging by 0.5°."""
    lag = 0.5 if phase.endswith("unloading") else 0.0
    return round((0.2 * orientation / 60.0 + 25.0 * torque_nm + lag) / ANGLE_GRID_DEG) \
        * ANGLE_GRID_DEG


def _render_group(args):
    """Render all images sharing one angle: one ideal render, per-image noise."""
    angle, items = args
    import cv2

    from vision_torsion.synthetic import Scene, render_ideal

    scene = Scene()
    ideal = render_ideal(scene, angle).astype(np.float32)
    sigma = scene.noise.read_noise_dn
    for path, seed in items:
        rng = np.random.default_rng(seed)
        noisy = ideal + sigma * rng.standard_normal(ideal.shape, dtype=np.float32)
        img = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
        ok, enc = cv2.imencode(".png", img)
        Path(path).write_bytes(enc.tobytes())
    return len(items)


def make_session(folder: Path, n: int, jobs: int) -> dict[str, float]:
    """Plan a 6-orientation session, keep its first `n` rows, render them."""
    from vision_torsion.session.manifest import REQUIRED_COLUMNS, manifest_text
    from vision_torsion.session.plan import plan_config, plan_session

    per_cycle = 6 * 4 * 18
    cycles = max(1, -(-n // per_cycle))
    plan = plan_session(plan_config(max_torque_nm=0.36, step_mass_kg=0.02, arm_radius_m=0.05, cycles=cycles,
                                    radius_range=(20, 60)), folder, overwrite=True)
    rows = plan.rows[:n]
    (folder / "manifest.csv").write_text(manifest_text(REQUIRED_COLUMNS, rows))
    groups: dict[float, list] = {}
    truth = {}
    for index, row in enumerate(rows):
        sign = {"pos": 1, "neg": -1, "ref": 0}[row["phase"][:3]]
        torque = sign * 2 * float(row["mass_kg"]) * 9.81 * 0.05
        angle = _truth_angle(float(row["orientation_deg"]), torque, row["phase"])
        groups.setdefault(angle, []).append((str(folder / row["image"]), index))
        truth[row["image"]] = angle
    with ProcessPoolExecutor(jobs) as pool:
        assert sum(pool.map(_render_group, groups.items())) == n
    return truth


def subset_session(source: Path, folder: Path, n: int) -> None:
    """A session of the first `n` rows of `source`, images hard-linked (no copies)."""
    lines = (source / "manifest.csv").read_text().splitlines()[: n + 1]
    (folder / "images").mkdir(parents=True, exist_ok=True)
    shutil.copy(source / "session.toml", folder / "session.toml")
    (folder / "manifest.csv").write_text("\n".join(lines) + "\n")
    for line in lines[1:]:
        image = line.split(",")[0]
        os.link(source / image, folder / image)


def _manifest_images(folder: Path) -> list[str]:
    return [str(folder / line.split(",")[0]) for line in
            (folder / "manifest.csv").read_text().splitlines()[1:]]


def _decode_files(paths: list[str]) -> int:
    """Read and decode each file (``cv2.imdecode``, as ``process`` does)."""
    import cv2

    cv2.setNumThreads(1)
    for path in paths:
        data = np.frombuffer(Path(path).read_bytes(), np.uint8)
        assert cv2.imdecode(data, cv2.IMREAD_UNCHANGED) is not None
    return len(paths)


def _ready(_):
    return None


def decode_only(folder: Path, jobs: int = 1) -> float:
    """Wall seconds to read and decode every image of the manifest with `jobs`
    processes (already started), each taking every jobs-th file."""
    images = _manifest_images(folder)
    if jobs == 1:
        start = time.perf_counter()
        _decode_files(images)
        return time.perf_counter() - start
    with ProcessPoolExecutor(jobs) as pool:
        list(pool.map(_ready, range(jobs)))
        start = time.perf_counter()
        assert sum(pool.map(_decode_files, [images[i::jobs] for i in range(jobs)])) == len(images)
        return time.perf_counter() - start


def child(session: str, out: str, jobs: int, mode: str) -> None:
    """Run process_session here and print wall time and counts as JSON; `mode`
    "processes" sends even 2 jobs to worker processes, "threads" keeps up to
    three in threads of this process, however many images."""
    import resource

    from vision_torsion.session import process as process_module
    from vision_torsion.session import process_session

    if mode == "processes":
        process_module.MAX_THREAD_JOBS = 0
    elif mode == "threads":
        process_module.PROCESS_MIN_IMAGES = sys.maxsize

    start = time.perf_counter()
    result = process_session(session, out_dir=out, jobs=jobs)
    wall = time.perf_counter() - start
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux
    print(json.dumps({"wall_s": wall, "n_ok": result.n_ok, "n_failed": result.n_failed,
                      "n_measured": result.n_measured, "n_cached": result.n_cached,
                      "main_peak_rss_mib": peak_mib}))


def _peak_rss_mib(session_id: int) -> dict[int, float]:
    """Peak resident memory (VmHWM) of every live process of a session (Linux /proc)."""
    peaks = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            if int(stat.rsplit(")", 1)[1].split()[3]) != session_id:
                continue
            for line in Path(f"/proc/{entry}/status").read_text().splitlines():
                if line.startswith("VmHWM:"):
                    peaks[int(entry)] = int(line.split()[1]) / 1024
        except (OSError, IndexError, ValueError):
            continue  # the process ended meanwhile
    return peaks


def _lines(cache: Path) -> int:
    """Lines in the cache logs so far (cheap: no parsing while the run is timed)."""
    total = 0
    for log in cache.glob("*.jsonl") if cache.is_dir() else ():
        try:
            total += log.read_bytes().count(b"\n")
        except OSError:
            continue  # merged away meanwhile
    return total


def run_child(session: Path, out: Path, jobs: int, *, mode: str = "default",
              kill_at: int | None = None) -> dict:
    """Run `process` in a child process group, sampling the peak memory of its
    workers (the main process reports its own); with `kill_at`, SIGKILL the whole
    group once that many results are cached.

    Sampling reads /proc every 0.5 s (the kill check every 0.05 s): scanning every
    process costs a few ms, which taken from the measured run every 0.1 s would
    slow it by a few percent. A worker's peak (VmHWM) holds for its whole life, so
    sparse samples still see it."""
    cmd = [sys.executable, __file__, "--child", str(session), str(out), str(jobs), mode]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, start_new_session=True)
    peaks: dict[int, float] = {}
    cache = out / CACHE_DIRNAME
    next_sample = time.monotonic()
    while proc.poll() is None:
        if kill_at is None and time.monotonic() >= next_sample:
            for pid, mib in _peak_rss_mib(proc.pid).items():
                peaks[pid] = max(mib, peaks.get(pid, 0.0))
            next_sample += 0.5
        if kill_at is not None and _lines(cache) >= kill_at:
            os.killpg(proc.pid, signal.SIGKILL)  # the main process and its workers
            proc.wait()
            return {"killed": True}
        time.sleep(0.05)
    stdout = proc.stdout.read()
    if proc.returncode != 0:
        raise RuntimeError(f"process run failed with status {proc.returncode}")
    others = [mib for pid, mib in peaks.items() if pid != proc.pid]
    return {**json.loads(stdout.strip().splitlines()[-1]),
            "worker_peak_rss_mib": max(others, default=float("nan"))}


def kill_and_resume(session: Path, out: Path, jobs: int, n: int) -> dict:
    """SIGKILL a run after ~n/3 cached results, then resume it."""
    killed = run_child(session, out, jobs, kill_at=n // 3).get("killed", False)
    killed_mid_run = killed and not (out / "measurements.csv").exists()
    from vision_torsion.session.cache import count_entries

    cached = count_entries(out / CACHE_DIRNAME)
    resumed = run_child(session, out, jobs)
    return {"killed_mid_run": killed_mid_run, "cached_at_kill": cached, "resumed": resumed}


def angle_errors(csv: Path, truth: dict[str, float]) -> float:
    import pandas as pd

    table = pd.read_csv(csv)
    worst = 0.0
    for _, group in table.groupby("orientation_deg"):
        ref = truth[group["image"].iloc[0]]
        err = group["angle_deg"] - np.array([truth[i] - ref for i in group["image"]])
        worst = max(worst, float(np.nanmax(np.abs(err))))
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=1000, help="images in the session")
    parser.add_argument("--workdir", type=Path, help="where to build the sessions "
                        "(default: a temporary folder, removed afterwards)")
    parser.add_argument("--child", nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child[0], args.child[1], int(args.child[2]), args.child[3])
        return
    n, quarter = args.n, max(1, args.n // 4)
    work = Path(args.workdir or tempfile.mkdtemp(prefix="bench_session_"))
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    from common import write_result

    from vision_torsion.session.process import code_fingerprint

    code_at_start = code_fingerprint()
    try:
        t0 = time.perf_counter()
        truth = make_session(work / "full", n, cores)
        subset_session(work / "full", work / "quarter", quarter)
        render_s = time.perf_counter() - t0
        print(f"rendered {n} images in {render_s:.0f} s", file=sys.stderr)
        decode_s = decode_only(work / "full")
        runs, decode_around = {}, {}
        for index, (name, jobs, mode) in enumerate(CONFIGS):
            # decoding with as many processes, just before and just after: this
            # machine's speed drifts by tens of percent over minutes, and two
            # processes on its two vCPUs do not run twice as fast as one
            before = decode_only(work / "full", jobs)
            runs[name] = run_child(work / "full", work / f"out_{index}", jobs, mode=mode)
            after = decode_only(work / "full", jobs)
            decode_around[name] = (before, after)
            print(f"process, {name}: {runs[name]['wall_s']:.1f} s (decoding with {jobs} "
                  f"process(es): {before:.1f} s before, {after:.1f} s after)", file=sys.stderr)
        small = run_child(work / "quarter", work / "out_quarter", 2)
        resume = kill_and_resume(work / "full", work / "out_killed", 2, n)
        reference = (work / "out_1" / "measurements.csv").read_bytes()
        identical = (work / "out_killed" / "measurements.csv").read_bytes() == reference
        only_rest = (resume["resumed"]["n_measured"] == n - resume["cached_at_kill"]
                     and resume["resumed"]["n_cached"] == resume["cached_at_kill"])
        same_files = all((work / f"out_{index}" / "measurements.csv").read_bytes() == reference
                         for index in range(len(CONFIGS)))
        worst = angle_errors(work / "out_1" / "measurements.csv", truth)
    finally:
        if args.workdir is None:
            shutil.rmtree(work, ignore_errors=True)

    rows = []
    for name, jobs, _ in CONFIGS:
        r = runs[name]
        parallel_decode_s = float(np.mean(decode_around[name]))
        rows.append({
            "run": name, "jobs": jobs, "process_s": r["wall_s"],
            "per_image_ms": 1000 * r["wall_s"] / n,
            "decode_same_processes_s": parallel_decode_s,
            "decode_same_processes_before_after_s": decode_around[name],
            "ratio_to_decode_same_processes": r["wall_s"] / parallel_decode_s,
            "ratio_to_decode_per_job": r["wall_s"] / (decode_s / jobs),
            "main_peak_rss_mib": r["main_peak_rss_mib"],
            "worker_peak_rss_mib": r["worker_peak_rss_mib"],
            "n_ok": r["n_ok"], "n_failed": r["n_failed"]})
    report = {
        "n_images": n, "image": "1400x1000 8-bit PNG, synthetic default scene",
        "cores": cores, "load_average_at_end": os.getloadavg(),
        "python": platform.python_version(), "render_s": render_s,
        "decode_only_s": decode_s, "decode_ms_per_image": 1000 * decode_s / n,
        "runs": rows,
        "quarter": {"n_images": quarter, **small},
        "kill_and_resume": {**resume, "identical_to_uninterrupted": identical,
                            "measured_only_the_rest": only_rest},
        "all_runs_give_the_same_file": same_files, "max_angle_error_deg": worst,
        "target_ratio": 1.3,
        "measuring_code_changed_during_run": code_fingerprint() != code_at_start,
    }
    write_result(RESULTS, report)  # NaN (no separate worker with --jobs 1) becomes null

    print(f"\nsession of {n} images (1400x1000 8-bit PNG), {cores} cores, "
          f"load average {os.getloadavg()[0]:.1f}")
    print(f"decode only, 1 core: {decode_s:.1f} s ({1000 * decode_s / n:.1f} ms/image)\n")
    print("| run | process (s) | decode, same processes (s) | process / that decode | "
          "process / (1-core decode / jobs) | main peak RSS (MiB) | worker peak RSS (MiB) "
          "| ok | failed |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        worker = "-" if np.isnan(r["worker_peak_rss_mib"]) else f"{r['worker_peak_rss_mib']:.0f}"
        print(f"| {r['run']} | {r['process_s']:.1f} | {r['decode_same_processes_s']:.1f} | "
              f"{r['ratio_to_decode_same_processes']:.2f} | "
              f"{r['ratio_to_decode_per_job']:.2f} | {r['main_peak_rss_mib']:.0f} | "
              f"{worker} | {r['n_ok']} | {r['n_failed']} |")
    print("(decode, same processes: reading and decoding every file with as many processes, "
          "mean of a run just before and one just after; the 1-core decode ran first; "
          "'-': no worker processes)")
    print(f"\nmemory vs size (2 jobs, threads; peak RSS of the process from itself): "
          f"{small['main_peak_rss_mib']:.0f} MiB at N/4 = {quarter}, "
          f"{rows[1]['main_peak_rss_mib']:.0f} MiB at N = {n}")
    print(f"kill and resume: killed with {resume['cached_at_kill']} of {n} cached; resumed "
          f"run measured {resume['resumed']['n_measured']}, took "
          f"{resume['resumed']['n_cached']} from the cache; measurements.csv identical to "
          f"the uninterrupted run: {identical}; measured only the rest: {only_rest}")
    print(f"every run gives the same file: {same_files}; largest angle error vs "
          f"the rendered truth: {worst:.4f}°")
    if report["measuring_code_changed_during_run"]:
        print("WARNING: the measuring code changed during the run; the runs are not "
              "comparable (the cache keys differ, equality checks may fail)")
    print(f"written {RESULTS}")


if __name__ == "__main__":
    main()
