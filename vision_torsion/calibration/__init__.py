"""Calibration: accuracy checks against a reference, and plane/lens correction.

- :func:`check_accuracy` — measure a folder with ``reference.csv`` and judge it
  against a tolerance (``vision-torsion check-accuracy``);
- :class:`PlaneCorrection` — image → disk-plane mapping (radial undistortion, then a
  homography), saved as TOML or JSON and applied by ``measure``,
  ``check-accuracy`` and ``process`` (``MeasureSettings.correction``);
- :func:`calibrate_plane` — self-calibration from the rotation sequence itself;
- :func:`calibrate_from_target` — from chessboard / circle-grid images (OpenCV).
"""

from .._lazy import attach

# public name -> submodule; imported on first use, so that ``process`` (which needs
# only the correction) does not pay for scipy.stats (~0.6 s) in every run
_LAZY = {
    "AccuracyResult": "accuracy",
    "AccuracySpec": "accuracy",
    "check_accuracy": "accuracy",
    "load_spec": "accuracy",
    "read_reference_table": "accuracy",
    "PlaneCorrection": "correction",
    "load_correction": "correction",
    "calibrate_plane": "selfcal",
    "MIN_SWEEP_DEG": "selfcal",
    "calibrate_from_target": "target",
}

__all__ = list(_LAZY)
__getattr__, __dir__ = attach(__name__, _LAZY)
