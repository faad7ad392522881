"""Calibration: accuracy checks against a reference, and plane/lens correction.

- :func:`check_accuracy` — measure a folder with ``reference.csv`` and judge it
  against a tolerance (``vision-torsion check-accuracy``);
- :class:`PlaneCorrection` — image → disk-plane mapping (radial undistortion, then a
  homography), saved as TOML or JSON and applied by ``measure``,
  ``check-accuracy`` and ``process`` (``MeasureSettings.correction``);
- :func:`calibrate_plane` — self-calibration from the rotation sequence itself;
- :func:`calibrate_from_target` — from chessboard / circle-grid images (OpenCV).
"""

from ..lazy import attach

# the modules whose __all__ make up this face, each imported on first use of one of its names:
# ``process`` (which needs only the correction) does not pay for scipy.stats (~0.6 s)
_LAZY = ("accuracy", "correction", "selfcal", "target")

__getattr__, __dir__ = attach(__name__, _LAZY)
