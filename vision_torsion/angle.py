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
the line by 180°, so an image gives two candidate angles, θ and θ + 180°. The angle
is the candidate nearest a predicted angle: 0° for a single image, the previous
angle in a sequence (``order="sequence"``), the reference (``order="independent"``:
the smallest rotation from it), or a given prediction (a check against reference
angles). In a sequence the choice is only as good as the assumption that the disk
turned less than 90° since the previous image; when the nearer candidate is more
than ``max_step_deg`` (default :data:`MAX_STEP_DEG`, 30°) from the previous angle the
image is flagged ambiguous (:attr:`AngleResult.ambiguous` gives the reason and both
candidates) rather than guessed, and tracking continues from the last certain
angle. A wrong (swapped) answer then needs a true turn of more than 180° - 30° =
150° between consecutive images. When the two markers differ in radius by clearly
more than their uncertainty, identity follows the radius, is certain at any angle,
and any rotation below 180° between consecutive images is tracked: the target to
use when images are not taken in small steps.

Uncertainty. With centre covariances Σ₁, Σ₂ and g = (v_y, -v_x)/|v|², the variance of
a line's direction is gᵀ(Σ₁ + Σ₂)g (first-order propagation; centres of different
markers and images are independent); the angle's variance is the sum over the two
images.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .correction import load_correction
from .errors import MarkerError, VisionTorsionError
from .markers import is_frame
from .pair import PairMeasurement, measure_pair, select_pair
from .settings import MeasureSettings

__all__ = [
    "AngleResult",
    "MAX_STEP_DEG",
    "ORDERS",
    "line_direction_deg",
    "paper_angle_deg",
    "pair_angle",
    "sequence_angles",
    "rotation_angle",
]


#: Largest turn (deg) between consecutive images of a sequence with two equal markers
#: that counts as certain: beyond it the image is flagged ambiguous. A swapped pair
#: passes only after a true turn of more than 180° minus this.
MAX_STEP_DEG = 30.0
#: How images of a folder relate: ``sequence`` (taken in small steps, tracked and
#: unwrapped) or ``independent`` (each the smallest rotation from the reference).
ORDERS = ("sequence", "independent")


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
    ambiguous : str
        Empty when identity is certain (within the limits of the order used);
        otherwise why it is not, with both candidate angles. An ambiguous result's
        angle is a guess and must not be used as a measurement.
    """

    angle_deg: float
    angle_std_deg: float
    swapped: bool = False
    ambiguous: str = ""


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
    # the direction's gradient g = (vy, -vx)/|v|² through the summed centre covariances,
    # in floats: a session computes this for every image, and 2x2 numpy arrays cost 20x more
    gx, gy = vy / n2, -vx / n2
    var = (gx * gx * (a.x_std_px**2 + b.x_std_px**2) + 2 * gx * gy * (a.xy_cov_px2 + b.xy_cov_px2)
           + gy * gy * (a.y_std_px**2 + b.y_std_px**2))
    return math.atan2(-vy, vx), float(var)


def _wrap(x, period):
    return (x + period / 2) % period - period / 2


def _distinct_radii(p: PairMeasurement) -> float:
    """Signed radius difference second - first when clearly significant, else 0."""
    a, b = p.first, p.second
    dr = b.radius_px - a.radius_px
    sd = math.hypot(a.radius_std_px, b.radius_std_px)
    if math.isnan(sd):  # a radius without its std is never clearly distinct
        return 0.0
    return dr if abs(dr) > max(0.5, 10 * sd) else 0.0


def pair_angle(
    reference: PairMeasurement, current: PairMeasurement, *, near_deg: float = 0.0, correction=None,
    max_step_deg: float | None = None,
) -> AngleResult:
    """Rotation of `current` against `reference`, the candidate nearest `near_deg`.

    Parameters
    ----------
    reference, current : PairMeasurement
        The target found in the reference and in the current image.
    near_deg : float
        Predicted angle (deg): the previous angle of a sequence, 0 for one image.
    max_step_deg : float, optional
        With two equal markers, flag the result ambiguous when the chosen candidate
        is more than this (deg) from `near_deg`; None never flags.
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
    ambiguous = ""
    if dr_ref and dr_cur:
        # identity from the radii: flip the current line if its order disagrees
        swapped = np.sign(dr_ref) != np.sign(dr_cur)
        raw += 180.0 * swapped
        angle = near_deg + _wrap(raw - near_deg, 360.0)
    else:
        angle = near_deg + _wrap(raw - near_deg, 180.0)
        swapped = bool(round((angle - raw) / 180.0) % 2)
        step = abs(angle - near_deg)
        if max_step_deg is not None and step > max_step_deg:
            other = angle - 180.0 if angle > near_deg else angle + 180.0
            ambiguous = (
                f"ambiguous marker identity: with two equal markers the image is at {angle:.3f}° or "
                f"{other:.3f}°, and the nearer is {step:.1f}° from the predicted {near_deg:.3f}° "
                f"(more than the {max_step_deg:g}° limit); measure independent rotations with "
                f"order 'independent', or use a target with two markers of different radii"
            )
    return AngleResult(
        angle_deg=float(angle),
        angle_std_deg=float(np.degrees(np.sqrt(var_ref + var_cur))),
        swapped=bool(swapped),
        ambiguous=ambiguous,
    )


def sequence_angles(reference: PairMeasurement, pairs, *, start_deg: float = 0.0, correction=None,
                    order: str = "sequence", max_step_deg: float | None = MAX_STEP_DEG,
                    predictions=None) -> list:
    """Angles of images against a reference, marker identity resolved.

    Parameters
    ----------
    reference : PairMeasurement
        The reference image's target.
    pairs : sequence of PairMeasurement or None
        The images in order; None marks an image that failed (skipped, gives None).
    start_deg : float
        Predicted angle of the first image (``sequence``).
    correction : PlaneCorrection, optional
        Plane/lens correction applied to every pair (see :func:`pair_angle`).
    order : {"sequence", "independent"}
        ``sequence``: images taken in small steps; each angle is the candidate
        nearest the previous certain angle, and the sequence is unwrapped; with two
        equal markers, an image more than `max_step_deg` from it is flagged
        ambiguous. ``independent``: each image is the smallest rotation from the
        reference (identity certain only within ±90°; with markers of different
        radii, within ±180°).
    max_step_deg : float or None
        The ``sequence`` limit (deg), :data:`MAX_STEP_DEG` by default; None never flags.
    predictions : sequence of float, optional
        A predicted angle (deg) per image, e.g. a check's reference angles relative to
        its reference image: each angle is the candidate nearest its prediction,
        which settles identity (`order` and `max_step_deg` are then unused).

    Returns
    -------
    list of AngleResult or None
        One entry per input (angles may pass ±180° in a sequence). Check
        :attr:`AngleResult.ambiguous` before using an angle.

    Raises
    ------
    ValueError
        Unknown `order`, or `predictions` of the wrong length.
    """
    if order not in ORDERS:
        raise ValueError(f"order must be one of {ORDERS}, got {order!r}")
    if predictions is not None and len(predictions) != len(pairs):
        raise ValueError(f"{len(predictions)} predictions for {len(pairs)} images")
    out = []
    near = float(start_deg)
    for k, p in enumerate(pairs):
        if p is None:
            out.append(None)
            continue
        if predictions is not None:
            res = pair_angle(reference, p, near_deg=float(predictions[k]), correction=correction)
        elif order == "independent":
            res = pair_angle(reference, p, near_deg=0.0, correction=correction)
        else:
            res = pair_angle(reference, p, near_deg=near, correction=correction, max_step_deg=max_step_deg)
            if not res.ambiguous:
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
