"""Plane self-calibration from the rotation itself: ``calibrate_plane``.

Model
-----
Over a rotation sequence the two marker centres move rigidly on the disk plane. In a
disk frame with the rotation centre at the origin, marker j of image i is at
``D_ij = R(θ_i) a_j`` (R a rotation, a_j the marker's fixed offset from the centre).
The camera sees the plane through a homography G and, optionally, radial distortion
(k1 about a centre c with focal length f, as in
:class:`~vision_torsion.calibration.correction.PlaneCorrection`)::

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
(:func:`~vision_torsion.calibration.correction.normalised`).

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
from tqdm.auto import tqdm

from ..angle import sequence_angles
from ..circlefit import fit_ellipse
from ..errors import CalibrationError, FitError, VisionTorsionError
from ..pair import PairMeasurement, measure_pair
from ..settings import MeasureSettings
from .correction import PlaneCorrection, normalised

__all__ = ["calibrate_plane", "MIN_SWEEP_DEG", "MIN_IMAGES"]

logger = logging.getLogger(__name__)

#: Smallest total rotation (deg, max - min of the sweep) accepted for self-calibration.
MIN_SWEEP_DEG = 40.0
#: Fewest images (reference included): 4n observations for 10 + n unknowns, with margin.
MIN_IMAGES = 6


def _rot(t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s], [s, c]]) if np.ndim(t) == 0 else np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _as_pairs(data, settings, progress):
    settings = settings or MeasureSettings()
    pairs = []
    for i, item in enumerate(tqdm(data, desc="measuring", unit="image", disable=not progress)):
        if isinstance(item, PairMeasurement):
            pairs.append(item)
            continue
        name = str(item) if isinstance(item, (str, bytes)) or hasattr(item, "__fspath__") else f"image {i}"
        try:
            pairs.append(measure_pair(item, settings=settings, name=name))
        except VisionTorsionError as exc:
            if i == 0:
                raise CalibrationError(f"the reference (first) image is unusable: {exc}") from None
            logger.warning("left out of the calibration: %s", exc)
    return pairs


def _centres_and_weights(pairs, swapped):
    """Centres (n, 2, 2) as [image, marker, xy] with marker identity tracked, and whitening (n, 2, 2, 2)."""
    P = np.empty((len(pairs), 2, 2))
    W = np.empty((len(pairs), 2, 2, 2))
    for i, (p, sw) in enumerate(zip(pairs, swapped)):
        ms = (p.second, p.first) if sw else (p.first, p.second)
        for j, m in enumerate(ms):
            P[i, j] = m.x_px, m.y_px
            cov = m.cov
            if not np.all(np.isfinite(cov)) or np.linalg.det(cov) <= 0:
                raise CalibrationError(f"image {i}: marker {j + 1} has no usable centre covariance")
            W[i, j] = np.linalg.inv(np.linalg.cholesky(cov))
    return P, W


def _distort(u, k1, c, f):
    if k1 == 0.0:
        return u
    d = u - c
    return c + d * (1.0 + k1 * np.sum(d * d, axis=-1, keepdims=True) / f**2)


def _affine_start(P):
    """Ellipse through all centres → (centre, M mapping the unit circle onto it)."""
    try:
        e = fit_ellipse(P[..., 0].ravel(), P[..., 1].ravel(), clip=np.inf)
    except FitError as exc:
        raise CalibrationError(f"no ellipse fits the marker centres ({exc})") from None
    phi = math.radians(e.angle_deg)
    M = np.array([[e.a * math.cos(phi), e.b * math.sin(phi)], [-e.a * math.sin(phi), e.b * math.cos(phi)]])
    return np.array([e.x, e.y]), M


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
    angles = sequence_angles(pairs[0], pairs[1:])
    raw = np.array([0.0] + [a.angle_deg for a in angles])
    sweep = float(raw.max() - raw.min())
    if sweep < min_sweep_deg:
        raise CalibrationError(
            f"the rotation sweep spans {sweep:.1f}°, too short to fit the ellipse of the markers' motion: "
            f"at least {min_sweep_deg:g}° is needed (turn the disk further, e.g. ±{min_sweep_deg / 2:g}°)"
        )
    swapped = [False] + [a.swapped for a in angles]
    P, W = _centres_and_weights(pairs, swapped)
    c_arr = None if centre is None else np.asarray(centre, dtype=np.float64)
    # start: undistort with the known k1, then the affine solution from the ellipse
    P0 = P if not k1 else np.stack(
        PlaneCorrection(np.eye(3), k1=k1, centre=centre, focal_length_px=f).undistort(P[..., 0], P[..., 1]), -1
    )
    m = P0.reshape(-1, 2).mean(axis=0)
    s = float(np.sqrt(np.mean(np.sum((P0.reshape(-1, 2) - m) ** 2, axis=-1))))
    ce, M = _affine_start(P0)
    q = np.einsum("ab,ijb->ija", np.linalg.inv(M), P0 - ce)
    psi = np.unwrap(np.arctan2(q[:, 0, 1], q[:, 0, 0]))
    theta0 = psi - psi[0]
    A = M @ _rot(psi[0]) / s
    G0 = np.eye(3)
    G0[:2, :2] = A
    G0[:2, 2] = (ce - m) / s
    a2 = np.mean(np.einsum("iab,ib->ia", np.swapaxes(_rot(psi), -1, -2), q[:, 1]), axis=0)
    n = len(pairs)

    def unpack(x):
        G = np.append(x[:8], 1.0).reshape(3, 3)
        return G, x[8:10], np.concatenate([[0.0], x[10 : 9 + n]]), (x[9 + n] if fit_k1 else k1)

    def residuals(x):
        G, a2_, th, k = unpack(x)
        a = np.array([[1.0, 0.0], a2_])
        D = np.einsum("iab,jb->ija", _rot(th), a)
        h = np.einsum("ab,ijb->ija", G, np.concatenate([D, np.ones(D.shape[:-1] + (1,))], -1))
        u = m + s * h[..., :2] / h[..., 2:]
        r = P - _distort(u, k, c_arr, f)
        return np.einsum("ijab,ijb->ija", W, r).ravel()

    x0 = np.concatenate([G0.ravel()[:8], a2, theta0[1:]] + ([[k1]] if fit_k1 else []))
    try:
        sol = least_squares(residuals, x0, method="lm", x_scale="jac", xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=2000)
    except (ValueError, np.linalg.LinAlgError) as exc:  # pragma: no cover - defensive
        raise CalibrationError(f"the self-calibration fit failed ({exc})") from None
    if not sol.success or not np.all(np.isfinite(sol.x)):
        raise CalibrationError(f"the self-calibration fit did not converge ({sol.message})")
    G, a2_fit, th, k_fit = unpack(sol.x)
    dof = sol.fun.size - sol.x.size
    chi2 = float(sol.fun @ sol.fun / max(dof, 1))
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * max(1.0, chi2)
        th_std = np.degrees(np.sqrt(np.concatenate([[0.0], np.diag(cov)[10 : 9 + n]])))
    except np.linalg.LinAlgError:
        raise CalibrationError("the self-calibration is degenerate (singular normal matrix)") from None
    Nmat = np.array([[1 / s, 0, -m[0] / s], [0, 1 / s, -m[1] / s], [0, 0, 1.0]])
    H = np.linalg.inv(G) @ Nmat  # undistorted image -> disk frame
    centre_img = _distort(m + s * G[:2, 2] / G[2, 2], k_fit, c_arr, f)
    # The disk frame turns with R(θ) in image axes (y down): CCW as displayed is -θ.
    info = {
        "n_images": n,
        "sweep_deg": sweep,
        "residual_rms": float(np.sqrt(np.mean(sol.fun**2))),
        "reduced_chi2": chi2,
        "rotation_centre_px": [float(v) for v in centre_img],
        "angles_deg": [float(v) for v in -np.degrees(th)],
        "angles_std_deg": [float(v) for v in th_std],
    }
    if fit_k1:
        info["k1_std"] = float(np.sqrt(cov[9 + n, 9 + n]))
    corr = PlaneCorrection(
        H,
        k1=float(k_fit),
        centre=None if c_arr is None else tuple(c_arr),
        focal_length_px=f if c_arr is not None else None,
        method="self-calibration",
        info=info,
    )
    return normalised(corr, centre_img)
