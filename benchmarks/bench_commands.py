"""What a user waits for: whole commands, start-up included (issue 16).

Run (one command; about 3-5 minutes on 2 cores)::

    python benchmarks/bench_commands.py
    python benchmarks/bench_commands.py --repeats 5

It times, each as a separate command in a fresh process (wall time, as a shell
would see it):

- ``vision-torsion --version`` and ``vision-torsion --help`` (best and median of
  10 runs; the issue asks for <= 0.3 s);
- ``vision-torsion process SESSION -o OUT --jobs 2`` of the demo session (the 444
  images of the ``paper_session`` scene, rendered once), with an empty output
  folder (no cache), against a plain two-thread decode of the same 444 files as a
  whole command (``python -c`` importing OpenCV and decoding every file with
  ``cv2.imread`` in two threads), the two run alternately ``--repeats`` times; the
  ratio ``process / decode`` per pair, and its median (the issue asks for <= 1.4);
- the same files decoded by the toolkit's own reader (``images.load_image``, two
  threads; it decodes OpenCV's PNGs with ISA-L, :mod:`vision_torsion.pngrows`), and
  ``process / own decode``: what measuring costs beyond reading the pixels;
- the same ``process`` again with its cache full (every result cached).

The machine's load average is recorded before each pair, and each command's CPU
time (user + system) beside its wall time: on a shared machine under load, the two
commands get a share of the cores rather than both, and the wall-time ratio tends
to the CPU-time ratio. Results are printed as a table and written to
``benchmarks/results/commands.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import compile_package  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results" / "commands.json"
_SCRIPT = Path(sys.executable).parent / "vision-torsion"  # the installed command, as a user runs it
CLI = [str(_SCRIPT)] if _SCRIPT.exists() else [sys.executable, "-m", "vision_torsion"]

DECODE = r"""
import sys
from concurrent.futures import ThreadPoolExecutor
import cv2
files = open(sys.argv[1]).read().split("\n")
with ThreadPoolExecutor(2) as pool:
    n = sum(1 for img in pool.map(lambda f: cv2.imread(f, cv2.IMREAD_UNCHANGED), files) if img is not None)
assert n == len(files), n
"""

OWN_DECODE = r"""
import sys
from concurrent.futures import ThreadPoolExecutor
from vision_torsion.images import load_image
files = open(sys.argv[1]).read().split("\n")
with ThreadPoolExecutor(2) as pool:
    n = sum(1 for img in pool.map(lambda f: load_image(f, keep_integers=True), files))
assert n == len(files), n
"""

_CPU = {"last": 0.0}


def _children_cpu() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _adopt_orphans() -> None:
    """Make this process the reaper of its descendants whose parent exits (Linux):
    `process`'s worker processes are children of its fork server, which outlives
    the command by a moment and is nobody's child then, so their CPU time would
    otherwise count nowhere."""
    import ctypes

    try:
        ctypes.CDLL(None, use_errno=True).prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER
    except (OSError, AttributeError):
        pass


def _reap_orphans() -> None:
    """Wait for every descendant adopted by :func:`_adopt_orphans` (its CPU time
    then counts as this process's children's)."""
    while True:
        try:
            os.waitpid(-1, 0)
        except ChildProcessError:
            return


def _wall(argv, **kw) -> float:
    """Wall time of the command; its CPU time (user + system, its descendants'
    included) is left in ``_CPU["last"]``."""
    cpu = _children_cpu()
    t = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, **kw)
    wall = time.perf_counter() - t
    _reap_orphans()
    _CPU["last"] = _children_cpu() - cpu
    return wall


def _load() -> float:
    return os.getloadavg()[0]


def startup(n: int = 10) -> dict:
    out = {}
    for name, args in (("--version", ["--version"]), ("--help", ["--help"])):
        times = [_wall(CLI + args) for _ in range(n)]
        out[name] = {"best_s": min(times), "median_s": statistics.median(times)}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="alternating process/decode pairs")
    parser.add_argument("--workdir", type=Path, help="where to render the session (default: a temporary folder)")
    args = parser.parse_args()
    _adopt_orphans()
    work = Path(args.workdir or tempfile.mkdtemp(prefix="vt-bench-commands-"))
    session = work / "session"
    if not (session / "truth.csv").is_file():
        print(f"rendering the demo session into {session} ...", flush=True)
        subprocess.run(CLI + ["synth", "session", str(session), "--scene", "paper_session", "--force", "-q"],
                       check=True)
    import pandas as pd

    images = [str(session / name) for name in pd.read_csv(session / "manifest.csv")["image"]]
    listing = work / "files.txt"
    listing.write_text("\n".join(images))

    # bytecode as an installed package has it (pip compiles it at install; an editable
    # install writes it at the first import, unless PYTHONDONTWRITEBYTECODE is set, as
    # on some CI machines): the decode command's OpenCV and numpy have theirs
    compile_package()
    starts = startup()
    pairs = []
    for i in range(args.repeats):
        load = _load()
        out = work / f"out{i}"
        shutil.rmtree(out, ignore_errors=True)
        t_decode = _wall([sys.executable, "-c", DECODE, str(listing)])
        cpu_decode = _CPU["last"]
        t_own = _wall([sys.executable, "-c", OWN_DECODE, str(listing)])
        cpu_own = _CPU["last"]
        t_process = _wall(CLI + ["process", str(session), "-o", str(out), "--jobs", "2", "-q"])
        cpu_process = _CPU["last"]
        t_cached = _wall(CLI + ["process", str(session), "-o", str(out), "--jobs", "2", "-q"])
        pairs.append({"load_before": load, "decode_s": t_decode, "process_s": t_process,
                      "process_cached_s": t_cached, "ratio": t_process / t_decode,
                      "decode_cpu_s": cpu_decode, "process_cpu_s": cpu_process,
                      "own_decode_s": t_own, "own_decode_cpu_s": cpu_own, "ratio_own": t_process / t_own})
    ratios = [p["ratio"] for p in pairs]
    cpu_ratios = [p["process_cpu_s"] / p["decode_cpu_s"] for p in pairs]
    result = {
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                    "platform": platform.platform()},
        "n_images": len(images),
        "startup": starts,
        "pairs": pairs,
        "ratio_median": statistics.median(ratios),
        "ratio_best": min(ratios),
        "cpu_ratio_median": statistics.median(cpu_ratios),
        "ratio_own_median": statistics.median(p["ratio_own"] for p in pairs),
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(result, indent=2) + "\n")
    print("\n| command | time |\n|---|---|")
    for name, t in starts.items():
        print(f"| `vision-torsion {name}` | best {t['best_s']:.3f} s, median {t['median_s']:.3f} s |")
    print(f"\n{len(images)} images, --jobs 2, no cache; load average before each pair\n")
    print("| pair | load | plain 2-thread decode, OpenCV (CPU) | process (CPU) | ratio | own decode (CPU) | "
          "process / own decode | process, all cached |")
    print("|---|---|---|---|---|---|---|---|")
    for i, p in enumerate(pairs, 1):
        print(f"| {i} | {p['load_before']:.2f} | {p['decode_s']:.2f} s ({p['decode_cpu_s']:.1f} s) | "
              f"{p['process_s']:.2f} s ({p['process_cpu_s']:.1f} s) | {p['ratio']:.2f} | "
              f"{p['own_decode_s']:.2f} s ({p['own_decode_cpu_s']:.1f} s) | {p['ratio_own']:.2f} | "
              f"{p['process_cached_s']:.2f} s |")
    print(f"\nratio median {result['ratio_median']:.2f}, best {result['ratio_best']:.2f} "
          f"(issue 16 asks <= 1.4); CPU-time ratio median {result['cpu_ratio_median']:.2f}; "
          f"process / own decode median {result['ratio_own_median']:.2f}; wrote {RESULTS}")


if __name__ == "__main__":
    main()
