"""Synthetic camera images of a torque disk with known rotation (the test truth).

Like ``trackpy.artificial`` beside trackpy's locator, this module sits beside the
measuring code so every accuracy claim can be checked on images whose answer is
known to far better than a thousandth of a pixel.
"""

from ..lazy import attach

# the modules whose __all__ make up this face, each imported on first use of one of its names
_LAZY = ("encoder", "gears", "geometry", "measurement_tables", "render", "scene", "target_scenes")

__getattr__, __dir__ = attach(__name__, _LAZY)
