"""Calibration: accuracy checks against a reference, and plane/lens correction.

- :func:`check_accuracy` — measure a folder with ``reference.csv`` and judge it
  against a tolerance (``vision-torsion check-accuracy``);
- :func:`normalised` — a computed plane correction made the identity at an anchor
  (the correction itself, :class:`vision_torsion.correction.PlaneCorrection`, lives in
  the core that applies it: ``measure``, ``check-accuracy``, ``process``);
- :func:`calibrate_plane` — self-calibration from the rotation sequence itself;
- :func:`calibrate_from_target` — from chessboard / circle-grid images (OpenCV).
"""

from ..lazy import attach

# the modules whose __all__ make up this face, each imported on first use of one of its names:
# ``process`` (which needs only the correction) does not pay for scipy.stats (~0.6 s)
_LAZY = ("accuracy", "anchoring", "selfcal", "target")

__getattr__, __dir__ = attach(__name__, _LAZY)
