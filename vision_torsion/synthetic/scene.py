"""Scene descriptions for the synthetic renderer, loadable from TOML.

A scene is the face of a torque disk seen by a camera: the disk turns about a
rotation centre anywhere in the frame and carries circular markers (and optionally
bolt holes); the camera adds blur, noise, lighting, tilt, lens distortion and JPEG.

TOML layout (all lengths in pixels of the untilted image, grey levels in DN of the
output bit depth, angles in degrees counter-clockwise as displayed)::

    [image]            width, height, bit_depth
    [disk]             center_x*, center_y*, background_level*, radius_px, outside_level
    [markers]          polarity*, level*, radius_px*, distance_px*, positions_deg, radii_px,
                       distances_px
    [optics]           blur_sigma_px, tilt_deg, tilt_axis_deg, focal_length_px, radial_k1
    [noise]            read_noise_dn, shot_noise, electrons_per_dn, jpeg_quality
    [lighting]         gradient_x, gradient_y, vignetting, shadow, shadow_angle_deg,
                       shadow_offset_px, shadow_edge_px, reflection_dn, reflection_x,
                       reflection_y, reflection_sigma_px
    [distractors]      bolt_holes, bolt_hole_radius_px, bolt_circle_px, bolt_level,
                       wire, wire_angle_deg, wire_offset_px, wire_width_px, wire_level,
                       dust, dust_radius_px, dust_level, dust_seed
    [sweep]            angles_deg (for accuracy folders)

Fields marked * are required. Anything else has the default shown in the dataclasses
below. Validation (:func:`validate_scene`) names the offending field.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from ..errors import SceneError
from ..textfiles import read_toml

__all__ = [
    "Scene",
    "ImageSpec",
    "DiskSpec",
    "MarkerSpec",
    "OpticsSpec",
    "NoiseSpec",
    "LightingSpec",
    "DistractorSpec",
    "SweepSpec",
    "load_scene",
    "scene_from_dict",
    "scene_to_dict",
    "validate_scene",
]


@dataclass(frozen=True)
class ImageSpec:
    """Image size (px) and output bit depth (8, 12 or 16)."""

    width: int = 1400
    height: int = 1000
    bit_depth: int = 8


@dataclass(frozen=True)
class DiskSpec:
    """The torque disk: rotation centre (px), grey level of its face (DN), optional rim."""

    center_x: float = 700.0
    center_y: float = 500.0
    background_level: float = 200.0
    radius_px: float | None = None
    outside_level: float = 20.0


@dataclass(frozen=True)
class MarkerSpec:
    """The circular markers: all share distance from the centre and polarity.

    ``positions_deg`` are the markers' angular positions on the disk at rotation 0,
    counter-clockwise as displayed from the +x axis. ``radii_px``, when given, is
    each marker's own radius (one per position), e.g. ``[35, 25]`` for a target
    whose two markers can never be mistaken for each other; otherwise every
    marker has ``radius_px``. ``distances_px``, when given, is each marker's own
    distance from the centre (a grid target, see
    :func:`~vision_torsion.synthetic.target_scene`); otherwise ``distance_px``.
    """

    polarity: str = "dark"
    level: float = 40.0
    radius_px: float = 35.0
    distance_px: float = 300.0
    positions_deg: tuple = (0.0, 180.0)
    radii_px: tuple = ()
    distances_px: tuple = ()

    def radii(self) -> tuple:
        """Radius (px) of each marker, in the order of ``positions_deg``."""
        return tuple(self.radii_px) if self.radii_px else (self.radius_px,) * len(self.positions_deg)

    def distances(self) -> tuple:
        """Distance (px) of each marker from the rotation centre, in the order of ``positions_deg``."""
        return tuple(self.distances_px) if self.distances_px else (self.distance_px,) * len(self.positions_deg)


@dataclass(frozen=True)
class OpticsSpec:
    """Gaussian PSF (σ, px), camera tilt (deg) about an in-plane axis, focal length (px), radial distortion k1."""

    blur_sigma_px: float = 1.0
    tilt_deg: float = 0.0
    tilt_axis_deg: float = 0.0
    focal_length_px: float = 5000.0
    radial_k1: float = 0.0


@dataclass(frozen=True)
class NoiseSpec:
    """Read noise σ (DN), signal-dependent shot noise (Poisson in electrons), JPEG quality (0 = off)."""

    read_noise_dn: float = 2.0
    shot_noise: bool = False
    electrons_per_dn: float = 20.0
    jpeg_quality: int = 0


@dataclass(frozen=True)
class LightingSpec:
    """Illumination: linear gradient (relative change across the frame in x and y),
    vignetting, a shadow, and a lamp's reflection.

    The light factor is ``(1 + gx·(x-W/2)/W + gy·(y-H/2)/H) · (1 - v·ρ²) · S``, with ρ
    the distance from the image centre divided by the half diagonal, and S the
    shadow: ``shadow`` (the relative light in the shade, 1 for none) beyond a
    straight edge whose normal points ``shadow_angle_deg`` (counter-clockwise as
    displayed from +x) into the shade and which passes ``shadow_offset_px`` from the
    image centre along that normal; the light changes linearly across a penumbra
    ``shadow_edge_px`` wide centred on the edge. The reflection of a lamp adds light
    that does not depend on the surface's reflectance (a glossy print's specular
    highlight): a Gaussian of peak ``reflection_dn`` (DN) and σ
    ``reflection_sigma_px`` at (``reflection_x``, ``reflection_y``) px, added after the
    light factor; where it pushes the image past the top of the bit depth the
    quantisation clips it, which takes the markers' contrast away there.
    """

    gradient_x: float = 0.0
    gradient_y: float = 0.0
    vignetting: float = 0.0
    shadow: float = 1.0
    shadow_angle_deg: float = 0.0
    shadow_offset_px: float = 0.0
    shadow_edge_px: float = 0.0
    reflection_dn: float = 0.0
    reflection_x: float = 0.0
    reflection_y: float = 0.0
    reflection_sigma_px: float = 100.0


@dataclass(frozen=True)
class DistractorSpec:
    """Things that are not the markers: bolt holes (turn with the disk), a static wire, dust specks."""

    bolt_holes: int = 0
    bolt_hole_radius_px: float = 12.0
    bolt_circle_px: float = 200.0
    bolt_level: float = 30.0
    wire: bool = False
    wire_angle_deg: float = 75.0
    wire_offset_px: float = 0.0
    wire_width_px: float = 3.0
    wire_level: float = 60.0
    dust: int = 0
    dust_radius_px: float = 2.0
    dust_level: float = 90.0
    dust_seed: int = 7


@dataclass(frozen=True)
class SweepSpec:
    """Rotation angles (deg) of an accuracy-check folder; the first should be 0 (the reference)."""

    angles_deg: tuple = tuple(float(a) for a in range(-70, 71, 10))


@dataclass(frozen=True)
class Scene:
    """A complete synthetic scene (see the module docstring for the TOML layout)."""

    image: ImageSpec = field(default_factory=ImageSpec)
    disk: DiskSpec = field(default_factory=DiskSpec)
    markers: MarkerSpec = field(default_factory=MarkerSpec)
    optics: OpticsSpec = field(default_factory=OpticsSpec)
    noise: NoiseSpec = field(default_factory=NoiseSpec)
    lighting: LightingSpec = field(default_factory=LightingSpec)
    distractors: DistractorSpec = field(default_factory=DistractorSpec)
    sweep: SweepSpec = field(default_factory=SweepSpec)
    name: str = "scene"

    def replace(self, **sections) -> "Scene":
        """A copy with some fields changed: ``scene.replace(noise={"read_noise_dn": 0})``."""
        changes = {}
        for key, value in sections.items():
            current = getattr(self, key)
            if isinstance(value, dict) and dataclasses.is_dataclass(current):
                changes[key] = dataclasses.replace(current, **value)
            else:
                changes[key] = value
        out = dataclasses.replace(self, **changes)
        validate_scene(out)
        return out


_SECTIONS = {
    "image": ImageSpec,
    "disk": DiskSpec,
    "markers": MarkerSpec,
    "optics": OpticsSpec,
    "noise": NoiseSpec,
    "lighting": LightingSpec,
    "distractors": DistractorSpec,
    "sweep": SweepSpec,
}
_REQUIRED = {
    "disk": ("center_x", "center_y", "background_level"),
    "markers": ("polarity", "level", "radius_px", "distance_px"),
}


def _coerce(section: str, name: str, value, default, where: str):
    label = f"{where}[{section}] {name}"
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise SceneError(f"{label} must be true or false, got {value!r}")
        return value
    if isinstance(default, int) and not isinstance(default, bool):
        if isinstance(value, bool) or not isinstance(value, int):
            raise SceneError(f"{label} must be an integer, got {value!r}")
        return value
    if isinstance(default, float) or default is None:
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(f"{label} must be a number, got {value!r}")
        if not math.isfinite(value):
            raise SceneError(f"{label} must be finite, got {value!r}")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise SceneError(f"{label} must be a string, got {value!r}")
        return value
    if isinstance(default, tuple):
        if not isinstance(value, (list, tuple)) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
        ):
            raise SceneError(f"{label} must be a list of numbers, got {value!r}")
        return tuple(float(v) for v in value)
    return value


def table_to_dataclass(cls, table: dict, *, section: str, prefix: str = ""):
    """Build the dataclass `cls` from a TOML table, each field typed like its default.

    Raises
    ------
    SceneError
        An unknown field or a wrong-typed value, naming ``[section] field``.
    """
    defaults = {f.name: f.default for f in dataclasses.fields(cls)}
    extra = set(table) - set(defaults)
    if extra:
        raise SceneError(f"{prefix}[{section}] unknown field(s) {sorted(extra)}; known: {sorted(defaults)}")
    return cls(**{k: _coerce(section, k, v, defaults[k], prefix) for k, v in table.items()})


def scene_from_dict(data: dict, *, where: str = "", name: str = "scene") -> Scene:
    """Build and validate a :class:`Scene` from a nested dict (as read from TOML).

    Parameters
    ----------
    data : dict
        Tables named as in the module docstring.
    where : str
        Prefix for error messages (the file name).
    name : str
        The scene's name (the TOML file's stem).

    Raises
    ------
    SceneError
        Unknown table or field, missing required field, wrong type, or an
        inconsistent scene (see :func:`validate_scene`).
    """
    prefix = f"{where}: " if where else ""
    unknown = set(data) - set(_SECTIONS) - {"name"}
    if unknown:
        raise SceneError(f"{prefix}unknown table(s) {sorted(unknown)}; expected {sorted(_SECTIONS)}")
    parts = {}
    for section, cls in _SECTIONS.items():
        table = data.get(section, {})
        if not isinstance(table, dict):
            raise SceneError(f"{prefix}[{section}] must be a table")
        for req in _REQUIRED.get(section, ()):
            if req not in table:
                raise SceneError(f"{prefix}[{section}] {req} is missing (required)")
        parts[section] = table_to_dataclass(cls, table, section=section, prefix=prefix)
    scene = Scene(**parts, name=str(data.get("name", name)))
    validate_scene(scene, where=where)
    return scene


def scene_to_dict(scene: Scene) -> dict:
    """The scene as nested plain dicts (TOML-writable; None fields left out)."""
    out = {"name": scene.name}
    for section in _SECTIONS:
        table = dataclasses.asdict(getattr(scene, section))
        out[section] = {k: (list(v) if isinstance(v, tuple) else v) for k, v in table.items() if v is not None}
    return out


def load_scene(path) -> Scene:
    """Read a scene TOML file (see the module docstring for its tables).

    Raises
    ------
    SceneError
        The file is missing or not valid TOML, or a field is missing, wrong-typed or
        inconsistent; the message names the file and the field.
    """
    from ..resources import SCENES, named_file

    p = named_file(path, SCENES, error=SceneError, what="scene")  # a path, or a ready scene's name
    data = read_toml(p, what="a scene file (TOML)", error=SceneError)
    return scene_from_dict(data, where=str(p), name=p.stem)


def validate_scene(scene: Scene, *, where: str = "") -> None:
    """Check a scene for consistency before anything is rendered.

    Raises
    ------
    SceneError
        Non-positive sizes or radii, unknown polarity or bit depth, markers that
        overlap or leave the frame at rotation 0, noise or blur below zero, JPEG with
        more than 8 bits. The message names the field.
    """
    p = f"{where}: " if where else ""
    im, disk, mk, op, nz = scene.image, scene.disk, scene.markers, scene.optics, scene.noise
    if im.width < 16 or im.height < 16:
        raise SceneError(f"{p}[image] width and height must be at least 16 px")
    if im.bit_depth not in (8, 12, 16):
        raise SceneError(f"{p}[image] bit_depth must be 8, 12 or 16, got {im.bit_depth}")
    top = 2**im.bit_depth - 1
    for label, value in (
        ("[disk] background_level", disk.background_level),
        ("[markers] level", mk.level),
    ):
        if not 0 <= value <= top:
            raise SceneError(f"{p}{label} must be within 0..{top} DN, got {value}")
    if mk.polarity not in ("dark", "bright"):
        raise SceneError(f"{p}[markers] polarity must be 'dark' or 'bright', got {mk.polarity!r}")
    if (mk.polarity == "dark") != (mk.level < disk.background_level):
        raise SceneError(
            f"{p}[markers] level {mk.level} does not match polarity {mk.polarity!r} "
            f"against the disk's background_level {disk.background_level}"
        )
    if mk.radius_px <= 0:
        raise SceneError(f"{p}[markers] radius_px must be positive, got {mk.radius_px}")
    if mk.radii_px and len(mk.radii_px) != len(mk.positions_deg):
        raise SceneError(
            f"{p}[markers] radii_px has {len(mk.radii_px)} value(s) for {len(mk.positions_deg)} positions_deg"
        )
    if any(r <= 0 for r in mk.radii_px):
        raise SceneError(f"{p}[markers] radii_px must all be positive, got {list(mk.radii_px)}")
    if mk.distance_px < 0:
        raise SceneError(f"{p}[markers] distance_px must not be negative, got {mk.distance_px}")
    if mk.distances_px and len(mk.distances_px) != len(mk.positions_deg):
        raise SceneError(
            f"{p}[markers] distances_px has {len(mk.distances_px)} value(s) for {len(mk.positions_deg)} positions_deg"
        )
    if any(d < 0 for d in mk.distances_px):
        raise SceneError(f"{p}[markers] distances_px must not be negative, got {list(mk.distances_px)}")
    if len(mk.positions_deg) < 1:
        raise SceneError(f"{p}[markers] positions_deg needs at least one marker")
    if op.blur_sigma_px < 0:
        raise SceneError(f"{p}[optics] blur_sigma_px must not be negative")
    if op.focal_length_px <= 0:
        raise SceneError(f"{p}[optics] focal_length_px must be positive")
    if not -30 <= op.tilt_deg <= 30:
        raise SceneError(f"{p}[optics] tilt_deg must be within ±30°, got {op.tilt_deg}")
    if nz.read_noise_dn < 0:
        raise SceneError(f"{p}[noise] read_noise_dn must not be negative")
    if nz.electrons_per_dn <= 0:
        raise SceneError(f"{p}[noise] electrons_per_dn must be positive")
    if nz.jpeg_quality and not (1 <= nz.jpeg_quality <= 100):
        raise SceneError(f"{p}[noise] jpeg_quality must be 0 (off) or 1..100")
    if nz.jpeg_quality and im.bit_depth != 8:
        raise SceneError(f"{p}[noise] jpeg_quality needs [image] bit_depth = 8")
    lt = scene.lighting
    if not 0 < lt.shadow <= 1:
        raise SceneError(f"{p}[lighting] shadow must be within (0, 1] (the relative light in the shade), "
                         f"got {lt.shadow}")
    if lt.shadow_edge_px < 0 or lt.reflection_dn < 0:
        raise SceneError(f"{p}[lighting] shadow_edge_px and reflection_dn must not be negative")
    if lt.reflection_sigma_px <= 0:
        raise SceneError(f"{p}[lighting] reflection_sigma_px must be positive, got {lt.reflection_sigma_px}")
    d = scene.distractors
    if d.bolt_holes < 0 or d.dust < 0:
        raise SceneError(f"{p}[distractors] bolt_holes and dust must not be negative")
    if d.bolt_hole_radius_px <= 0 or d.dust_radius_px <= 0 or d.wire_width_px <= 0:
        raise SceneError(f"{p}[distractors] radii and widths must be positive")
    # marker overlap (on the disk, rotation-invariant)
    pos, radii, dist = mk.positions_deg, mk.radii(), mk.distances()
    for i in range(len(pos)):
        for j in range(i + 1, len(pos)):
            dphi = math.radians(pos[i] - pos[j])
            sep = math.sqrt(max(dist[i] ** 2 + dist[j] ** 2 - 2 * dist[i] * dist[j] * math.cos(dphi), 0.0))
            if sep < radii[i] + radii[j] + 2:
                raise SceneError(
                    f"{p}[markers] markers {i + 1} and {j + 1} overlap "
                    f"(centres {sep:.1f} px apart, radii {radii[i]:g} and {radii[j]:g} px)"
                )
    check_markers_in_frame(scene, 0.0, where=where)


def check_markers_in_frame(scene: Scene, angle_deg: float, *, where: str = "") -> None:
    """Raise SceneError if a marker at rotation `angle_deg` is not wholly inside the frame."""
    from .geometry import marker_centres_disk

    p = f"{where}: " if where else ""
    mk = scene.markers
    for k, ((x, y), r) in enumerate(zip(marker_centres_disk(scene, angle_deg), mk.radii())):
        margin = r + 3 * scene.optics.blur_sigma_px + 2
        if not (margin <= x <= scene.image.width - 1 - margin and margin <= y <= scene.image.height - 1 - margin):
            raise SceneError(
                f"{p}[markers] marker {k + 1} at rotation {angle_deg:g}° lies outside the "
                f"{scene.image.width}x{scene.image.height} frame (centre {x:.1f}, {y:.1f} px)"
            )
