"""process_session with the real measurement core on rendered sessions.

Uses ``vision_torsion.synthetic`` (exact edge coverage, seeded noise) so the angle
drawn in every image is known, and real worker processes.
"""

import os
import signal
import subprocess
import sys
import time

import pandas as pd
import pytest
from helpers import make_session

from vision_torsion.session import process as process_module
from vision_torsion.session import process_session
from vision_torsion.session.cache import CACHE_DIRNAME, count_entries
from vision_torsion.synthetic import Scene, render

# Small frames keep the tests fast; the rotation centre is off the pixel grid.
SCENE = Scene().replace(image={"width": 240, "height": 170},
                        disk={"center_x": 121.3, "center_y": 84.6},
                        markers={"radius_px": 14.0, "distance_px": 60.0})


def draw(angle, index):
    return render(SCENE, angle, seed=1000 + index).image


# The core reports about 0.004° (1σ) per angle on these frames (2 DN read noise);
# 0.04° is ten times that and still far below the 0.4° between neighbouring steps,
# so a row matched to the wrong image or the wrong reference cannot pass.
ANGLE_TOL_DEG = 0.04


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    folder = tmp_path_factory.mktemp("core") / "session"
    plan, truth = make_session(folder, draw=draw)
    return folder, plan, truth


def test_angles_match_the_rendered_truth_in_parallel(rendered, tmp_path, monkeypatch):
    folder, plan, truth = rendered
    result = process_session(folder, out_dir=tmp_path / "two", jobs=2)  # threads
    assert result.ok and result.n_measured == len(plan.rows)
    table = pd.read_csv(result.measurements_path)
    for _, group in table.groupby("orientation_deg"):
        ref = truth[group["image"].iloc[0]]
        errors = [a - (truth[i] - ref) for i, a in zip(group["image"], group["angle_deg"])]
        assert max(map(abs, errors)) < ANGLE_TOL_DEG
    assert (table["angle_std_deg"][1:] > 0).all()
    # one job, two reading threads or two worker processes: the same file, byte for byte
    single = process_session(folder, out_dir=tmp_path / "one", jobs=1)
    assert single.measurements_path.read_bytes() == result.measurements_path.read_bytes()
    monkeypatch.setattr(process_module, "MAX_THREAD_JOBS", 1)
    pooled = process_session(folder, out_dir=tmp_path / "pool", jobs=2)
    assert pooled.n_measured == len(plan.rows)
    assert pooled.measurements_path.read_bytes() == result.measurements_path.read_bytes()


_RUN = ("import sys; from vision_torsion.session import process_session; "
        "process_session(sys.argv[1], out_dir=sys.argv[2], jobs=int(sys.argv[3]))")


@pytest.mark.parametrize("jobs", [1, 2])  # measured alone; beside two reading threads
def test_killed_run_resumes_to_the_same_file(tmp_path, jobs):
    folder = tmp_path / "session"
    # ~100 images: two reading threads measure them in ~0.3 s, time enough to kill
    plan, _ = make_session(folder, orientations=(0, 60, 120), steps=8, draw=draw)
    n = len(plan.rows)
    reference = process_session(folder, out_dir=tmp_path / "a", jobs=1).measurements_path
    out = tmp_path / "b"
    cache = out / CACHE_DIRNAME
    proc = subprocess.Popen([sys.executable, "-c", _RUN, str(folder), str(out), str(jobs)],
                            env={**os.environ, "PYTHONWARNINGS": "error"})
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            if count_entries(cache) >= 5:
                break
            time.sleep(0.005)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    done = count_entries(cache)
    assert not (out / "measurements.csv").exists(), "the run finished before it was killed"
    assert 5 <= done < n
    result = process_session(folder, out_dir=out, jobs=jobs)
    assert (result.n_measured, result.n_cached) == (n - done, done)
    assert result.measurements_path.read_bytes() == reference.read_bytes()


def _how_measured(caplog) -> str:
    said = [r.getMessage() for r in caplog.records if "results: measuring with" in r.getMessage()]
    assert len(said) == 1, said
    return said[0].rsplit("measuring with ", 1)[1]


def test_many_images_to_measure_go_to_worker_processes_and_give_the_same_file(rendered, tmp_path, monkeypatch,
                                                                              caplog):
    folder, plan, _ = rendered
    caplog.set_level("DEBUG", logger="vision_torsion.session.process")
    few = process_session(folder, out_dir=tmp_path / "threads", jobs=2)
    assert _how_measured(caplog) == "2 reading threads"  # fewer than PROCESS_MIN_IMAGES
    monkeypatch.setattr(process_module, "PROCESS_MIN_IMAGES", len(plan.rows))
    caplog.clear()
    many = process_session(folder, out_dir=tmp_path / "processes", jobs=2)
    assert _how_measured(caplog) == "2 worker processes"
    assert many.n_measured == len(plan.rows)
    assert many.measurements_path.read_bytes() == few.measurements_path.read_bytes()
    caplog.clear()
    again = process_session(folder, out_dir=tmp_path / "processes", jobs=2)  # every result cached
    assert _how_measured(caplog) == "2 reading threads"
    assert again.n_cached == len(plan.rows)


def test_a_measuring_function_that_does_not_pickle_runs_in_threads(rendered, tmp_path, monkeypatch, caplog):
    from vision_torsion.pair import measure_pair

    folder, plan, _ = rendered
    monkeypatch.setattr(process_module, "PROCESS_MIN_IMAGES", 1)
    caplog.set_level("DEBUG", logger="vision_torsion.session.process")

    def local_measure(image, **kw):  # a local function: not picklable
        return measure_pair(image, **kw)

    result = process_session(folder, out_dir=tmp_path / "two", jobs=2, measure=local_measure)
    assert _how_measured(caplog) == "2 reading threads"
    assert result.n_measured == len(plan.rows) and result.n_ok == len(plan.rows)
    caplog.clear()
    result = process_session(folder, out_dir=tmp_path / "four", jobs=4, measure=local_measure)
    assert _how_measured(caplog) == "3 reading threads"
    assert "cannot be sent to worker processes; measuring with 3 threads of this process instead" in caplog.text
