"""Large real-camera images: a 20-MP JPEG session, grey and colour (issue 31, item 3).

Run (renders 38 images per session at run time, then times whole commands; about
5-10 minutes on 2 cores)::

    python benchmarks/bench_jpeg20.py
    python benchmarks/bench_jpeg20.py --repeats 3 --workdir /tmp/jpeg20

Two sessions are rendered into a temporary folder (never committed): the
``paper_session`` protocol at one orientation seen by a 20-MP camera (5472 x 3648
px, markers of 130 px radius 1100 px apart, blur sigma 2.5 px, read noise 3 DN,
JPEG quality 90), once as grey JPEGs and once as colour JPEGs (the same rendered
grey levels through three channel gains, each channel with its own sensor noise of
2 DN, encoded 4:2:0 by OpenCV at quality 90).

For each session it times, each as a separate command in a fresh process (wall time
and CPU time, user + system, as a shell sees them), alternately ``--repeats`` times:

- **floor**: a plain 1/8-scale decode of every file (libjpeg-turbo's DCT scaling,
  ``simplejpeg`` in two threads): entropy decoding of the whole file and nothing else
  of note, the least any reader of these files can do;
- **full decode**: a plain full-resolution decode of every file (``cv2.imread`` in two
  threads);
- **process**: ``vision-torsion process SESSION -o OUT --jobs 2`` with an empty output
  folder (no cache), the whole command.

It prints the ratios process / floor and full decode / floor, and per image, on one
core in this process (CPU time, best of three): the 1/8 decode, a half-scale decode
to grey (libjpeg-turbo's 4/8 DCT scaling), a full decode to grey by ``simplejpeg``
(what ``process`` does), the DCT coefficients read by ``jpeglib`` (``read_dct(path).Y``,
when jpeglib is installed: the way to the coefficients a "1/8 from the DC terms, inverse
DCT only around the markers" reader would take), a full OpenCV decode, and the least a
"1/8 look, then full resolution only around the markers" reader would pay: the
1/8 decode plus the entropy decoding of the file down to the lowest marker's last
row (libjpeg cannot skip entropy-coded data without restart markers, so a cropped
decode pays for every row above the crop; measured as a 1/8 decode of the file cut
after that row's MCU row). ``process`` measures at full resolution, so its angles
are the full-resolution measurement (difference 0 sigma by construction); the table
gives its angle noise against the rendering's truth as a check that the session
measures. Every angle shares the reference image's error, one draw, which moves
that figure by itself (a reference 1.2 sigma off makes it ~1.12 with honest
sigmas), so the table also gives each image's own orientation error (the
marker-to-marker direction against the rendered one) over its sigma, RMS over the
images (``measure_pair`` on each file, as ``process`` measures it).

Results are printed as tables and written to ``benchmarks/results/jpeg20.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))
from common import compile_package  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results" / "jpeg20.json"
#: this tree's code, whatever an installed command would run
CLI = [sys.executable, "-m", "vision_torsion"]
_ENV = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}

WIDTH, HEIGHT, RADIUS_PX = 5472, 3648, 130.0
SCENE = f"""
[image]
width = {WIDTH}
height = {HEIGHT}
bit_depth = 8

[disk]
center_x = 2736.37
center_y = 1824.61
background_level = 200.0

[markers]
polarity = "dark"
level = 40.0
radius_px = {RADIUS_PX}
distance_px = 1100.0
positions_deg = [10.0, 190.0]

[optics]
blur_sigma_px = 2.5

[noise]
read_noise_dn = 3.0
jpeg_quality = 90

[session]
k_u_nm_per_rad = 4.4
k_l_nm_per_rad = 0.3
tau_c_nm = 0.15
max_torque_nm = 0.36
step_mass_kg = 0.04
arm_radius_m = 0.05
gravity_m_per_s2 = 9.81
mass_tolerance_kg = 0.0001
orientations_deg = [0.0]
cycles = 1
orientation_variation = 0.03
cycle_variation = 0.0
angle_sign = -1
"""
#: Channel gains (B, G, R as OpenCV orders them) and per-channel noise (DN) of the colour session.
GAINS, COLOUR_NOISE_DN = (0.78, 0.95, 1.0), 2.0

FLOOR = r"""
import sys
from concurrent.futures import ThreadPoolExecutor
import simplejpeg
files = open(sys.argv[1]).read().split("\n")
def eighth(f):
    raw = open(f, "rb").read()
    h, w = simplejpeg.decode_jpeg_header(raw)[:2]
    return simplejpeg.decode_jpeg(raw, colorspace="GRAY", min_height=h // 8, min_width=w // 8)
with ThreadPoolExecutor(2) as pool:
    n = sum(1 for img in pool.map(eighth, files) if img is not None)
assert n == len(files), n
"""
FULL = r"""
import sys
from concurrent.futures import ThreadPoolExecutor
import cv2
files = open(sys.argv[1]).read().split("\n")
with ThreadPoolExecutor(2) as pool:
    n = sum(1 for img in pool.map(lambda f: cv2.imread(f, cv2.IMREAD_UNCHANGED), files) if img is not None)
assert n == len(files), n
"""


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _timed(argv, ok=(0,)) -> tuple[float, float]:
    """(wall, CPU) seconds of a command in a fresh process, which must exit with a
    status in `ok`."""
    cpu, t = _children_cpu(), time.perf_counter()
    done = subprocess.run(argv, stdout=subprocess.DEVNULL, env=_ENV)
    if done.returncode not in ok:
        raise SystemExit(f"{' '.join(argv)}: exit status {done.returncode}")
    return time.perf_counter() - t, _children_cpu() - cpu


def render_sessions(work: Path) -> dict[str, Path]:
    """The grey and the colour session (rendered once into `work`)."""
    import cv2
    import numpy as np

    from vision_torsion.synthetic.session import load_session_scene, write_session_folder

    grey, colour = work / "grey", work / "colour"
    if not (grey / "truth.csv").is_file():
        scene_file = work / "scene20.toml"
        scene_file.write_text(SCENE)
        scene, spec = load_session_scene(scene_file)
        print(f"rendering the 20-MP grey session into {grey} ...", flush=True)
        write_session_folder(scene, spec, grey, seed=0, overwrite=True)
    if not (colour / "truth.csv").is_file():
        print(f"encoding the colour session into {colour} ...", flush=True)
        shutil.rmtree(colour, ignore_errors=True)
        shutil.copytree(grey, colour, ignore=shutil.ignore_patterns("*.jpg"))
        rng = np.random.default_rng(31)
        for src in sorted(grey.rglob("*.jpg")):
            level = cv2.imread(str(src), cv2.IMREAD_UNCHANGED).astype(np.float32)
            bgr = np.stack([g * level for g in GAINS], axis=-1)
            bgr += rng.normal(0.0, COLOUR_NOISE_DN, bgr.shape).astype(np.float32)
            out = colour / src.relative_to(grey)
            out.parent.mkdir(parents=True, exist_ok=True)
            ok = cv2.imwrite(str(out), np.clip(np.rint(bgr), 0, 255).astype(np.uint8),
                             [cv2.IMWRITE_JPEG_QUALITY, 90])
            assert ok, out
        # truth.csv last: a session interrupted while encoding is encoded again
        shutil.copy2(grey / "truth.csv", colour / "truth.csv")
    return {"grey": grey, "colour": colour}


def _cut_after_row(raw: bytes, row: int, height: int) -> bytes | None:
    """`raw` cut after the entropy-coded data of the MCU rows down to `row` (px), with an
    end-of-image marker: about what a decoder must read to reach that row (the bytes
    are taken as spread evenly over the MCU rows, as they are in a scene of uniform
    noise). None when the file has no start-of-scan marker."""
    start = raw.find(b"\xff\xda")
    if start < 0:
        return None
    scan_start = start + 2 + int.from_bytes(raw[start + 2:start + 4], "big")
    scan_end = raw.rfind(b"\xff\xd9")
    frac = min(1.0, (row + 16) / height)  # to the end of the MCU row holding `row` (8 px grey, 16 for 4:2:0)
    cut = scan_start + int((scan_end - scan_start) * frac)
    return raw[:cut] + b"\xff\xd9"


def per_image(session: Path) -> dict:
    """CPU ms per image on one core, best of three passes over the session's files."""
    import cv2
    import numpy as np
    import pandas as pd
    import simplejpeg

    cv2.setNumThreads(1)
    truth = pd.read_csv(session / "truth.csv")
    raws = [(session / name).read_bytes() for name in truth["image"]]
    # the lowest marker's last row in each image (the rendered centres, plus the radius)
    bottoms = (truth[["marker1_y_px", "marker2_y_px"]].max(axis=1) + RADIUS_PX).tolist()

    def best(fn) -> float:
        times = []
        for _ in range(3):
            c = time.process_time()
            for raw in raws:
                fn(raw)
            times.append(time.process_time() - c)
        return 1e3 * min(times) / len(raws)

    def eighth(raw, strict=True):
        return simplejpeg.decode_jpeg(raw, colorspace="GRAY", min_height=HEIGHT // 8, min_width=WIDTH // 8,
                                      strict=strict)

    cuts = [_cut_after_row(raw, int(bottom), HEIGHT) for raw, bottom in zip(raws, bottoms)]
    cut_ms = best_cut = None
    if all(c is not None for c in cuts):
        times = []
        for _ in range(3):
            c = time.process_time()
            for cut in cuts:
                eighth(cut, strict=False)  # the missing rows are filled in, not decoded
            times.append(time.process_time() - c)
        cut_ms = 1e3 * min(times) / len(cuts)
    floor_ms = best(eighth)
    try:
        import jpeglib
    except ImportError:
        coefficients_ms = None
    else:
        paths = [str(session / name) for name in truth["image"]]
        times = []
        for _ in range(3):
            c = time.process_time()
            for path in paths:
                jpeglib.read_dct(path).Y  # noqa: B018 - the luma coefficients are read on first use
            times.append(time.process_time() - c)
        coefficients_ms = 1e3 * min(times) / len(paths)
    if cut_ms is not None:
        best_cut = floor_ms + cut_ms
    return {
        "eighth_ms": floor_ms,
        "half_grey_simplejpeg_ms": best(lambda raw: simplejpeg.decode_jpeg(
            raw, colorspace="GRAY", min_height=HEIGHT // 2, min_width=WIDTH // 2)),
        "full_grey_simplejpeg_ms": best(lambda raw: simplejpeg.decode_jpeg(raw, colorspace="GRAY")),
        "jpeglib_read_dct_ms": coefficients_ms,
        "full_opencv_ms": best(lambda raw: cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_UNCHANGED)),
        "entropy_to_marker_bottom_ms": cut_ms,
        "eighth_then_crop_lower_bound_ms": best_cut,
        "file_mb": float(np.mean([len(r) for r in raws]) / 1e6),
    }


def angle_check(session: Path, measurements: Path) -> dict:
    """process's angles against the rendering's truth: RMS error over the reported std."""
    import numpy as np
    import pandas as pd

    m = pd.read_csv(measurements)
    t = pd.read_csv(session / "truth.csv")
    both = m.merge(t[["image", "true_angle_deg"]].rename(columns={"true_angle_deg": "truth_deg"}), on="image")
    ok = both[both["status"] == "ok"]
    err = ok["angle_deg"] - ok["truth_deg"]
    std = ok["angle_std_deg"]
    return {"n_ok": int(len(ok)), "n_rows": int(len(m)), "rms_error_deg": float(np.sqrt(np.mean(err**2))),
            "median_std_deg": float(np.median(std)),
            "rms_error_over_std": float(np.sqrt(np.mean((err[std > 0] / std[std > 0]) ** 2)))}


def orientation_check(session: Path) -> dict:
    """Each image's own orientation error over its sigma: the direction of the
    marker-to-marker vector measured by ``measure_pair`` against the rendered one
    (no reference image, so no error shared between images), RMS over the images."""
    import math

    import pandas as pd

    from vision_torsion.images import load_image
    from vision_torsion.pair import measure_pair

    z = []
    for _, row in pd.read_csv(session / "truth.csv").iterrows():
        a, b = measure_pair(load_image(session / row["image"], keep_integers=True)).markers
        t1, t2 = (row.marker1_x_px, row.marker1_y_px), (row.marker2_x_px, row.marker2_y_px)
        if math.dist((a.x_px, a.y_px), t1) > math.dist((a.x_px, a.y_px), t2):
            t1, t2 = t2, t1
        vx, vy = b.x_px - a.x_px, b.y_px - a.y_px
        length = math.hypot(vx, vy)
        nx, ny = -vy / length, vx / length  # across the vector: what moves its direction
        var = sum(nx * nx * m.x_std_px**2 + ny * ny * m.y_std_px**2 + 2 * nx * ny * m.xy_cov_px2
                  for m in (a, b)) / length**2
        err = math.atan2(vy, vx) - math.atan2(t2[1] - t1[1], t2[0] - t1[0])
        z.append(((err + math.pi) % (2 * math.pi) - math.pi) / math.sqrt(var))
    return {"n_images": len(z), "rms_error_over_std": math.sqrt(sum(v * v for v in z) / len(z))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="alternating floor/full/process rounds")
    parser.add_argument("--workdir", type=Path, help="where to render the sessions (default: a temporary folder)")
    args = parser.parse_args()
    work = Path(args.workdir or tempfile.mkdtemp(prefix="vt-bench-jpeg20-"))
    work.mkdir(parents=True, exist_ok=True)
    sessions = render_sessions(work)
    compile_package()
    result = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
              "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                          "platform": platform.platform()},
              "image_px": [WIDTH, HEIGHT], "sessions": {}}
    for name, session in sessions.items():
        files = sorted(str(p) for p in session.rglob("*.jpg"))
        listing = work / f"{name}-files.txt"
        listing.write_text("\n".join(files))
        rounds = []
        for i in range(args.repeats):
            out = work / f"out-{name}-{i}"
            shutil.rmtree(out, ignore_errors=True)
            load = os.getloadavg()[0]
            floor = _timed([sys.executable, "-c", FLOOR, str(listing)])
            full = _timed([sys.executable, "-c", FULL, str(listing)])
            # exit status 1 when a row is suspect or failed: the table is written all the same
            proc = _timed(CLI + ["process", str(session), "-o", str(out), "--jobs", "2", "-q"], ok=(0, 1))
            rounds.append({"load_before": load, "floor_s": floor[0], "floor_cpu_s": floor[1],
                           "full_s": full[0], "full_cpu_s": full[1],
                           "process_s": proc[0], "process_cpu_s": proc[1],
                           "ratio": proc[0] / floor[0], "cpu_ratio": proc[1] / floor[1],
                           "full_ratio": full[0] / floor[0], "full_cpu_ratio": full[1] / floor[1]})
        entry = {"n_images": len(files), "rounds": rounds,
                 "ratio_median": statistics.median(r["ratio"] for r in rounds),
                 "cpu_ratio_median": statistics.median(r["cpu_ratio"] for r in rounds),
                 "full_cpu_ratio_median": statistics.median(r["full_cpu_ratio"] for r in rounds),
                 "per_image": per_image(session),
                 "angles": angle_check(session, work / f"out-{name}-0" / "measurements.csv"),
                 "orientations": orientation_check(session)}
        result["sessions"][name] = entry
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=2) + "\n")
    print(f"\n{WIDTH}x{HEIGHT} px JPEG sessions, whole commands, 2 threads/jobs, no cache\n")
    print("| session | round | load | floor: 1/8 decode, wall (CPU) | full OpenCV decode, wall (CPU) | "
          "`process -j 2`, wall (CPU) | process / floor, wall (CPU) |")
    print("|---|---|---|---|---|---|---|")
    for name, entry in result["sessions"].items():
        for i, r in enumerate(entry["rounds"], 1):
            print(f"| {name} ({entry['n_images']} images) | {i} | {r['load_before']:.1f} | {r['floor_s']:.2f} s "
                  f"({r['floor_cpu_s']:.2f} s) | {r['full_s']:.2f} s ({r['full_cpu_s']:.2f} s) | "
                  f"{r['process_s']:.2f} s ({r['process_cpu_s']:.2f} s) | {r['ratio']:.2f} ({r['cpu_ratio']:.2f}) |")
    print("\nper image, one core, CPU (best of three passes)\n")
    print("| session | MB | 1/8 decode (floor) | 1/2 grey, simplejpeg | full grey, simplejpeg | DCT coefficients, "
          "jpeglib | full OpenCV | entropy down to the lowest marker | 1/8 look + crop, least | "
          "process angle RMS error / std | each image's orientation, RMS error / std |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, entry in result["sessions"].items():
        p, a = entry["per_image"], entry["angles"]
        crop = (f"{p['entropy_to_marker_bottom_ms']:.1f} ms | {p['eighth_then_crop_lower_bound_ms']:.1f} ms "
                f"({p['eighth_then_crop_lower_bound_ms'] / p['eighth_ms']:.2f}x)"
                if p["entropy_to_marker_bottom_ms"] is not None else "- | -")
        coefficients = ("-" if p["jpeglib_read_dct_ms"] is None else
                        f"{p['jpeglib_read_dct_ms']:.1f} ms ({p['jpeglib_read_dct_ms'] / p['eighth_ms']:.2f}x)")
        print(f"| {name} | {p['file_mb']:.2f} | {p['eighth_ms']:.1f} ms | {p['half_grey_simplejpeg_ms']:.1f} ms "
              f"({p['half_grey_simplejpeg_ms'] / p['eighth_ms']:.2f}x) | {p['full_grey_simplejpeg_ms']:.1f} ms "
              f"({p['full_grey_simplejpeg_ms'] / p['eighth_ms']:.2f}x) | {coefficients} | {p['full_opencv_ms']:.1f} ms "
              f"({p['full_opencv_ms'] / p['eighth_ms']:.2f}x) | {crop} | {a['rms_error_over_std']:.2f} "
              f"({a['n_ok']}/{a['n_rows']} ok) | {entry['orientations']['rms_error_over_std']:.2f} |")
    for name, entry in result["sessions"].items():
        print(f"{name}: process / floor median {entry['ratio_median']:.2f} wall, {entry['cpu_ratio_median']:.2f} "
              f"CPU (issue 31 asks <= 1.15); full decode / floor {entry['full_cpu_ratio_median']:.2f} CPU")
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
