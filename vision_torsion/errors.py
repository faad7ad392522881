"""Exceptions raised by vision-torsion.

Every error the library raises for bad input is a subclass of
:class:`VisionTorsionError`, so a caller can catch the whole family in one place
while tests can match each specific message.
"""

from __future__ import annotations

__all__ = [
    "VisionTorsionError",
    "ImageReadError",
    "MarkerError",
    "FitError",
    "SceneError",
    "ManifestError",
    "SessionError",
    "ReferenceTableError",
    "CalibrationError",
    "AnalysisError",
    "RigError",
    "RecordError",
    "OutputError",
]


class VisionTorsionError(Exception):
    """Base class of every error vision-torsion raises for bad input or a failed fit."""


class ImageReadError(VisionTorsionError):
    """An image file is missing, unreadable, corrupt, truncated or of an unsupported kind."""


class MarkerError(VisionTorsionError):
    """The markers needed for a measurement were not found, or are unusable."""


class FitError(VisionTorsionError):
    """A fit could not be carried out (too few points, degenerate geometry, no convergence)."""


class SceneError(VisionTorsionError):
    """A synthetic scene description is invalid."""


class ManifestError(VisionTorsionError):
    """A session manifest (manifest.csv) has bad rows."""


class SessionError(VisionTorsionError):
    """A session folder or its session.toml is invalid."""


class ReferenceTableError(VisionTorsionError):
    """A reference table (reference.csv of an accuracy check) is invalid."""


class CalibrationError(VisionTorsionError):
    """A calibration (plane or lens correction) cannot be computed or applied."""


class AnalysisError(VisionTorsionError):
    """Torque-angle data cannot give the requested figure."""


class RigError(VisionTorsionError):
    """Rig constants (arm radius, transmission ratio, sensor stiffness, ...) are invalid."""


class RecordError(VisionTorsionError):
    """A torque/angle record (encoder rig CSV or measurements table) is invalid."""


class OutputError(VisionTorsionError):
    """Results cannot be written: the output folder is read-only, not a folder, or
    the disk is full; the message names the path and the reason."""
