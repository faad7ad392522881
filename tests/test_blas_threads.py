"""A command's own process runs numpy's BLAS with one thread unless the user set a
count: OpenBLAS's idle threads would otherwise spin on the other core while the
command imports and starts (``benchmarks/bench_commands.py``)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from vision_torsion.cli import BLAS_THREAD_VARIABLES

ROOT = Path(__file__).resolve().parents[1]

# a command that imports numpy and fails at once (no such image), then what BLAS runs with
SCRIPT = """
import os, sys
from threadpoolctl import threadpool_info
from vision_torsion.cli import main
sys.argv = ["vision-torsion", "measure", "no-such-folder", "--reference", "no-such-image.png"]
status = main()
threads = [i["num_threads"] for i in threadpool_info() if i["internal_api"] == "openblas"]
print(status, os.environ.get("OPENBLAS_NUM_THREADS"), threads[0] if threads else None)
"""


def _run(tmp_path, **variables) -> list[str]:
    env = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES}
    env.update(PYTHONPATH=str(ROOT), PYTHONWARNINGS="error", **variables)
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=120)
    return done.stdout.split()


def test_a_command_runs_blas_with_one_thread(tmp_path):
    status, variable, threads = _run(tmp_path)
    assert status == "2" and variable == "1"
    if threads == "None":
        pytest.skip("numpy here does not use OpenBLAS")
    assert threads == "1"


def test_a_thread_count_the_user_set_is_kept(tmp_path):
    status, variable, threads = _run(tmp_path, OMP_NUM_THREADS="2")
    assert status == "2" and variable == "None"
    if threads == "None":
        pytest.skip("numpy here does not use OpenBLAS")
    assert threads == "2"
