"""Normalising a computed plane correction (calibration's side of :mod:`vision_torsion.correction`).

:class:`~vision_torsion.correction.PlaneCorrection` and :func:`~vision_torsion.correction.load_correction`
live in the core (:mod:`vision_torsion.correction`), beside the settings and the angle
that apply them; they are re-exported here for the calibration code and its callers.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..correction import FORMAT_NAME, FORMAT_VERSION, PlaneCorrection, check_suffix, load_correction
from ..errors import CalibrationError

__all__ = ["PlaneCorrection", "load_correction", "normalised", "check_suffix", "FORMAT_NAME", "FORMAT_VERSION"]


def normalised(correction: PlaneCorrection, anchor) -> PlaneCorrection:
    """The same correction followed by the disk-plane similarity that makes it look like
    the identity at `anchor`: the anchor (image px) maps to itself and the Jacobian
    there is symmetric with determinant 1 (no turn, no overall scale).

    Angles are unchanged (a similarity turns every line by the same amount).
    """
    ax, ay = float(anchor[0]), float(anchor[1])
    J, X, Y = correction.jacobian(ax, ay)
    U, s, Vt = np.linalg.svd(J)
    R = U @ Vt  # polar decomposition J = R S
    if np.linalg.det(R) < 0:
        raise CalibrationError("the correction mirrors the image (orientation reversed)")
    scale = 1.0 / math.sqrt(float(np.linalg.det(J)))
    A = scale * R.T
    T = np.eye(3)
    T[:2, :2] = A
    T[:2, 2] = np.array([ax, ay]) - A @ np.array([float(X), float(Y)])
    return replace(correction, homography=T @ correction.homography, info=dict(correction.info))
