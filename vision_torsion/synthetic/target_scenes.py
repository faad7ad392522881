"""Scenes of N-marker targets: a printed :class:`~vision_torsion.targets.Target` on the disk.

The target's origin (its ring's or grid's centre) is put on the disk's rotation
centre, the layout is scaled by `px_per_mm`, and the markers keep the base scene's
polarity, level, optics, noise and lighting.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..targets import Target, load_target
from .scene import Scene, validate_scene

__all__ = ["target_scene"]


def target_scene(target, *, px_per_mm: float, base: Scene | None = None) -> Scene:
    """A scene whose markers are the dots of `target`.

    Parameters
    ----------
    target : Target, str or os.PathLike
        The target, a target file or a ready target's name.
    px_per_mm : float
        Image scale of the disk plane (px per mm).
    base : Scene, optional
        Everything but the markers' layout (:class:`Scene` defaults: a 1400×1000
        image turning about (700, 500)).

    Returns
    -------
    Scene

    Raises
    ------
    TargetError
        The target cannot be read.
    SceneError
        The scaled target does not fit the frame, or its dots overlap.

    Examples
    --------
    >>> s = target_scene("ring16", px_per_mm=7.5)
    >>> len(s.markers.positions_deg), s.markers.radii()[:2], s.markers.distance_px
    (16, (45.0, 36.0), 300.0)
    """
    target = target if isinstance(target, Target) else load_target(target)
    base = base or Scene()
    c = target.centres_mm * float(px_per_mm)
    dist = np.hypot(c[:, 0], c[:, 1])
    positions = tuple(float(v) for v in np.degrees(np.arctan2(-c[:, 1], c[:, 0])))
    radii = tuple(float(v) for v in target.radii_mm * float(px_per_mm))
    same = bool(np.allclose(dist, dist[0], rtol=0, atol=1e-9))
    markers = dataclasses.replace(
        base.markers, positions_deg=positions, radii_px=radii, radius_px=float(np.median(radii)),
        distance_px=float(dist[0]) if same else float(np.max(dist)),
        distances_px=() if same else tuple(float(v) for v in dist))
    scene = dataclasses.replace(base, markers=markers)
    validate_scene(scene, where=f"target {target.name}")
    return scene
