"""Smoke test of the peer benchmark (benchmarks/peers.py, benchmarks/bench_peers.py).

Not an accuracy claim (those live in benchmarks/results/): it only keeps the
benchmark code from rotting. Every method must run without warnings on a standard
scene image and return the two marker centres near the truth, and the benchmark's
per-repeat worker must produce an angle for every method.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from vision_torsion.synthetic import load_scene, render

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


def _load(name):
    if str(BENCH) not in sys.path:
        sys.path.insert(0, str(BENCH))
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(name, module)
    spec.loader.exec_module(module)
    return sys.modules[name]


peers = _load("peers")

# Hough centres lie on the accumulator grid (half-pixel steps with dp = 1.5), so
# they may be off by up to ~0.75 px per axis; every other method is sub-pixel.
TOLERANCE_PX = {"hough_alt": 1.5}
DEFAULT_TOLERANCE_PX = 0.1


def _has_new_skimage() -> bool:
    """scikit-image >= 0.26 (CircleModel.from_estimate): the bench extra; it needs
    Python >= 3.11, so on 3.10 the scikit-image peer is not tested."""
    try:
        from skimage.measure import CircleModel
    except ImportError:
        return False
    return hasattr(CircleModel, "from_estimate")


needs_skimage = pytest.mark.skipif(not _has_new_skimage(), reason="scikit-image >= 0.26 not installed")


@pytest.fixture(scope="module")
def standard_image():
    scene = load_scene(
        Path(__file__).resolve().parents[1] / "vision_torsion" / "synthetic" / "scenes" / "standard.toml"
    )
    return render(scene, 27.5, seed=np.random.default_rng(8))


@pytest.mark.parametrize(
    "peer",
    [pytest.param(p, marks=needs_skimage) if p.name == "canny_circle" else p for p in peers.PEERS],
    ids=lambda p: p.name,
)
def test_peer_finds_both_markers(peer, standard_image):
    det = peer.func(standard_image.image)
    truth = standard_image.centres[np.argsort(standard_image.centres[:, 0])]
    assert det.centres.shape == (2, 2)
    err = np.abs(det.centres - truth).max()
    assert err < TOLERANCE_PX.get(peer.name, DEFAULT_TOLERANCE_PX), f"{peer.name}: centre error {err:.3f} px"
    assert (det.pair is not None) == peer.name.startswith("ours")


def test_peer_failure_is_raised_not_returned():
    blank = np.full((200, 300), 128, dtype=np.uint8)
    for peer in peers.PEERS:
        if peer.name == "canny_circle" and not _has_new_skimage():
            continue
        with pytest.raises(peers.PeerFailure):
            peer.func(blank)


@needs_skimage
def test_bench_repeat_and_summary():
    bench = _load("bench_peers")
    rep = bench.run_repeat("standard", 0, 0, [12.5])
    assert {r["method"] for r in rep["rows"]} == {p.name for p in peers.PEERS}
    assert all(r["status"] == "ok" for r in rep["rows"])
    summary = bench.summarise(rep["rows"], rep["times_s"], crb_rms=0.00044)
    ours = summary["ours_default"]
    # one angle from two images: the error is a few thousandths of a degree at most
    assert ours["n_ok"] == 1 and ours["rms_deg"] < 0.005
    assert "reported_std_over_rms" in ours
    table = bench.scene_table("Standard", summary, 0.00044, 2)
    assert table.count("\n| ") == len(peers.PEERS) + 1
