"""The rotation angle between a reference image and a loaded image.

The paper computes θ = arctan(k₂) - arctan(k₁) from the slopes k of the line through
the two marker centres before and after loading. That is undefined for a vertical
line and folds every angle into (-90°, 90°). Here the direction of the
marker-to-marker vector is taken with ``atan2``, which is the same quantity wherever
the paper's formula is defined (a test shows it) and is right everywhere else.

Angles are in degrees, positive counter-clockwise as the image is displayed (y
pointing up), so with image coordinates (y down) the direction of v = p₂ - p₁ is
atan2(-v_y, v_x).

Marker identity. Two markers of equal size are interchangeable: swapping them turns
the line by 180°. The angle is therefore taken as the candidate nearest a predicted
angle (0° for a single image, the previous angle in a sequence), which both keeps
identity and unwraps the sequence; rotations between consecutive images must stay
below 90°. When the two markers differ in radius by clearly more than their
uncertainty, identity follows the radius and any rotation below 180° between
consecutive images is tracked.

Uncertainty. With centre covariances Σ₁, Σ₂ and g = (v_y, -v_x)/|v|², the variance of
a line's direction is gᵀ(Σ₁ + Σ₂)g (first-order propagation; centres of different
markers and images are independent); the angle's variance is the sum over the two
images.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .correction import load_correction
from .errors import MarkerError, VisionTorsionError
from .markers import is_frame
from .pair import PairMeasurement, measure_pair, select_pair
from .settings import MeasureSettings

__all__ = [
    "AngleResult",
    "line_direction_deg",
    "paper_angle_deg",
    "pair_angle",
    "sequence_angles",
    "rotation_angle",
]


@dataclass(frozen=True)
class AngleResult:
    """A rotation angle with its standard uncertainty.

    Attributes
    ----------
    angle_deg : float
        Rotation of the current image against the reference, degrees,
        counter-clockwise as displayed.
    angle_std_deg : float
        Standard uncertainty (1σ) in degrees.
    swapped : bool
        True when the current image's markers were matched crosswise to the reference's.
    """

    angle_deg: float
    angle_std_deg: float
    swapped: bool = False


def line_direction_deg(p1, p2) -> float:
    """Direction of the vector p1 → p2 in degrees, counter-clockwise as displayed.

    Examples
    --------
    >>> line_direction_deg((0, 0), (1, 0)), line_direction_deg((0, 0), (0, -1))
    (0.0, 90.0)
    """
    return float(np.degrees(np.arctan2(-(p2[1] - p1[1]), p2[0] - p1[0])))


def paper_angle_deg(reference_points, current_points) -> float:
    """The paper's formula θ = arctan(k₂) - arctan(k₁) from line slopes, in degrees.

    Slopes are taken in the displayed sense (y up), k = -(y₂ - y₁)/(x₂ - x₁). Kept
    for comparison only: it fails for vertical lines and cannot exceed ±90°.

    Raises
    ------
    ZeroDivisionError
        A line is vertical (its slope is undefined).
    """
    (x1, y1), (x2, y2) = reference_points
    (x3, y3), (x4, y4) = current_points
    k1 = -(y2 - y1) / (x2 - x1)
    k2 = -(y4 - y3) / (x4 - x3)
    return float(np.degrees(np.arctan(k2) - np.arctan(k1)))


def _direction_and_var(a, b):
    vx, vy = b.x_px - a.x_px, b.y_px - a.y_px
    n2 = vx * vx + vy * vy
    if not n2 > 0:
        raise MarkerError("the two markers coincide")
    g = np.array([vy, -vx]) / n2
    var = float(g @ (a.cov + b.cov) @ g)
    return float(np.arctan2(-vy, vx)), var


def _wrap(x, period):
    return (x + period / 2) % period - period / 2


def _distinct_radii(p: PairMeasurement) -> float:
    """Signed radius difference second - first when clearly significant, else 0."""
    a, b = p.first, p.second
    dr = b.radius_px - a.radius_px
    sd = np.hypot(np.nan_to_num(a.radius_std_px, nan=np.inf), np.nan_to_num(b.radius_std_px, nan=np.inf))
    return dr if abs(dr) > max(0.5, 10 * sd) else 0.0


def pair_angle(
    reference: PairMeasurement, current: PairMeasurement, *, near_deg: float = 0.0, correction=None
) -> AngleResult:
    """Rotation of `current` against `reference`, the candidate nearest `near_deg`.

    Parameters
    ----------
    reference, current : PairMeasurement
        The target found in the reference and in the current image.
    near_deg : float
        Predicted angle (deg): the previous angle of a sequence, 0 for one image.
    correction : PlaneCorrection, optional
        Plane/lens correction (:mod:`vision_torsion.calibration`) applied to both
        pairs first, so the angle is the disk's rotation rather than the image's;
        the centre covariances are propagated through it.

    Returns
    -------
    AngleResult
    """
    if correction is not None:
        reference, current = correction.apply_pair(reference), correction.apply_pair(current)
    phi_ref, var_ref = _direction_and_var(reference.first, reference.second)
    dr_ref, dr_cur = _distinct_radii(reference), _distinct_radii(current)
    phi_cur, var_cur = _direction_and_var(current.first, current.second)
    raw = np.degrees(phi_cur - phi_ref)
    if dr_ref and dr_cur:
        # identity from the radii: flip the current line if its order disagrees
        swapped = np.sign(dr_ref) != np.sign(dr_cur)
        raw += 180.0 * swapped
        angle = near_deg + _wrap(raw - near_deg, 360.0)
    else:
        angle = near_deg + _wrap(raw - near_deg, 180.0)
        swapped = bool(round((angle - raw) / 180.0) % 2)
    return AngleResult(
        angle_deg=float(angle),
        angle_std_deg=float(np.degrees(np.sqrt(var_ref + var_cur))),
        swapped=bool(swapped),
    )


def sequence_angles(reference: PairMeasurement, pairs, *, start_deg: float = 0.0, correction=None) -> list:
    """Angles of a sequence of images against a reference, identity tracked and unwrapped.

    Parameters
    ----------
    reference : PairMeasurement
        The reference image's target.
    pairs : sequence of PairMeasurement or None
        The images in order; None marks an image that failed (skipped, gives None).
    start_deg : float
        Predicted angle of the first image.
    correction : PlaneCorrection, optional
        Plane/lens correction applied to every pair (see :func:`pair_angle`).

    Returns
    -------
    list of AngleResult or None
        One entry per input, continuous across the sequence (angles may pass ±180°).
    """
    out = []
    near = float(start_deg)
    for p in pairs:
        if p is None:
            out.append(None)
            continue
        res = pair_angle(reference, p, near_deg=near, correction=correction)
        near = res.angle_deg
        out.append(res)
    return out


def _as_pair(obj, settings, name) -> PairMeasurement:
    if isinstance(obj, PairMeasurement):
        return obj
    if is_frame(obj):  # a find_markers table
        return select_pair(obj, pair=settings.pair, name=name)
    return measure_pair(obj, settings=settings, name=name)


def rotation_angle(
    reference, current, *, settings: MeasureSettings | None = None, near_deg: float = 0.0, correction=None
) -> AngleResult:
    """Rotation of the torque disk between a reference and a current image.

    Parameters
    ----------
    reference, current : path, GreyImage, array_like, marker table or PairMeasurement
        Images (found and fitted with `settings`), tables from
        :func:`~vision_torsion.markers.find_markers`, or already selected pairs.
    settings : MeasureSettings, optional
        How markers are found, which pair is the target, and the plane/lens
        correction file (``settings.correction``), applied as `correction` is.
    near_deg : float
        Predicted angle (deg); with two equal markers the answer is the candidate
        within ±90° of it.
    correction : PlaneCorrection or path, optional
        Plane/lens correction applied to both pairs (see :func:`pair_angle`); give it
        here or in `settings`, not both.

    Returns
    -------
    AngleResult
        Angle in degrees, counter-clockwise as displayed, with its standard uncertainty.

    Raises
    ------
    ImageReadError, MarkerError
        An image cannot be read or its target found.
    CalibrationError
        The correction file cannot be read.
    VisionTorsionError
        A correction given both as `correction` and in `settings` (reason
        ``conflicting_options``).

    Examples
    --------
    >>> from vision_torsion.synthetic import Scene, render
    >>> scene = Scene()
    >>> ref, cur = render(scene, 0.0, seed=1), render(scene, 12.5, seed=2)
    >>> res = rotation_angle(ref.image, cur.image)
    >>> bool(abs(res.angle_deg - 12.5) < 0.005), bool(res.angle_std_deg < 0.002)
    (True, True)
    """
    settings = settings or MeasureSettings()
    if correction is not None and settings.correction is not None:
        raise VisionTorsionError("give the plane correction either as correction= or in settings.correction, "
                                 "not both", reason="conflicting_options")
    correction = load_correction(settings.correction if correction is None else correction)
    ref = _as_pair(reference, settings, "reference")
    cur = _as_pair(current, settings, "current")
    return pair_angle(ref, cur, near_deg=near_deg, correction=correction)
