"""Plane self-calibration from the rotation itself: ``calibrate_plane``.

Model
-----
Over a rotation sequence the two marker centres move rigidly on the disk plane. In a
disk frame with the rotation centre at the origin, marker j of image i is at
``D_ij = R(θ_i) a_j`` (R a rotation, a_j the marker's fixed offset from the centre).
The camera sees the plane through a homography G and, optionally, radial distortion
(k1 about a centre c with focal length f, as in
:class:`~vision_torsion.correction.PlaneCorrection`)::

    p_ij = distort(G · D_ij) + noise,   noise ~ N(0, Σ_ij)

with Σ_ij the measured centre covariance. Unknowns: G (8), a_2 (2), θ_1..θ_{n-1}
and optionally k1. The gauge (the similarity of the disk plane, which does not change
any angle) is fixed by the origin at the rotation centre, a_1 = (1, 0) (scale and
turn) and θ_0 = 0 for the reference image. The weighted residuals
L_ij⁻¹ (p_ij - model) with Σ_ij = L Lᵀ are minimised by
:func:`scipy.optimize.least_squares` in coordinates normalised by the centres'
centroid and spread (so the fit stays well conditioned at large pixel coordinates).
The correction saved is G⁻¹ (after undistortion), followed by the similarity that
makes it look like the identity at the rotation centre
(:func:`~vision_torsion.calibration.anchoring.normalised`).

Start: both markers lie on one circle (a diametric target), imaged as an ellipse.
An ellipse fit to all centres gives the affine solution (ellipse centre = rotation
centre, axes = the circle's image), the start angles and the start a_2; the fit then
adds the projective part. The fit itself does not assume equal radii.

Why it is determined, and the degeneracies
------------------------------------------
The image of the circle of motion (5 numbers) gives the rectification up to the
3-parameter group of projective maps keeping that conic; the lines joining the two
markers of each image all pass through one point, the image of the rotation centre
(for a diametric target; in general they envelope the image of a concentric
circle), which removes the remaining two non-similarity parameters (the line at
infinity is the polar of the centre with respect to the circle). Degenerate or
weak cases:

- a short sweep: two short opposite arcs do not fix an ellipse, and nearly
  parallel marker lines do not fix their common point. The fit is refused below
  :data:`MIN_SWEEP_DEG` (see below);
- k1 with the distortion centre near the rotation centre: radial distortion then
  only rescales the circle, which the homography already absorbs, so k1 is not
  fitted by default (``fit_k1=False``); give a known k1 instead (from a target
  calibration) or fit it only when the rotation centre is well away from the
  distortion centre;
- the focal length f of the distortion model only scales k1 (k1/f² matters).

Sweep needed. With the standard scene's noise (centre σ ≈ 0.005 px, markers 300 px
from the centre) and 3° tilt, the simulated error of the corrected rotation over the
swept range stays below 0.001° RMS when the disk is turned by at least about
40° in total; below that the projective part is not determined and the "corrected"
angles can be worse than the raw ones. :data:`MIN_SWEEP_DEG` = 40° is therefore the
threshold; the benchmark ``benchmarks/bench_calibration.py`` sweeps ±70°.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from scipy.optimize import least_squares

from ..angle import sequence_angles
from ..batch import measure_each
from ..circlefit import fit_ellipse
from ..correction import PlaneCorrection
from ..errors import CalibrationError, FitError
from ..pair import PairMeasurement, measure_pair
from ..settings import MeasureSettings
from .anchoring import normalised

__all__ = ["calibrate_plane", "MIN_SWEEP_DEG", "MIN_IMAGES"]

logger = logging.getLogger(__name__)

#: Smallest total rotation (deg, max - min of the sweep) accepted for self-calibration.
MIN_SWEEP_DEG = 40.0
#: Fewest images (reference included): 4n observations for 10 + n unknowns, with margin.
MIN_IMAGES = 6


def _rotation(angle_rad):
    """2x2 rotation matrix of an angle (rad), or a stack of them for an array of angles."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    if np.ndim(angle_rad) == 0:
        return np.array([[c, -s], [s, c]])
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _as_pairs(data, settings, progress):
    """The marker pairs of `data` (pairs pass through, images are measured); an image
    whose target is not found is left out, unless it is the reference."""
    settings = settings or MeasureSettings()

    def measure(item):
        index, value = item
        if isinstance(value, PairMeasurement):
            return value
        is_path = isinstance(value, (str, bytes)) or hasattr(value, "__fspath__")
        return measure_pair(value, settings=settings, name=str(value) if is_path else f"image {index}")

    done = measure_each(measure, list(enumerate(data)), progress=progress)
    if done and not done[0].ok:
        raise CalibrationError(f"the reference (first) image is unusable: {done[0].message}")
    for d in done:
        if not d.ok:
            logger.warning("left out of the calibration: %s", d.message)
    return [d.value for d in done if d.ok]


def _centres_and_whitening(pairs, swapped):
    """Marker centres and their whitening matrices, marker identity tracked.

    Returns
    -------
    centres_px : ndarray (n, 2, 2)
        [image, marker, (x, y)] in px.
    whitening : ndarray (n, 2, 2, 2)
        L⁻¹ with Σ = L·Lᵀ the centre covariance, per image and marker.
    """
    centres_px = np.empty((len(pairs), 2, 2))
    whitening = np.empty((len(pairs), 2, 2, 2))
    for i, (pair, swap) in enumerate(zip(pairs, swapped)):
        markers = (pair.second, pair.first) if swap else (pair.first, pair.second)
        for j, marker in enumerate(markers):
            centres_px[i, j] = marker.x_px, marker.y_px
            cov = marker.cov
            if not np.all(np.isfinite(cov)) or np.linalg.det(cov) <= 0:
                raise CalibrationError(f"image {i}: marker {j + 1} has no usable centre covariance")
            whitening[i, j] = np.linalg.inv(np.linalg.cholesky(cov))
    return centres_px, whitening


def _distort(points_px, k1, centre_px, focal_length_px):
    """Radial distortion of undistorted points (px): c + (u − c)(1 + k1·|u − c|²/f²)."""
    if k1 == 0.0:
        return points_px
    offset = points_px - centre_px
    return centre_px + offset * (1.0 + k1 * np.sum(offset * offset, axis=-1, keepdims=True) / focal_length_px**2)


def _affine_start(centres_px):
    """Ellipse through all centres → (its centre, the matrix mapping the unit circle onto it)."""
    try:
        e = fit_ellipse(centres_px[..., 0].ravel(), centres_px[..., 1].ravel(), clip=np.inf)
    except FitError as exc:
        raise CalibrationError(f"no ellipse fits the marker centres ({exc})") from None
    phi = math.radians(e.angle_deg)
    circle_to_ellipse = np.array([[e.a_px * math.cos(phi), e.b_px * math.sin(phi)],
                                  [-e.a_px * math.sin(phi), e.b_px * math.cos(phi)]])
    return np.array([e.x_px, e.y_px]), circle_to_ellipse


def calibrate_plane(
    data,
    *,
    settings: MeasureSettings | None = None,
    fit_k1: bool = False,
    k1: float = 0.0,
    distortion_centre=None,
    focal_length_px: float | None = None,
    min_sweep_deg: float = MIN_SWEEP_DEG,
    progress: bool = False,
) -> PlaneCorrection:
    """Self-calibrate the disk plane (and optionally k1) from a rotation sequence.

    Parameters
    ----------
    data : sequence of PairMeasurement, or of images (paths, arrays)
        The sequence in the order taken, the reference image first. Images are
        measured with `settings`; an image whose target is not found is left out
        (logged). Marker identity is tracked along the sequence as ``measure`` does.
    settings : MeasureSettings, optional
        How markers are found when images are given.
    fit_k1 : bool
        Also fit the radial distortion coefficient (weakly determined, see Notes).
    k1 : float
        Known (or starting) radial distortion coefficient.
    distortion_centre : (float, float), optional
        Distortion centre (x, y) in px; the image centre ((w-1)/2, (h-1)/2) of the
        first image by default when images are given.
    focal_length_px : float, optional
        f of the distortion model; max(w, h) of the first image by default.
    min_sweep_deg : float
        Smallest accepted total rotation of the sequence (deg).
    progress : bool
        Show a progress bar while images are measured.

    Returns
    -------
    PlaneCorrection
        Image → disk plane, normalised to look like the identity at the rotation
        centre. ``info`` holds the fit's figures: images used, sweep (deg), weighted
        residual RMS, reduced χ², the fitted rotation angles (deg, CCW as displayed)
        with their standard uncertainties, and the rotation centre (image px).

    Raises
    ------
    CalibrationError
        Fewer than :data:`MIN_IMAGES` usable images; a sweep shorter than
        `min_sweep_deg` (the message says how many degrees are needed); k1 without a
        distortion centre or focal length; no ellipse through the centres; the fit
        does not converge.

    Notes
    -----
    The model, its gauge and its degeneracies are described in the module
    docstring (:mod:`vision_torsion.calibration.selfcal`).
    """
    data = list(data)
    centre, f = distortion_centre, focal_length_px
    if data and not isinstance(data[0], PairMeasurement) and (centre is None or f is None):
        from ..images import as_grey_array

        shape = np.shape(as_grey_array(data[0]))
        centre = centre if centre is not None else ((shape[1] - 1) / 2.0, (shape[0] - 1) / 2.0)
        f = f if f is not None else float(max(shape[:2]))
    if (fit_k1 or k1) and (centre is None or f is None):
        raise CalibrationError("k1 needs distortion_centre and focal_length_px when marker pairs are given")
    pairs = _as_pairs(data, settings, progress)
    if len(pairs) < MIN_IMAGES:
        raise CalibrationError(
            f"self-calibration needs at least {MIN_IMAGES} usable images (reference included), got {len(pairs)}"
        )
    # a sweep is taken in order, in steps under 90° (as before): tracked without the
    # 30° ambiguity limit of measure's sequence order
    angles = sequence_angles(pairs[0], pairs[1:], max_step_deg=None)
    raw_deg = np.array([0.0] + [a.angle_deg for a in angles])
    sweep = float(raw_deg.max() - raw_deg.min())
    if sweep < min_sweep_deg:
        raise CalibrationError(
            f"the rotation sweep spans {sweep:.1f}°, too short to fit the ellipse of the markers' motion: "
            f"at least {min_sweep_deg:g}° is needed (turn the disk further, e.g. ±{min_sweep_deg / 2:g}°)"
        )
    swapped = [False] + [a.swapped for a in angles]
    centres_px, whitening = _centres_and_whitening(pairs, swapped)
    distortion_centre_px = None if centre is None else np.asarray(centre, dtype=np.float64)
    # start: undistort with the known k1, then the affine solution from the ellipse
    undistorted_px = centres_px if not k1 else np.stack(
        PlaneCorrection(np.eye(3), k1=k1, centre=centre, focal_length_px=f).undistort(centres_px[..., 0],
                                                                                     centres_px[..., 1]), -1
    )
    # fit in coordinates normalised by the centres' centroid and RMS spread (px)
    mean_px = undistorted_px.reshape(-1, 2).mean(axis=0)
    spread_px = float(np.sqrt(np.mean(np.sum((undistorted_px.reshape(-1, 2) - mean_px) ** 2, axis=-1))))
    ellipse_centre_px, circle_to_ellipse = _affine_start(undistorted_px)
    on_unit_circle = np.einsum("ab,ijb->ija", np.linalg.inv(circle_to_ellipse), undistorted_px - ellipse_centre_px)
    phase = np.unwrap(np.arctan2(on_unit_circle[:, 0, 1], on_unit_circle[:, 0, 0]))
    start_angles = phase - phase[0]
    plane_to_image_start = np.eye(3)  # disk frame -> normalised image, homogeneous
    plane_to_image_start[:2, :2] = circle_to_ellipse @ _rotation(phase[0]) / spread_px
    plane_to_image_start[:2, 2] = (ellipse_centre_px - mean_px) / spread_px
    second_marker_start = np.mean(np.einsum("iab,ib->ia", np.swapaxes(_rotation(phase), -1, -2),
                                            on_unit_circle[:, 1]), axis=0)
    n_images = len(pairs)

    def unpack(params):
        """(plane_to_image, second marker's offset a_2, angles θ (rad), k1) from the fit's parameters."""
        plane_to_image = np.append(params[:8], 1.0).reshape(3, 3)
        angles_rad = np.concatenate([[0.0], params[10 : 9 + n_images]])
        return plane_to_image, params[8:10], angles_rad, (params[9 + n_images] if fit_k1 else k1)

    def residuals(params):
        plane_to_image, second_marker, angles_rad, k1_now = unpack(params)
        offsets = np.array([[1.0, 0.0], second_marker])  # a_1 = (1, 0) fixes the gauge
        on_disk = np.einsum("iab,jb->ija", _rotation(angles_rad), offsets)
        projected = np.einsum("ab,ijb->ija", plane_to_image,
                              np.concatenate([on_disk, np.ones(on_disk.shape[:-1] + (1,))], -1))
        model_px = mean_px + spread_px * projected[..., :2] / projected[..., 2:]
        misfit_px = centres_px - _distort(model_px, k1_now, distortion_centre_px, f)
        return np.einsum("ijab,ijb->ija", whitening, misfit_px).ravel()

    start = np.concatenate([plane_to_image_start.ravel()[:8], second_marker_start, start_angles[1:]]
                           + ([[k1]] if fit_k1 else []))
    try:
        fit = least_squares(residuals, start, method="lm", x_scale="jac", xtol=1e-14, ftol=1e-14, gtol=1e-14,
                            max_nfev=2000)
    except (ValueError, np.linalg.LinAlgError) as exc:  # pragma: no cover - defensive
        raise CalibrationError(f"the self-calibration fit failed ({exc})") from None
    if not fit.success or not np.all(np.isfinite(fit.x)):
        raise CalibrationError(f"the self-calibration fit did not converge ({fit.message})")
    plane_to_image, _, angles_rad, k1_fit = unpack(fit.x)
    dof = fit.fun.size - fit.x.size
    chi2 = float(fit.fun @ fit.fun / max(dof, 1))
    try:
        param_cov = np.linalg.inv(fit.jac.T @ fit.jac) * max(1.0, chi2)
        angles_std_deg = np.degrees(np.sqrt(np.concatenate([[0.0], np.diag(param_cov)[10 : 9 + n_images]])))
    except np.linalg.LinAlgError:
        raise CalibrationError("the self-calibration is degenerate (singular normal matrix)") from None
    normalise = np.array([[1 / spread_px, 0, -mean_px[0] / spread_px], [0, 1 / spread_px, -mean_px[1] / spread_px],
                          [0, 0, 1.0]])
    image_to_disk = np.linalg.inv(plane_to_image) @ normalise  # undistorted image -> disk frame
    rotation_centre_px = _distort(mean_px + spread_px * plane_to_image[:2, 2] / plane_to_image[2, 2], k1_fit,
                                  distortion_centre_px, f)
    # The disk frame turns with R(θ) in image axes (y down): CCW as displayed is -θ.
    info = {
        "n_images": n_images,
        "sweep_deg": sweep,
        "residual_rms": float(np.sqrt(np.mean(fit.fun**2))),
        "reduced_chi2": chi2,
        "rotation_centre_px": [float(v) for v in rotation_centre_px],
        "angles_deg": [float(v) for v in -np.degrees(angles_rad)],
        "angles_std_deg": [float(v) for v in angles_std_deg],
    }
    if fit_k1:
        info["k1_std"] = float(np.sqrt(param_cov[9 + n_images, 9 + n_images]))
    correction = PlaneCorrection(
        image_to_disk,
        k1=float(k1_fit),
        centre=None if distortion_centre_px is None else tuple(distortion_centre_px),
        focal_length_px=f if distortion_centre_px is not None else None,
        method="self-calibration",
        info=info,
    )
    return normalised(correction, rotation_centre_px)
