"""Calibration: accuracy checks against a reference, and plane/lens correction.

- :func:`check_accuracy` — measure a folder with ``reference.csv`` and judge it
  against a tolerance (``vision-torsion check-accuracy``);
- :class:`PlaneCorrection` — image → disk-plane mapping (radial undistortion, then a
  homography), saved as TOML or JSON and applied by ``measure``,
  ``check-accuracy`` and ``process`` (``MeasureSettings.correction``);
- :func:`calibrate_plane` — self-calibration from the rotation sequence itself;
- :func:`calibrate_from_target` — from chessboard / circle-grid images (OpenCV).
"""

from .accuracy import AccuracyResult, AccuracySpec, check_accuracy, load_spec, read_reference_table
from .correction import PlaneCorrection, load_correction
from .selfcal import MIN_SWEEP_DEG, calibrate_plane
from .target import calibrate_from_target

__all__ = [
    "AccuracyResult",
    "AccuracySpec",
    "check_accuracy",
    "load_spec",
    "read_reference_table",
    "PlaneCorrection",
    "load_correction",
    "calibrate_plane",
    "MIN_SWEEP_DEG",
    "calibrate_from_target",
]
