"""A bumped camera or a loosened target, seen in the markers' positions.

While the gear turns, the target's two markers turn about one axis: with the
marker-to-marker direction turned by θ_i from the first image's, the midpoint
of the markers is ``m_i = c + R(θ_i) v`` for one centre ``c`` and one offset
``v`` (image coordinates, px). Four unknowns, linear; the images so far of an
orientation determine them (least squares), and each new image must fall on the
prediction. A camera knocked by a pixel (or the target slipping on its shaft)
moves every later midpoint by that pixel while the angles hardly change: the new
image is then off the prediction by about the shift, where the markers' centres
scatter by a few hundredths of a pixel.

The rule: off by more than ``max(0.3 px, 8 × the RMS residual of the fit so
far)`` is a move. 0.3 px is ten times the midpoint scatter of a sharp 8-bit
image and a third of the smallest bump worth catching (1 px, which turns the
angles of a 45 px arm by up to 0.01°); 8 × the fit's own scatter keeps a noisier
camera from false alarms. The first move of an orientation is reported (its
later images are all off by it: one bump, one warning); the fit needs three
images before it predicts (a move at the first loaded image after the reference
is seen when the angles come back towards zero).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["AxisWarning", "check_axis", "MIN_MOVE_PX"]

#: Smallest departure (px) from the rotation about the axis reported as a move.
MIN_MOVE_PX = 0.3
_RMS_FACTOR = 8.0
_MIN_FIT = 3


@dataclass(frozen=True)
class AxisWarning:
    """An image whose markers are off the rotation about the orientation's axis.

    Attributes
    ----------
    index : int
        Position of the image in the sequence given to :func:`check_axis`.
    offset_px : float
        How far its markers' midpoint is from where the rotation puts it (px).
    threshold_px : float
        The limit it passed (px).
    message : str
        What it looks like and what to do, in words (the caller adds file and row).
    """

    index: int
    offset_px: float
    threshold_px: float
    message: str


def _direction(p) -> float:
    return math.atan2(p.second.y_px - p.first.y_px, p.second.x_px - p.first.x_px)


def check_axis(pairs) -> list[AxisWarning]:
    """The first image of a sequence whose markers left the rotation about the axis.

    Parameters
    ----------
    pairs : sequence of PairMeasurement or None
        One orientation's images in capture order (None: not measured; skipped).
        Coordinates ``(x, y)`` in pixels, origin at the centre of the top-left
        pixel, y down.

    Returns
    -------
    list of AxisWarning
        Empty, or the first image off the prediction by more than the limit (module
        docstring).
    """
    idx = [i for i, p in enumerate(pairs) if p is not None]
    if len(idx) <= _MIN_FIT:
        return []
    first = _direction(pairs[idx[0]])
    rows, mids = [], []
    for i in idx:
        p = pairs[i]
        # the marker identity may swap between images: the direction mod 180°
        t = (_direction(p) - first + math.pi / 2) % math.pi - math.pi / 2
        c, s = math.cos(t), math.sin(t)
        rows.append(((1.0, 0.0, c, -s), (0.0, 1.0, s, c)))
        mids.append(((p.first.x_px + p.second.x_px) / 2, (p.first.y_px + p.second.y_px) / 2))
    a = np.asarray(rows, float)  # (n, 2, 4)
    m = np.asarray(mids, float)  # (n, 2)
    origin = m[0].copy()  # centred, so the fit stays conditioned far from the image origin
    m -= origin
    for k in range(_MIN_FIT, len(idx)):
        design, target = a[:k].reshape(-1, 4), m[:k].reshape(-1)
        coef, *_ = np.linalg.lstsq(design, target, rcond=1e-10)
        resid = target - design @ coef
        dof = max(design.shape[0] - 4, 1)
        rms = math.sqrt(float(resid @ resid) / dof)
        off = float(np.hypot(*(m[k] - a[k] @ coef)))
        limit = max(MIN_MOVE_PX, _RMS_FACTOR * rms)
        if off > limit:
            return [AxisWarning(idx[k], off, limit,
                                f"the camera or the target moved: the markers are {off:.2f} px off "
                                f"the rotation about the axis of the {k} images before (limit "
                                f"{limit:.2f} px; a bumped camera or a loosened target?); the "
                                "angles from this image on are offset: fix the camera and shoot "
                                "this orientation again")]
    return []
