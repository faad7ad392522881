"""Anchoring a computed plane correction: calibration's side of :mod:`vision_torsion.correction`.

:class:`~vision_torsion.correction.PlaneCorrection` lives in the core, beside the
settings and the angle that apply it; here a computed one is normalised so that it
looks like the identity at an anchor point.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..correction import PlaneCorrection
from ..errors import CalibrationError

__all__ = ["normalised"]


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
