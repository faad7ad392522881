"""How long a campaign of 1,000 reports takes to add and to report (issue 29).

Run (one command)::

    python benchmarks/bench_campaign.py                # 1000 reports, 3 repeats
    python benchmarks/bench_campaign.py --reports 200 --repeats 1

It writes ``--reports`` report folders of a synthetic campaign
(:func:`vision_torsion.synthetic.campaign.write_campaign_folders`: one analysed
session, each report its gear's identity and scattered figures; every tenth report a
life-test gear), untimed, then times two whole commands as a user runs them,
start-up included:

    vision-torsion campaign add DB REPORT_DIR...      (a new database each repeat)
    vision-torsion campaign report DB -o OUT          (against a catalogue file: K1 min, lost motion max)

and prints the median and best wall time with the CPU time beside it, and the load
average (on a shared machine wall time includes waiting for a core). Targets: add
<= 10 s, report <= 5 s for 1,000 reports. Results go to
``benchmarks/results/campaign.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import compile_package, git_commit  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results" / "campaign.json"
_SCRIPT = Path(sys.executable).parent / "vision-torsion"
CLI = [str(_SCRIPT)] if _SCRIPT.exists() else [sys.executable, "-m", "vision_torsion"]
TARGETS_S = {"add": 10.0, "report": 5.0}


def _timed(argv) -> tuple[float, float]:
    """(wall s, CPU s of the child) of one command, which must succeed."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run(argv, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(argv[:4])} ... failed ({proc.returncode}): {proc.stderr.strip()}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reports", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-write", action="store_true", help="do not write benchmarks/results/campaign.json")
    args = parser.parse_args(argv)
    from vision_torsion.synthetic.campaign import write_campaign_folders

    compile_package()
    runs = {"add": [], "report": []}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        folders = write_campaign_folders(tmp / "reports", n_reports=args.reports, seed=0, life_test_every=10)
        print(f"{len(folders)} report folders written in {time.perf_counter() - t0:.1f} s (untimed)")
        catalogue = tmp / "catalogue.toml"
        catalogue.write_text("[gear]\nname = 'CSF-14-100'\nt1_nm = 0.07\nt2_nm = 0.25\nrated_torque_nm = 6.0\n"
                             "[spec]\nk1_min_nm_per_rad = 0.28\nlost_motion_max_arcmin = 180\n", encoding="utf-8")
        for i in range(args.repeats):
            db = tmp / f"campaign_{i}.db"
            load = os.getloadavg()[0]
            runs["add"].append((*_timed([*CLI, "-q", "campaign", "add", str(db), *map(str, folders)]), load))
            load = os.getloadavg()[0]
            runs["report"].append((*_timed([*CLI, "-q", "campaign", "report", str(db), "-o", str(tmp / "out"),
                                            "--catalogue", str(catalogue)]), load))
    rows = []
    print(f"\n{args.reports} reports, {args.repeats} repeat(s), whole commands\n")
    print("| command | median wall (s) | best wall (s) | median CPU (s) | load (1 min) | target (s) | met |")
    print("|---|---|---|---|---|---|---|")
    for name, values in runs.items():
        walls = [w for w, _, _ in values]
        cpus = [c for _, c, _ in values]
        loads = [ld for _, _, ld in values]
        median = statistics.median(walls)
        target = TARGETS_S[name] * args.reports / 1000
        row = {"command": f"campaign {name}", "median_wall_s": median, "best_wall_s": min(walls),
               "median_cpu_s": statistics.median(cpus), "load": max(loads), "target_s": target,
               "met": median <= target}
        rows.append(row)
        print(f"| campaign {name} | {median:.2f} | {min(walls):.2f} | {row['median_cpu_s']:.2f} | "
              f"{row['load']:.1f} | {target:g} | {'yes' if row['met'] else 'NO'} |")
    if not args.no_write:
        RESULTS.parent.mkdir(exist_ok=True)
        RESULTS.write_text(json.dumps({"commit": git_commit(), "reports": args.reports, "repeats": args.repeats,
                                       "date": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "rows": rows}, indent=2)
                           + "\n", encoding="utf-8")
    return 0 if all(r["met"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
