"""A scripted camera: a session's photographs as a camera takes them, mistakes included.

:func:`capture_script` plans a session (:func:`~vision_torsion.session.plan.plan_session`,
no images) and renders the photographs a test engineer would take following it,
with the capture mistakes of the rig on request:

- ``forgotten=i``: at row ``i`` a weight piece was forgotten on one pan (one piece
  too few while loading, one too many while unloading): the torque is off by half a
  step for that photograph, and right again at the next row;
- ``extra_after=j``: after row ``j``'s photograph, a second one of the same load
  (new noise: a new exposure, not a copy);
- ``missed=m``: row ``m``'s load was applied but not photographed;
- ``swapped=s``: rows ``s`` and ``s + 1`` photographed the other way round;
- ``bumped=(b, dx, dy, turn)``: the camera knocked before row ``b``'s photograph;
- ``blurred=u``: row ``u``'s photograph out of focus.

Angles follow the paper's bilinear model (:func:`~vision_torsion.analysis.models.bilinear_response`)
for the nominal torque sequence of every row (a missed row's load was applied),
relative to each orientation's reference. :class:`ScriptedCamera` then writes the
photographs into a folder as ``IMG_0001.png, ...`` in chunks, as a camera writing
to a card or a tethering program does, so that a watcher sees half-written files;
its :meth:`ScriptedCamera.steps` yields after every chunk (a test interleaves its
own polling without waiting), :meth:`ScriptedCamera.run` sleeps between chunks.
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..measurements import couple_torque_nm
from .render import render
from .scene import Scene

__all__ = ["CameraShot", "capture_script", "ScriptedCamera"]

_SIGN = {"reference": 0, "positive_unloading": 1, "negative_loading": -1,
         "negative_unloading": -1, "positive_loading": 1, "closing": 0}


@dataclass(frozen=True)
class CameraShot:
    """One photograph of the script.

    Attributes
    ----------
    row : int
        Index of the manifest row whose load it shows.
    kind : str
        "planned", "extra" (a second photograph of row's load) or "forgotten"
        (row's load with a piece missing on one pan).
    torque_nm, angle_deg : float
        True torque (N·m) and angle (deg, positive with positive torque, relative to
        the orientation's reference).
    png : bytes
        The encoded photograph.
    """

    row: int
    kind: str
    torque_nm: float
    angle_deg: float
    png: bytes


def capture_script(scene: Scene, spec, session_dir, *, seed: int = 0, forgotten=None,
                   extra_after=None, missed=None, swapped=None, bumped=None, blurred=None,
                   response=None):
    """Plan a session into `session_dir` and render its photographs with mistakes.

    Parameters
    ----------
    scene : Scene
        The camera's view (8-bit PNG output).
    spec : vision_torsion.synthetic.session.SessionSpec
        Rig, protocol and bilinear model (orientation variation is not applied).
    session_dir : path-like
        Where the session (session.toml, manifest.csv; no images) is planned.
    seed : int
        Seed of the image noise.
    forgotten, extra_after, missed : int, optional
        Row indices of the mistakes (module docstring).
    swapped : int, optional
        The photographs of rows ``swapped`` and ``swapped + 1`` are taken the other
        way round (the second load photographed first).
    bumped : (int, float, float, float), optional
        ``(row, dx_px, dy_px, turn_deg)``: the camera is knocked before that row's
        photograph: the view moves by (dx, dy) px and turns by `turn_deg` from then
        on.
    blurred : int, optional
        Row index of a photograph taken out of focus (blur σ three times the scene's,
        and at least 3 px).
    response : callable, optional
        ``response(torque_nm) -> angle_rad`` of one orientation's torque sequence
        (the gear); the bilinear model of `spec` by default.

    Returns
    -------
    (SessionPlan, list of CameraShot)
        The plan, and the photographs in the order they were taken.
    """
    from ..analysis.models import bilinear_response
    from ..session.plan import plan_session

    plan = plan_session(spec.session_config(polarity=scene.markers.polarity), session_dir)
    rows, rig = plan.rows, plan.config.rig
    torque = np.array([_SIGN[r["phase"]] * couple_torque_nm(float(r["mass_kg"]), gravity_m_per_s2=rig.gravity_m_per_s2,
                                                             arm_radius_m=rig.arm_radius_m) for r in rows])
    actual = torque.copy()
    if forgotten is not None:
        unloading = rows[forgotten]["phase"].endswith("unloading")
        sign = _SIGN[rows[forgotten]["phase"]]
        # one piece forgotten on one pan of the pair: half the step
        actual[forgotten] += sign * (1 if unloading else -1) * rig.step_torque_nm / 2
    angles = np.zeros(len(rows))
    orient = np.array([float(r["orientation_deg"]) for r in rows])
    for o in dict.fromkeys(orient):
        idx = np.flatnonzero(orient == o)
        if response is None:
            th = np.degrees(bilinear_response(actual[idx], k_u=spec.k_u_nm_per_rad,
                                              k_l=spec.k_l_nm_per_rad, tau_c=spec.tau_c_nm))
        else:
            th = np.degrees(np.asarray(response(actual[idx]), float))
        angles[idx] = th - th[0]
    rngs = np.random.SeedSequence(seed).spawn(len(rows) + 1)
    shots = []

    def shoot(i, kind, rng):
        view, turn = scene, 0.0
        if bumped is not None and i >= bumped[0]:
            disk = dataclasses.replace(scene.disk, center_x=scene.disk.center_x + bumped[1],
                                       center_y=scene.disk.center_y + bumped[2])
            view, turn = dataclasses.replace(scene, disk=disk), bumped[3]
        if i == blurred:
            sigma = max(3.0 * scene.optics.blur_sigma_px, 3.0)
            view = dataclasses.replace(view, optics=dataclasses.replace(scene.optics, blur_sigma_px=sigma))
        r = render(view, spec.angle_sign * angles[i] + turn, seed=np.random.default_rng(rng))
        ok, buf = cv2.imencode(".png", r.image)
        shots.append(CameraShot(i, kind, float(actual[i]), float(angles[i]), buf.tobytes()))

    for i in range(len(rows)):
        if i != missed:
            shoot(i, "forgotten" if i == forgotten else "planned", rngs[i])
        if i == extra_after:
            shoot(i, "extra", rngs[-1])
    if swapped is not None:
        k = next(n for n, shot in enumerate(shots) if shot.row == swapped)
        shots[k], shots[k + 1] = shots[k + 1], shots[k]
    return plan, shots


class ScriptedCamera:
    """Writes photographs into a folder the way a camera does: in chunks.

    Parameters
    ----------
    folder : path-like
        The camera folder (created).
    photos : sequence of bytes
        The encoded photographs, in the order taken.
    chunk_bytes : int
        Bytes per write; a file is complete after its last chunk.
    name : str
        File name pattern, formatted with the 1-based photograph number.
    start_time : float
        Modification time given to the first photograph (s since the epoch); each
        next one is `interval_s` later, as if taken at the rig's pace.
    """

    def __init__(self, folder, photos, *, chunk_bytes: int = 16384, name: str = "IMG_{:04d}.png",
                 start_time: float = 1.7e9, interval_s: float = 20.0):
        self.folder = Path(folder)
        self.photos = list(photos)
        self.chunk_bytes = chunk_bytes
        self.name = name
        self.start_time = start_time
        self.interval_s = interval_s
        self.written: list[Path] = []

    def steps(self):
        """Write everything; yield (path, complete) after every chunk."""
        self.folder.mkdir(parents=True, exist_ok=True)
        for k, data in enumerate(self.photos):
            path = self.folder / self.name.format(k + 1)
            with open(path, "wb") as fh:
                for start in range(0, len(data), self.chunk_bytes):
                    fh.write(data[start:start + self.chunk_bytes])
                    fh.flush()
                    done = start + self.chunk_bytes >= len(data)
                    if done:
                        break
                    yield path, False
            when = self.start_time + k * self.interval_s
            os.utime(path, (when, when))
            self.written.append(path)
            yield path, True

    def run(self, *, chunk_delay_s: float = 0.005, photo_delay_s: float = 0.02) -> None:
        """Write everything in real time: `chunk_delay_s` between chunks,
        `photo_delay_s` between photographs."""
        for _, complete in self.steps():
            time.sleep(photo_delay_s if complete else chunk_delay_s)
