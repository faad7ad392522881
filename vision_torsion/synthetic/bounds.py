"""The Cramér-Rao bound of the rotation angle for a scene: the physical limit.

No unbiased estimator of a marker centre can have a smaller covariance than the
inverse of the Fisher information of the pixels about it. For a marker with
parameters β = (X, Y, r, B, F) (centre on the disk plane, radius, grey level outside
and inside) and independent Gaussian pixel noise of variance vᵢ::

    I(β) = Σᵢ (∂μᵢ/∂β)(∂μᵢ/∂β)ᵀ / vᵢ

where μᵢ is the noise-free pixel value rendered exactly as the renderer does (area
coverage, lighting, tilt, PSF blur) and vᵢ = read² + μᵢ/electrons_per_dn (shot) +
1/12 (quantisation). The centre's bound is the (X, Y) block of I⁻¹ (radius and
levels are nuisance parameters, marginalised). The angle between the reference
and the current image combines four centres (two markers, two images) through
the same first-order propagation the measurement uses, see :mod:`vision_torsion.angle`.

Derivatives are central differences of exact renders (steps of 1e-3 px and 1e-2 DN),
accurate to far better than the few per cent that matter for a bound.
"""

from __future__ import annotations

import numpy as np

from .geometry import CameraMapping, marker_centres_disk, marker_centres_image
from .render import paint_circle, reflection, scene_light
from .scene import Scene

__all__ = ["centre_covariance_bound", "angle_bound_deg", "target_angle_bound_deg"]


def _marker_patch(scene: Scene, mapping, params, box):
    import cv2

    X, Y, r, B, F = params
    x0, y0, x1, y1 = box
    sub = np.full((y1 - y0, x1 - x0), B, dtype=np.float64)
    class Shifted:
        """The scene's camera mapping with image coordinates relative to the patch."""

        is_identity = mapping.is_identity

        def to_image(self, a, b):
            xx, yy = mapping.to_image(a, b)
            return xx - x0, yy - y0

        def to_disk(self, a, b):
            return mapping.to_disk(np.asarray(a) + x0, np.asarray(b) + y0)

    if mapping.is_identity:
        paint_circle(sub, mapping, X - x0, Y - y0, r, F)
    else:
        paint_circle(sub, Shifted(), X, Y, r, F)
    light = scene_light(scene)
    if light is not None:
        sub *= light[y0:y1, x0:x1]
    s = scene.optics.blur_sigma_px
    if s > 0:
        sub = cv2.GaussianBlur(sub, (0, 0), sigmaX=s, sigmaY=s, borderType=cv2.BORDER_REFLECT)
    return sub


def centre_covariance_bound(scene: Scene, angle_deg: float = 0.0) -> np.ndarray:
    """Cramér-Rao covariance of each marker's centre on the disk plane.

    Parameters
    ----------
    scene : Scene
        The scene (noise, blur, lighting, tilt are all taken into account; JPEG is
        not, since its error is not Gaussian pixel noise).
    angle_deg : float
        Disk rotation (deg, counter-clockwise as displayed).

    Returns
    -------
    numpy.ndarray
        (n_markers, 2, 2) covariance bounds in px².
    """
    mapping = CameraMapping(scene)
    mk, nz = scene.markers, scene.noise
    out = []
    for (X, Y), radius in zip(marker_centres_disk(scene, angle_deg), mk.radii()):
        cx, cy = mapping.to_image(X, Y)
        half = radius * 1.2 + 4 * scene.optics.blur_sigma_px + 6
        x0, y0 = int(np.floor(cx - half)), int(np.floor(cy - half))
        x1, y1 = int(np.ceil(cx + half)) + 1, int(np.ceil(cy + half)) + 1
        box = (max(x0, 0), max(y0, 0), min(x1, scene.image.width), min(y1, scene.image.height))
        p0 = np.array([X, Y, radius, scene.disk.background_level, mk.level], dtype=np.float64)
        steps = np.array([1e-3, 1e-3, 1e-3, 1e-2, 1e-2])
        mu = _marker_patch(scene, mapping, p0, box)
        var = nz.read_noise_dn**2 + 1.0 / 12.0
        if nz.shot_noise:
            # a lamp's reflection adds shot noise, not signal (the bound leaves out
            # where it clips the image)
            glare = (reflection(scene, *np.mgrid[box[1]:box[3], box[0]:box[2]][::-1])
                     if scene.lighting.reflection_dn else 0.0)
            var = var + np.clip(mu + glare, 0, None) / nz.electrons_per_dn
        var = np.broadcast_to(var, mu.shape).ravel()
        J = np.empty((mu.size, 5))
        for k in range(5):
            dp = np.zeros(5)
            dp[k] = steps[k]
            J[:, k] = (
                (_marker_patch(scene, mapping, p0 + dp, box) - _marker_patch(scene, mapping, p0 - dp, box))
                / (2 * steps[k])
            ).ravel()
        fisher = (J / var[:, None]).T @ J
        out.append(np.linalg.inv(fisher)[:2, :2])
    return np.array(out)


def _line_var(centres, covs):
    v = centres[1] - centres[0]
    g = np.array([v[1], -v[0]]) / (v @ v)
    return float(g @ (covs[0] + covs[1]) @ g)


def angle_bound_deg(scene: Scene, angle_deg: float = 0.0, *, reference_deg: float = 0.0) -> float:
    """Cramér-Rao bound (1σ, degrees) of the rotation measured between two images.

    Parameters
    ----------
    scene : Scene
        The scene; its first two markers are the target.
    angle_deg : float
        Rotation of the current image (deg).
    reference_deg : float
        Rotation of the reference image (deg).

    Returns
    -------
    float
        Smallest standard deviation (deg) an unbiased measurement of the angle can
        have from these two images.

    Examples
    --------
    >>> b = angle_bound_deg(Scene())
    >>> 0.0004 < b < 0.0005
    True
    """
    total = 0.0
    for a in (reference_deg, angle_deg):
        c = marker_centres_disk(scene, a)[:2]
        total += _line_var(c, centre_covariance_bound(scene, a)[:2])
    return float(np.degrees(np.sqrt(total)))


def target_angle_bound_deg(scene: Scene, angle_deg: float = 0.0, *, reference_deg: float = 0.0) -> float:
    """Cramér-Rao bound (1σ, degrees) of the rotation from **all** the scene's markers.

    The centres' bounds (:func:`centre_covariance_bound`, both images) are combined
    through the weighted rigid fit the measurement makes
    (:func:`vision_torsion.rigid.fit_rigid`, errors in both images): each marker's
    pixels are independent of the others', so this is the bound of the angle with
    every centre, radius and grey level of both images a nuisance parameter. With
    two markers it equals :func:`angle_bound_deg`.

    Parameters
    ----------
    scene : Scene
        The scene (an N-marker target: :func:`~vision_torsion.synthetic.target_scene`).
    angle_deg, reference_deg : float
        Rotation of the current and of the reference image (deg).

    Returns
    -------
    float
        Smallest standard deviation (deg) of an unbiased angle from these two images.

    Examples
    --------
    >>> s = Scene()
    >>> bool(abs(target_angle_bound_deg(s, 10.0) / angle_bound_deg(s, 10.0) - 1) < 1e-6)
    True
    """
    from ..rigid import fit_rigid

    ref = marker_centres_image(scene, reference_deg)
    cur = marker_centres_image(scene, angle_deg)
    fit = fit_rigid(ref, _image_cov(scene, reference_deg), cur, _image_cov(scene, angle_deg), reject_sigma=np.inf)
    return float(fit.angle_std_deg)


def _image_cov(scene, angle_deg):
    """Centre bounds in image coordinates: the disk-plane bounds through the camera's Jacobian."""
    mapping = CameraMapping(scene)
    cov = centre_covariance_bound(scene, angle_deg)
    if mapping.is_identity:
        return cov
    out = np.empty_like(cov)
    for k, (X, Y) in enumerate(marker_centres_disk(scene, angle_deg)):
        h = 1e-3
        jx = (np.array(mapping.to_image(X + h, Y)) - np.array(mapping.to_image(X - h, Y))) / (2 * h)
        jy = (np.array(mapping.to_image(X, Y + h)) - np.array(mapping.to_image(X, Y - h))) / (2 * h)
        J = np.column_stack([jx, jy])
        out[k] = J @ cov[k] @ J.T
    return out
