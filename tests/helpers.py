"""Shared helpers for the session tests (not a test module: imported by test_session_*).

- :func:`draw_target` renders two dark discs at sub-pixel centres with OpenCV, the
  way a camera sees the marker target rotated by a known angle.
- :func:`make_session` plans a small session and renders every image of it with a
  known angle, returning the truth.
- :func:`supersampled_grid`, :func:`ellipse_mask` and :func:`area_image` render
  dark shapes (ellipses seen obliquely, teardrops) by area coverage, for the marker
  tests that need shapes the synthetic renderer does not draw.
- :func:`run_cli` runs the command line in this process and checks that no
  traceback reached the user.
- :class:`FakeCore` is a simple centroid measurer, passed to ``process_session`` as
  its ``measure`` function, so the bookkeeping of ``process`` (cache, resume,
  failures, output table) can be tested independently of the measurement core; it
  counts the images it measured.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import cv2
import numpy as np

from vision_torsion.errors import MarkerError
from vision_torsion.images import load_image, write_image
from vision_torsion.markers import Marker
from vision_torsion.pair import PairMeasurement
from vision_torsion.session.plan import plan_config, plan_session

# Image geometry: non-square, target centre off the pixel grid.
WIDTH, HEIGHT = 200, 150
CENTRE = (101.3, 74.6)
ARM_PX = 45.0
MARKER_RADIUS_PX = 9.0
BACKGROUND = 220


def draw_target(angle_deg: float, *, width=WIDTH, height=HEIGHT, centre=CENTRE,
                arm_px=ARM_PX, radius_px=MARKER_RADIUS_PX) -> np.ndarray:
    """8-bit image of two dark discs on a bright background, the marker-to-marker
    vector at `angle_deg` CCW as displayed (y grows downwards)."""
    img = np.full((height, width), BACKGROUND, np.uint8)
    a = math.radians(angle_deg)
    for s in (-1, 1):
        x = centre[0] + s * arm_px * math.cos(a)
        y = centre[1] - s * arm_px * math.sin(a)
        cv2.circle(img, (round(x * 256), round(y * 256)), round(radius_px * 256), 30,
                   thickness=-1, lineType=cv2.LINE_AA, shift=8)
    return img


def true_angle(orientation: float, torque_nm: float, phase: str, index: int) -> float:
    """The angle rendered for a row: an orientation offset, a linear response, a
    hysteresis offset (unloading lags), and a small drift with the image index that
    makes every image of a session different (identical files would share a cache
    entry)."""
    lag = 0.5 if phase.endswith("unloading") else 0.0
    return 0.3 * orientation / 60.0 + 40.0 * torque_nm + lag + 0.01 * index


def make_session(folder, *, orientations=(0, 60), cycles=1, steps=2, draw=None,
                 **plan_kw):
    """Plan a small session and render all of its images; returns (plan, truth).

    `draw(angle_deg, index)` returns the image of a row (default: :func:`draw_target`);
    `truth` maps the manifest image path to the angle (degrees) drawn in it.
    """
    draw = draw or (lambda angle, index: draw_target(angle))
    step_mass = 0.02
    plan = plan_session(plan_config(max_torque_nm=steps * 2 * step_mass * 9.81 * 0.05, step_mass_kg=step_mass,
                                    arm_radius_m=0.05, orientations_deg=orientations, cycles=cycles, **plan_kw), folder)
    truth = {}
    for index, row in enumerate(plan.rows):
        sign = {"pos": 1, "neg": -1, "ref": 0}[row["phase"][:3]]
        torque = sign * 2 * float(row["mass_kg"]) * 9.81 * 0.05
        angle = true_angle(float(row["orientation_deg"]), torque, row["phase"], index)
        write_image(Path(folder) / row["image"], draw(angle, index))
        truth[row["image"]] = angle
    return plan, truth


def run_cli(capsys, *argv):
    """Run the command line in this process; return (status, stdout, stderr), checking
    that no traceback was printed."""
    from vision_torsion.cli import main

    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err, err
    return code, out, err


def tree_digest(folder, *, exclude=()) -> dict[str, tuple[str, int]]:
    """Every file under `folder` (outside `exclude` subfolders): content hash and mtime."""
    folder = Path(folder)
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder).as_posix()
        if any(rel == e or rel.startswith(e + "/") for e in exclude):
            continue
        st = p.lstat()
        digest = hashlib.blake2b(p.read_bytes()).hexdigest() if p.is_file() else "dir"
        out[rel] = (digest, st.st_mtime_ns)
    return out


# -- a stand-in for the measurement core ----------------------------------------------


class FakeCore:
    """Centroids of the two largest dark blobs, as a real :class:`PairMeasurement`;
    counts what it measured.

    Passed to ``process_session(..., measure=core.measure_pair)`` so the bookkeeping of
    ``process`` (cache, resume, failures, output table) is tested apart from the
    measurement core; the angles are then computed by the real
    :func:`vision_torsion.angle.sequence_angles` from these centres.
    """

    def __init__(self, *, interrupt_after: int | None = None):
        self.measured: list[str] = []
        self.interrupt_after = interrupt_after

    def measure_pair(self, image, *, settings, name=None, candidates=None):
        if self.interrupt_after is not None and len(self.measured) >= self.interrupt_after:
            raise KeyboardInterrupt
        data = np.asarray(image.data if hasattr(image, "data") else load_image(image).data, dtype=np.float64)
        weight = np.clip(BACKGROUND - data, 0, None)  # darkness, anti-aliased edges included
        n, labels, stats, _ = cv2.connectedComponentsWithStats((weight > 0).astype(np.uint8))
        if n - 1 < 2:
            raise MarkerError(f"{name or image}: found {n - 1} marker(s), expected 2")
        big = 1 + np.argsort(stats[1:, cv2.CC_STAT_AREA])[::-1][:2]
        ys, xs = np.indices(data.shape)
        markers = []
        for label in big:
            w = np.where(labels == label, weight, 0)
            x, y = float((w * xs).sum() / w.sum()), float((w * ys).sum() / w.sum())
            radius = math.sqrt(stats[label, cv2.CC_STAT_AREA] / math.pi)
            markers.append(Marker(x_px=x, y_px=y, radius_px=radius, x_std_px=0.01, y_std_px=0.01,
                                  xy_cov_px2=0.0, radius_std_px=0.01))
        first, second = sorted(markers, key=lambda m: m.x_px)
        self.measured.append(name or str(image))
        return PairMeasurement(first=first, second=second)


def supersampled_grid(height: int, width: int, n: int = 4):
    """(xs, ys) of the centres of an image's sub-pixels, `n` x `n` per pixel, in
    image pixels (origin at the centre of the top-left pixel)."""
    return (np.mgrid[0 : height * n, 0 : width * n][::-1] + 0.5) / n - 0.5


def ellipse_mask(xs, ys, centre, radius, axis_ratio=1.0, angle_deg=0.0):
    """Sub-pixels inside an ellipse of geometric-mean radius `radius` (px), minor over
    major axis `axis_ratio`, its major axis at `angle_deg` from the x axis."""
    t = np.deg2rad(angle_deg)
    u = (xs - centre[0]) * np.cos(t) + (ys - centre[1]) * np.sin(t)
    v = (ys - centre[1]) * np.cos(t) - (xs - centre[0]) * np.sin(t)
    q = np.sqrt(axis_ratio)
    return (u * q / radius) ** 2 + (v / (q * radius)) ** 2 < 1.0


def area_image(dark, n: int = 4, *, background=200.0, depth=160.0):
    """An image (float64) of sub-pixel flags `dark` (`n` x `n` per pixel): each
    pixel `background` less `depth` times the share of it covered."""
    h, w = dark.shape[0] // n, dark.shape[1] // n
    return background - depth * dark.reshape(h, n, w, n).mean(axis=(1, 3))


def mount_tmpfs(path: Path, options: str) -> bool:
    """Mount a tmpfs with `options` (``size=4m``, ``ro``, ...) on `path` (created);
    False where mounting is not allowed (not root, a container without it)."""
    import subprocess

    path.mkdir(parents=True, exist_ok=True)
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)],
                              capture_output=True, timeout=20)
    except (OSError, subprocess.SubprocessError):
        return False
    return done.returncode == 0
