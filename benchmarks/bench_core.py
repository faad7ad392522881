"""Measurement core and renderer benchmark (issues 2 and 3).

    python benchmarks/bench_core.py [--repeats N]   # default 20 repeats, about a minute

On the standard scene (synthetic/standard.toml: 1400x1000 px, 8 bit, dark markers
of radius 35 px 600 px apart, contrast 160 DN, blur 1 px, read noise 2 DN) it
renders, for each repeat, the scene's sweep (-70° to +70°), every angle with its own
reference image at 0° and fresh noise (so the errors are independent), measures
every angle with the default pipeline and prints:

- RMS, largest and mean angle error (deg) against the true rotation, and the RMS
  divided by the Cramér-Rao bound of the scene;
- honesty: mean reported angle_std_deg divided by the empirical RMS;
- processing CPU time per image on one core, excluding decoding (ms; 20 images,
  best of 3 runs each, timed apart from rendering);
- render time of one 1400x1000 image (ms);
- on the distractor scene: right pair / clear error / wrong pair over the sweep.

Results also go to benchmarks/results/core.json.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from common import one_core, write_result  # noqa: E402

from vision_torsion.angle import pair_angle  # noqa: E402
from vision_torsion.errors import MarkerError  # noqa: E402
from vision_torsion.images import as_grey_array  # noqa: E402
from vision_torsion.pair import measure_pair  # noqa: E402
from vision_torsion.synthetic import load_scene, render  # noqa: E402
from vision_torsion.synthetic.bounds import angle_bound_deg  # noqa: E402


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def accuracy(scene, repeats: int):
    """Angles of the sweep, each against its own freshly rendered 0° reference (independent errors)."""
    angles = [a for a in scene.sweep.angles_deg if a != 0.0]
    errs, stds = [], []
    for rep in range(repeats):
        for i, a in enumerate(angles):
            # decoded images are float32 (load_image): convert before timing
            ref_img = as_grey_array(render(scene, 0.0, seed=10_000 + rep * 1000 + i).image)
            img = as_grey_array(render(scene, a, seed=rep * 1000 + i).image)
            res = pair_angle(measure_pair(ref_img), measure_pair(img))
            errs.append(res.angle_deg - a)
            stds.append(res.angle_std_deg)
    errs = np.asarray(errs)
    bound = float(np.mean([angle_bound_deg(scene, a) for a in (-70.0, 0.0, 70.0)]))
    rms = float(np.sqrt(np.mean(errs**2)))
    return {
        "n": int(errs.size),
        "rms_deg": rms,
        "max_abs_deg": float(np.abs(errs).max()),
        "mean_deg": float(errs.mean()),
        "crb_deg": bound,
        "rms_over_crb": rms / bound,
        "reported_std_over_rms": float(np.mean(stds)) / rms,
    }


def speed(scene, n: int = 20) -> dict:
    """CPU time of measure_pair + pair_angle per decoded (8-bit) image, best of 3
    each, on one thread (as a session worker runs).

    Timed apart from rendering, which would otherwise evict the caches between
    renders and inflate the figure.
    """
    one_core()
    imgs = [as_grey_array(render(scene, a, seed=50_000 + i).image, keep_integers=True)
            for i, a in enumerate(np.linspace(-70, 70, n))]
    ref = measure_pair(as_grey_array(render(scene, 0.0, seed=49_999).image))
    best = []
    for img in imgs:
        ts = []
        for _ in range(3):
            t0 = time.process_time()
            pair_angle(ref, measure_pair(img))
            ts.append(time.process_time() - t0)
        best.append(min(ts))
    return {"cpu_ms_per_image_median": 1e3 * float(np.median(best)), "cpu_ms_per_image_max": 1e3 * float(np.max(best))}


def render_time(scene, n: int = 10) -> float:
    ts = []
    for i in range(n):
        t0 = time.perf_counter()
        render(scene, 10.0 + i, seed=i)
        ts.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(ts))


def distractors(scene):
    right = error = wrong = 0
    for i, a in enumerate(np.arange(-70.0, 70.1, 5.0)):
        r = render(scene, a, seed=500 + i)
        try:
            pair = measure_pair(r.image)
        except MarkerError:
            error += 1
            continue
        found = np.array([[m.x_px, m.y_px] for m in pair.markers])
        ok = all(np.hypot(*(found - c).T).min() < 0.5 for c in r.centres)
        right += ok
        wrong += not ok
    return {"right_pair": right, "clear_error": error, "wrong_pair": wrong}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=20, help="repeats of the sweep (default 20: 400 angles)")
    args = ap.parse_args(argv)
    cv2.setNumThreads(1)  # one core
    std = load_scene(ROOT / "vision_torsion" / "synthetic" / "scenes" / "standard.toml")
    acc = accuracy(std, args.repeats)
    spd = speed(std)  # after the accuracy run: the first few hundred calls of a fresh process run slower
    rt = render_time(std)
    dis = distractors(load_scene(ROOT / "vision_torsion" / "synthetic" / "scenes" / "distractors.toml"))
    rows = [
        ("angles measured", f"{acc['n']}", ""),
        ("RMS angle error", f"{acc['rms_deg']:.5f}°", "≤ 0.0007°"),
        ("largest abs error", f"{acc['max_abs_deg']:.5f}°", ""),
        ("mean error (bias)", f"{acc['mean_deg']:+.5f}°", ""),
        ("Cramér-Rao bound", f"{acc['crb_deg']:.5f}°", ""),
        ("RMS / bound", f"{acc['rms_over_crb']:.2f}", "≤ 1.5"),
        ("reported std / RMS", f"{acc['reported_std_over_rms']:.2f}", "0.7 – 1.3"),
        (
            "processing, CPU ms/image (1 core, no decode)",
            f"{spd['cpu_ms_per_image_median']:.1f} (slowest {spd['cpu_ms_per_image_max']:.1f})",
            "≤ 10",
        ),
        ("render, ms/image 1400x1000", f"{rt:.0f}", "< 300"),
        (
            "distractors: right / error / wrong pair",
            f"{dis['right_pair']} / {dis['clear_error']} / {dis['wrong_pair']}",
            "wrong = 0",
        ),
    ]
    w = max(len(r[0]) for r in rows)
    print(
        f"\nMeasurement core, standard scene ({datetime.now(timezone.utc):%Y-%m-%d}, {_cpu()}, "
        f"load {os.getloadavg()[0]:.2f})\n"
    )
    print(f"| {'quantity'.ljust(w)} | value | target |")
    print(f"|{'-' * (w + 2)}|-------|--------|")
    for name, value, target in rows:
        print(f"| {name.ljust(w)} | {value} | {target} |")
    write_result(
        ROOT / "benchmarks" / "results" / "core.json",
        {
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "machine": {
                "cpu": _cpu(),
                "cores": os.cpu_count(),
                "python": platform.python_version(),
                "numpy": np.__version__,
                "opencv": cv2.__version__,
            },
            "standard": acc,
            "speed": spd,
            "render_ms": rt,
            "distractors": dis,
        },
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
