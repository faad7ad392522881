"""A synthetic test session: images whose angles follow a hysteresis model.

The session is planned exactly as a test engineer would plan it
(:func:`vision_torsion.session.plan.plan_session`: session.toml, manifest.csv,
capture sheet), then every planned image is rendered with the disk turned by the
angle the paper's bilinear stiffness-switching model gives for the torque really
applied (:func:`vision_torsion.analysis.models.bilinear_response`).

Realism that makes uncertainty coverage testable:

- true torques: every weight piece has its own true mass, drawn once per session
  from the rig's mass tolerance (uniform within ± the tolerance, the distribution
  a ± tolerance implies), and the torque of a step is ``g·r·Σ`` of the pieces really
  on the two loaded pans;
- orientation-to-orientation and cycle-to-cycle variation: k_u, k_l and τ_c of
  each orientation and cycle are the nominal ones times ``1 + N(0, variation)``.

The scene TOML of a session carries a ``[session]`` table (see
``synthetic/paper_session.toml``); ``truth.csv`` records the true torque, the
true angle (in the reported convention: angle_sign applied, positive with positive
torque) and the disk rotation of every image, and ``truth.json`` the model
parameters of every orientation and cycle.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import SceneError
from ..fileio import write_csv, write_json
from ..progress import track
from ..textfiles import read_toml
from .folders import truth_row, write_rendered
from .render import render
from .scene import Scene, check_markers_in_frame, scene_from_dict, table_to_dataclass

__all__ = ["SessionSpec", "load_session_scene", "write_session_folder", "session_truth"]


@dataclass(frozen=True)
class SessionSpec:
    """The rig, protocol and hysteresis model of a synthetic session (SI units).

    Defaults are the main paper's: unloading stiffness 4.4 N·m/rad, loading stiffness
    after reversal 0.3 N·m/rad, critical torque 0.15 N·m, ±0.36 N·m in 0.02 kg steps
    at r = 0.05 m (snapped down to 18 steps, 0.353 N·m), six orientations.
    """

    k_u_nm_per_rad: float = 4.4
    k_l_nm_per_rad: float = 0.3
    tau_c_nm: float = 0.15
    max_torque_nm: float = 0.36
    step_mass_kg: float = 0.02
    arm_radius_m: float = 0.05
    gravity_m_per_s2: float = 9.81
    mass_tolerance_kg: float = 1e-4
    orientations_deg: tuple = (0.0, 60.0, 120.0, 180.0, 240.0, 300.0)
    cycles: int = 1
    orientation_variation: float = 0.0
    cycle_variation: float = 0.0
    angle_sign: int = 1

    def session_config(self, *, polarity: str = "dark", steps: int | None = None, header: dict | None = None,
                       catalogue=None, target=None):
        """The :class:`~vision_torsion.session.config.SessionConfig` of this session's rig
        and protocol (:func:`~vision_torsion.session.plan.plan_config`): markers of
        `polarity`; `steps` per phase instead of the spec's maximum torque; the
        test's identity, catalogue and an N-marker `target` (None: two markers) as
        :func:`~vision_torsion.session.plan.plan_config` takes them.

        Raises
        ------
        SessionError
            An invalid rig or protocol (named as its session.toml key).
        """
        from ..session.plan import plan_config

        return plan_config(
            max_torque_nm=None if steps is not None else self.max_torque_nm, steps=steps,
            step_mass_kg=self.step_mass_kg, arm_radius_m=self.arm_radius_m, orientations_deg=self.orientations_deg,
            cycles=self.cycles, gravity_m_per_s2=self.gravity_m_per_s2, mass_tolerance_kg=self.mass_tolerance_kg,
            polarity=polarity, angle_sign=self.angle_sign, header=header, catalogue=catalogue,
            **({} if target is None else {"target": target}))


def _spec_from_dict(table: dict, where: str) -> SessionSpec:
    spec = table_to_dataclass(SessionSpec, table, section="session", prefix=f"{where}: ")
    for k in ("k_u_nm_per_rad", "k_l_nm_per_rad", "max_torque_nm", "step_mass_kg", "arm_radius_m", "gravity_m_per_s2"):
        if not getattr(spec, k) > 0:
            raise SceneError(f"{where}: [session] {k} must be positive, got {getattr(spec, k)}")
    if spec.angle_sign not in (1, -1):
        raise SceneError(f"{where}: [session] angle_sign must be 1 or -1, got {spec.angle_sign}")
    if spec.tau_c_nm < 0 or spec.mass_tolerance_kg < 0 or spec.orientation_variation < 0 or spec.cycle_variation < 0:
        raise SceneError(f"{where}: [session] tau_c_nm, mass_tolerance_kg and variations must not be negative")
    return spec


def load_session_scene(path) -> tuple[Scene, SessionSpec]:
    """Read a scene TOML with a ``[session]`` table.

    Raises
    ------
    SceneError
        The file is missing, invalid, or its ``[session]`` table has a bad field.
    """
    from ..resources import SCENES, named_file

    p = named_file(path, SCENES, error=SceneError, what="scene")  # a path, or a ready scene's name
    data = read_toml(p, what="a scene file (TOML)", error=SceneError)
    table = data.pop("session", {})
    if not isinstance(table, dict):
        raise SceneError(f"{p}: [session] must be a table")
    return scene_from_dict(data, where=str(p), name=p.stem), _spec_from_dict(table, str(p))


def _piece_masses(spec: SessionSpec, n_pieces: int, rng) -> np.ndarray:
    """True masses (kg) of the pieces on the four pans (+A, +B, -A, -B), shape (4, n)."""
    tol = spec.mass_tolerance_kg
    return spec.step_mass_kg + rng.uniform(-tol, tol, size=(4, n_pieces))


def session_truth(spec: SessionSpec, rows, *, seed: int = 0):
    """True torque (N·m) and model angle (deg) of every planned manifest row.

    Parameters
    ----------
    spec : SessionSpec
        Rig and model.
    rows : sequence of dict
        Manifest rows in protocol order (``orientation_deg, cycle, phase, mass_kg``).
    seed : int
        Seed for the piece masses and the parameter variations.

    Returns
    -------
    (pandas.DataFrame, dict)
        Per row: ``true_torque_nm`` and ``true_angle_deg`` (relative to the
        orientation's reference, positive with positive torque); and the model
        parameters used for every orientation and cycle.
    """
    from ..analysis.models import bilinear_response

    rng = np.random.default_rng(seed)
    frame = pd.DataFrame(list(rows))
    per_pan = frame["mass_kg"].astype(float) / spec.step_mass_kg
    n_max = int(np.ceil(per_pan.max() - 1e-9)) if len(frame) else 0
    pieces = _piece_masses(spec, max(n_max, 1), rng)
    cum = np.concatenate([np.zeros((4, 1)), np.cumsum(pieces, axis=1)], axis=1)
    g_r = spec.gravity_m_per_s2 * spec.arm_radius_m
    sign = frame["phase"].map(
        {
            "reference": 0,
            "positive_unloading": 1,
            "negative_loading": -1,
            "negative_unloading": -1,
            "positive_loading": 1,
        }
    )
    k = np.rint(per_pan).astype(int)
    pos = g_r * (cum[0, k] + cum[1, k])
    neg = g_r * (cum[2, k] + cum[3, k])
    torque = np.where(sign > 0, pos, np.where(sign < 0, -neg, 0.0))
    frame["true_torque_nm"] = torque
    angles = np.zeros(len(frame))
    params = []
    for orient, idx in frame.groupby("orientation_deg", sort=False).groups.items():
        idx = np.asarray(list(idx))
        o_scale = 1 + spec.orientation_variation * rng.standard_normal(3)
        sub = frame.loc[idx]
        theta_prev, prev_tau = None, None
        for cycle, cidx in sub.groupby(sub["cycle"].astype(int), sort=False).groups.items():
            cidx = np.asarray(list(cidx))
            c_scale = o_scale * (1 + spec.cycle_variation * rng.standard_normal(3))
            p = dict(
                k_u=spec.k_u_nm_per_rad * c_scale[0],
                k_l=spec.k_l_nm_per_rad * c_scale[1],
                tau_c=max(spec.tau_c_nm * c_scale[2], 0.0),
            )
            params.append(
                {
                    "orientation_deg": float(orient),
                    "cycle": int(cycle),
                    "k_u_nm_per_rad": p["k_u"],
                    "k_l_nm_per_rad": p["k_l"],
                    "tau_c_nm": p["tau_c"],
                }
            )
            tau = torque[cidx]
            if theta_prev is None:
                th = bilinear_response(tau, **p)
            else:
                # continue from the previous cycle's last state (same torque, +Tmax)
                th = bilinear_response(np.concatenate([[prev_tau], tau]), theta_start=theta_prev, **p)[1:]
            angles[cidx] = th
            theta_prev, prev_tau = th[-1], tau[-1]
        ref = idx[frame.loc[idx, "phase"].to_numpy() == "reference"]
        base = angles[ref[0]] if ref.size else angles[idx[0]]
        angles[idx] -= base
    frame["true_angle_deg"] = np.degrees(angles)
    return frame, {"cycles": params, "spec": dataclasses.asdict(spec)}


def _target_scene(scene: Scene, target):
    """`scene` with the dots of `target` for markers (the farthest at the scene's
    marker distance), and the target read."""
    from ..targets import Target, load_target
    from .target_scenes import target_scene

    target = target if isinstance(target, Target) else load_target(target)
    reach_mm = float(np.max(np.hypot(target.centres_mm[:, 0], target.centres_mm[:, 1])))
    if not reach_mm > 0:
        raise SceneError(f"target {target.name!r}: every dot is on the shaft axis; nothing turns")
    return target_scene(target, px_per_mm=scene.markers.distance_px / reach_mm, base=scene), target


def write_session_folder(
    scene: Scene, spec: SessionSpec, out_dir, *, seed: int = 0, progress: bool = False, overwrite: bool = False,
    header: dict | None = None, catalogue=None, target=None,
) -> Path:
    """Plan and render a complete synthetic test session.

    Parameters
    ----------
    scene : Scene
        The camera's view of the disk.
    spec : SessionSpec
        Rig, protocol and hysteresis model.
    out_dir : str or os.PathLike
        The session folder to create (must not hold a session yet).
    seed : int
        Seed of the piece masses, parameter variations and image noise.
    progress : bool
        Show a progress bar.
    overwrite : bool
        Replace a session already in the folder.
    header, catalogue : optional
        The test's identity and the gear type's catalogue file, as
        :func:`~vision_torsion.session.plan.plan_session` takes them (into
        session.toml's ``[gear]``, ``[test]`` and ``[spec]``).
    target : Target, str or os.PathLike, optional
        An N-marker target (a ready target's name such as ``"ring16"``, a target
        file): its dots replace the scene's two markers
        (:func:`~vision_torsion.synthetic.target_scene`), scaled so the dot farthest
        from the shaft sits at the scene's marker distance, with the scene's
        polarity, optics and noise; session.toml gets its ``[target]``, and
        truth.csv every dot's true centre (``marker1_x_px`` is dot 0).

    Returns
    -------
    pathlib.Path
        The session folder, with session.toml, manifest.csv, capture_sheet.md,
        images/, truth.csv and truth.json.

    Raises
    ------
    SceneError
        A rotation of the session would take a marker out of the frame (checked
        before any image is written), or the scaled target does not fit it.
    TargetError
        `target` cannot be read.
    SessionError
        Invalid rig or protocol, or the folder already holds a session.
    """
    from ..session.plan import plan_rows, plan_session

    out = Path(out_dir)
    if target is not None:
        scene, target = _target_scene(scene, target)
    suffix = ".jpg" if scene.noise.jpeg_quality else ".png"
    # planned by its whole number of steps (the spec's maximum snapped down, as documented):
    # planning by max_torque_nm would warn a demo user that 0.36 N·m is not whole steps
    rig = spec.session_config(polarity=scene.markers.polarity).rig
    n = max(int(np.floor(spec.max_torque_nm / rig.step_torque_nm + 1e-9)), 1)
    config = spec.session_config(polarity=scene.markers.polarity, steps=n, header=header, catalogue=catalogue,
                                 target=target)
    # the rows the plan will hold, so the rotations are checked against the frame
    # before anything is written
    truth, params = session_truth(spec, plan_rows(config, n, suffix=suffix), seed=seed)
    disk_angles = spec.angle_sign * truth["true_angle_deg"].to_numpy()
    for a in (disk_angles.min(), disk_angles.max()):
        check_markers_in_frame(scene, float(a), where=scene.name)
    plan = plan_session(config, out, image_suffix=suffix, overwrite=overwrite)
    if list(plan.rows) != truth[list(plan.rows[0])].to_dict("records"):  # pragma: no cover - a planning change
        raise SceneError("the session plan changed between checking and writing")
    rows = []
    noise_seed = np.random.SeedSequence(seed).spawn(1)[0]
    rngs = noise_seed.spawn(len(truth))
    for i, rec in enumerate(track(truth.to_dict("records"), desc="rendering", unit="image", enabled=progress)):
        disk_angle = spec.angle_sign * rec["true_angle_deg"]
        r = render(scene, disk_angle, seed=np.random.default_rng(rngs[i]))
        write_rendered(out / rec["image"], r, scene)
        rows.append(
            truth_row(
                rec["image"], r, true_torque_nm=rec["true_torque_nm"], true_angle_deg_reported=rec["true_angle_deg"]
            )
        )
    table = pd.DataFrame(rows).rename(
        columns={"true_angle_deg": "disk_rotation_deg", "true_angle_deg_reported": "true_angle_deg"}
    )
    write_csv(out / "truth.csv", table)
    write_json(out / "truth.json", params)
    return out
