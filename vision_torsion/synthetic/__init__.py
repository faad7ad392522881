"""Synthetic camera images of a torque disk with known rotation (the test truth).

Like ``trackpy.artificial`` beside trackpy's locator, this module sits beside the
measuring code so every accuracy claim can be checked on images whose answer is
known to far better than a thousandth of a pixel.
"""

from .geometry import CameraMapping, marker_centres_disk, marker_centres_image
from .render import Rendered, render, render_ideal
from .scene import Scene, load_scene, scene_from_dict, scene_to_dict, validate_scene
from .targets import target_scene

__all__ = [
    "Scene",
    "load_scene",
    "scene_from_dict",
    "scene_to_dict",
    "validate_scene",
    "render",
    "render_ideal",
    "Rendered",
    "CameraMapping",
    "marker_centres_disk",
    "marker_centres_image",
    "target_scene",
]
