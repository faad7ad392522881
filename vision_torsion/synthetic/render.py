"""The renderer: a camera image of the torque disk at a known rotation.

The image is formed as a camera forms it, each stage switchable in the scene:

1. reflectance of the disk face with exact area coverage at every edge (markers and
   bolt holes on the disk plane, seen through the camera's tilt and lens distortion;
   a static wire and dust specks in front), see :mod:`.coverage`;
2. illumination: a linear gradient and vignetting multiply the reflectance;
3. the optics' point-spread function, a Gaussian of σ = ``blur_sigma_px``;
4. sensor noise: Poisson shot noise in electrons (``electrons_per_dn``) and Gaussian
   read noise in DN;
5. quantisation to 8, 12 or 16 bits, and optionally JPEG compression.

Every random draw comes from ``numpy.random.default_rng(seed)``: the same scene,
angle and seed give the same image, bit for bit.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from .coverage import band_coverage, shape_coverage
from .geometry import CameraMapping, marker_centres_disk
from .scene import Scene, check_markers_in_frame

__all__ = [
    "Rendered",
    "render",
    "render_ideal",
    "bolt_hole_centres_disk",
    "dust_specks",
    "circle_distance_fn",
    "paint_circle",
    "light_field",
    "scene_light",
    "reflection",
]


@dataclass(frozen=True)
class Rendered:
    """A rendered image with its ground truth.

    Attributes
    ----------
    image : numpy.ndarray
        Grey levels indexed ``[y, x]``: uint8 for 8-bit scenes, uint16 (holding 12 or
        16 significant bits) otherwise.
    angle_deg : float
        The disk's true rotation, degrees counter-clockwise as displayed.
    centres : numpy.ndarray
        (n, 2) true marker centres (x, y) in image pixels: the projections of the
        centres on the disk plane (under tilt this is not the centre of the imaged
        ellipse).
    centres_disk : numpy.ndarray
        (n, 2) marker centres on the disk plane (px).
    jpeg_bytes : bytes or None
        The JPEG file the image was decoded from, for JPEG scenes.
    """

    image: np.ndarray
    angle_deg: float
    centres: np.ndarray
    centres_disk: np.ndarray
    jpeg_bytes: bytes | None = None


def bolt_hole_centres_disk(scene: Scene, angle_deg: float) -> np.ndarray:
    """Bolt-hole centres on the disk plane (px), evenly spaced on the bolt circle.

    The holes sit half-way between the angular positions of an even spacing starting
    at 15° from the first marker, so they never coincide with a marker position.
    """
    d = scene.distractors
    if d.bolt_holes == 0:
        return np.zeros((0, 2))
    step = 360.0 / d.bolt_holes
    phi = np.deg2rad(scene.markers.positions_deg[0] + 15.0 + step * (np.arange(d.bolt_holes) + 0.5) + angle_deg)
    cx, cy = scene.disk.center_x, scene.disk.center_y
    return np.stack([cx + d.bolt_circle_px * np.cos(phi), cy - d.bolt_circle_px * np.sin(phi)], axis=-1)


def dust_specks(scene: Scene) -> np.ndarray:
    """Dust specks in front of the disk: (n, 3) rows of x, y, radius (px); fixed by ``dust_seed``."""
    d = scene.distractors
    rng = np.random.default_rng(d.dust_seed)
    xs = rng.uniform(0, scene.image.width - 1, d.dust)
    ys = rng.uniform(0, scene.image.height - 1, d.dust)
    rs = d.dust_radius_px * rng.uniform(0.6, 1.4, d.dust)
    return np.stack([xs, ys, rs], axis=-1)


def circle_distance_fn(mapping: CameraMapping, cx: float, cy: float, r: float):
    """The signed distance of image points from a circle given on the disk plane.

    Parameters
    ----------
    mapping : CameraMapping
        Disk plane -> image.
    cx, cy, r : float
        Centre and radius of the circle on the disk plane (disk units).

    Returns
    -------
    callable
        ``fn(x, y) -> (d, nx, ny)`` for image coordinates (px, origin at the centre
        of the top-left pixel, y down): the signed distance d (image px, negative
        inside; through the local scale of the mapping when it is not the identity)
        and the outward unit normal (nx, ny).
    """
    if mapping.is_identity:

        def fn(x, y):
            dx, dy = x - cx, y - cy
            rho = np.hypot(dx, dy)
            safe = np.where(rho > 0, rho, 1.0)
            return rho - r, dx / safe, dy / safe

        return fn

    def plane_sd(x, y):
        X, Y = mapping.to_disk(x, y)
        return np.hypot(X - cx, Y - cy) - r

    def fn(x, y):
        eps = 1e-3
        s = plane_sd(x, y)
        gx = (plane_sd(x + eps, y) - plane_sd(x - eps, y)) / (2 * eps)
        gy = (plane_sd(x, y + eps) - plane_sd(x, y - eps)) / (2 * eps)
        g = np.hypot(gx, gy)
        return s / g, gx / g, gy / g

    return fn


def paint_circle(canvas, mapping, cx, cy, r, level, *, n_sub=8):
    """Paint a disk-plane circle of grey `level` (DN) onto `canvas` in place, each
    pixel blended by the share of it the circle covers (`n_sub` x `n_sub` samples
    per pixel along the edge, :func:`~vision_torsion.synthetic.coverage.shape_coverage`).
    A circle whose image misses `canvas` paints nothing."""
    h, w = canvas.shape
    # bounding box of the circle's image, from points around its rim
    t = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    bx, by = mapping.to_image(cx + (r + 1) * np.cos(t), cy + (r + 1) * np.sin(t))
    x0 = max(int(np.floor(bx.min())) - 2, 0)
    y0 = max(int(np.floor(by.min())) - 2, 0)
    x1 = min(int(np.ceil(bx.max())) + 3, w)
    y1 = min(int(np.ceil(by.max())) + 3, h)
    if x1 <= x0 or y1 <= y0:
        return
    cov = shape_coverage(circle_distance_fn(mapping, cx, cy, r), x0, y0, x1 - x0, y1 - y0, n_sub=n_sub)
    block = canvas[y0:y1, x0:x1]
    block += (level - block) * cov


@functools.lru_cache(maxsize=8)
def light_field(width, height, gx, gy, vignetting, shadow=1.0, shadow_angle_deg=0.0, shadow_offset_px=0.0,
                shadow_edge_px=0.0):
    """The relative illumination (1 at the image centre) of a `width` x `height` px
    image as float32, read-only (cached): linear gradients `gx`, `gy` (relative
    change across the image's width and height) times 1 - `vignetting`·ρ², ρ the
    distance from the centre over the half-diagonal, times the shadow of
    :class:`~vision_torsion.synthetic.scene.LightingSpec` (`shadow` < 1)."""
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    light = 1 + gx * (xs - width / 2) / width + gy * (ys - height / 2) / height
    if vignetting:
        half_diag2 = (width / 2) ** 2 + (height / 2) ** 2
        rho2 = ((xs - (width - 1) / 2) ** 2 + (ys - (height - 1) / 2) ** 2) / half_diag2
        light *= 1 - vignetting * rho2
    if shadow < 1:
        # signed distance into the shade (y grows downwards: the angle is as displayed)
        a = np.deg2rad(shadow_angle_deg)
        depth = (xs - (width - 1) / 2) * np.cos(a) - (ys - (height - 1) / 2) * np.sin(a) - shadow_offset_px
        shade = np.clip(depth / max(shadow_edge_px, 1e-9) + 0.5, 0.0, 1.0)
        light *= 1 - (1 - shadow) * shade
    light.setflags(write=False)
    return light


def scene_light(scene: Scene) -> np.ndarray | None:
    """The scene's relative illumination (:func:`light_field` of its
    :class:`~vision_torsion.synthetic.scene.LightingSpec`), or None for even light."""
    lt = scene.lighting
    if not (lt.gradient_x or lt.gradient_y or lt.vignetting or lt.shadow < 1):
        return None
    return light_field(scene.image.width, scene.image.height, lt.gradient_x, lt.gradient_y, lt.vignetting,
                       lt.shadow, lt.shadow_angle_deg, lt.shadow_offset_px, lt.shadow_edge_px)


def reflection(scene: Scene, xs, ys) -> np.ndarray:
    """The light (DN) a lamp's reflection adds at the pixels (`xs`, `ys`) (arrays of
    x and y in px), before blur and clipping
    (:class:`~vision_torsion.synthetic.scene.LightingSpec`)."""
    lt = scene.lighting
    return lt.reflection_dn * np.exp(-((xs - lt.reflection_x) ** 2 + (ys - lt.reflection_y) ** 2)
                                     / (2 * lt.reflection_sigma_px**2))


def render_ideal(scene: Scene, angle_deg: float = 0.0) -> np.ndarray:
    """The noise-free, unquantised image (float64 DN) after lighting and blur.

    This is the expectation of every pixel of :func:`render` before quantisation;
    it is what the Cramér–Rao bound is computed from.
    """
    check_markers_in_frame(scene, angle_deg, where=scene.name)
    W, H = scene.image.width, scene.image.height
    mapping = CameraMapping(scene)
    disk = scene.disk
    canvas = np.full((H, W), disk.background_level, dtype=np.float64)
    if disk.radius_px is not None:
        outside = np.full_like(canvas, disk.outside_level)
        paint_circle(outside, mapping, disk.center_x, disk.center_y, disk.radius_px, disk.background_level, n_sub=4)
        canvas = outside
    d = scene.distractors
    for cx, cy in bolt_hole_centres_disk(scene, angle_deg):
        paint_circle(canvas, mapping, cx, cy, d.bolt_hole_radius_px, d.bolt_level)
    for (cx, cy), r in zip(marker_centres_disk(scene, angle_deg), scene.markers.radii()):
        paint_circle(canvas, mapping, cx, cy, r, scene.markers.level)
    if d.wire:
        ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
        cov = band_coverage(xs, ys, point=(disk.center_x + d.wire_offset_px, disk.center_y),
                            direction_deg=d.wire_angle_deg, width=d.wire_width_px)
        canvas += (d.wire_level - canvas) * cov
    if d.dust:
        identity = CameraMapping(scene.replace(optics={"tilt_deg": 0.0, "radial_k1": 0.0}))
        for x, y, r in dust_specks(scene):
            paint_circle(canvas, identity, x, y, r, d.dust_level, n_sub=4)
    light = scene_light(scene)
    if light is not None:
        canvas *= light
    if scene.lighting.reflection_dn:
        canvas += reflection(scene, *np.mgrid[0:H, 0:W][::-1])
    sigma = scene.optics.blur_sigma_px
    if sigma > 0:
        canvas = cv2.GaussianBlur(canvas, (0, 0), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REFLECT)
    return canvas


def _add_noise(ideal: np.ndarray, scene: Scene, rng: np.random.Generator) -> np.ndarray:
    nz = scene.noise
    img = ideal
    if nz.shot_noise:
        electrons = np.clip(img, 0, None) * nz.electrons_per_dn
        img = rng.poisson(electrons).astype(np.float64) / nz.electrons_per_dn
    if nz.read_noise_dn > 0:
        img = img + nz.read_noise_dn * rng.standard_normal(img.shape, dtype=np.float32)
    return img


def _quantise(img: np.ndarray, bit_depth: int) -> np.ndarray:
    top = 2**bit_depth - 1
    dtype = np.uint8 if bit_depth == 8 else np.uint16
    return np.clip(np.rint(img), 0, top).astype(dtype)


def render(scene: Scene, angle_deg: float = 0.0, *, seed=None) -> Rendered:
    """Render the scene with the disk turned by `angle_deg`.

    Parameters
    ----------
    scene : Scene
        What to render.
    angle_deg : float
        Disk rotation in degrees, counter-clockwise as displayed.
    seed : int or numpy.random.Generator, optional
        Seed of the noise; the same seed gives the same image.

    Returns
    -------
    Rendered
        The quantised image with its ground truth (true angle, marker centres).

    Raises
    ------
    SceneError
        A marker leaves the frame at this rotation.

    Examples
    --------
    >>> from vision_torsion.synthetic import Scene
    >>> r = render(Scene(), 10.0, seed=1)
    >>> r.image.shape, r.image.dtype.name, r.centres.shape
    ((1000, 1400), 'uint8', (2, 2))
    """
    from .geometry import marker_centres_image

    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    ideal = render_ideal(scene, angle_deg)
    image = _quantise(_add_noise(ideal, scene, rng), scene.image.bit_depth)
    jpeg_bytes = None
    if scene.noise.jpeg_quality:
        _, enc = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(scene.noise.jpeg_quality)])
        jpeg_bytes = enc.tobytes()
        image = cv2.imdecode(enc, cv2.IMREAD_UNCHANGED)
    return Rendered(
        image=image,
        angle_deg=float(angle_deg),
        centres=marker_centres_image(scene, angle_deg),
        centres_disk=marker_centres_disk(scene, angle_deg),
        jpeg_bytes=jpeg_bytes,
    )
