"""Exceptions raised by vision-torsion.

Every error the library raises for bad input is a subclass of
:class:`VisionTorsionError`, so a caller can catch the whole family in one place
while tests can match each specific message.

Each error also carries a ``reason``: a short, stable code (``"low_contrast"``,
``"not_monotonic"``, ``"not_found"``, ...) that code may branch on. A status or a
decision is taken from the type and the ``reason``, never from the message text,
which is for people and may be reworded. The class attribute ``reason`` is the
default code of each class; raise with ``reason=...`` to be more specific:

>>> try:
...     raise FitError("marker edge has too little contrast (3.1 DN)", reason="low_contrast")
... except FitError as exc:
...     exc.reason
'low_contrast'
>>> FitError("no convergence").reason
'fit_failed'

Each class also derives from the built-in exception that matches it, so code that
knows nothing of vision-torsion catches it as it would any library's error: bad
values and bad input are :class:`ValueError` (a fit that fails too, as numpy's
``LinAlgError`` is); a file that cannot be read as an image (as Pillow's
``UnidentifiedImageError``) and results that cannot be written are
:class:`OSError`:

>>> try:
...     raise SessionError("rig.arm_radius_m must be a finite number > 0 (m), got -1")
... except ValueError as exc:
...     exc.reason
'bad_session'
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
    "MeasurementsError",
    "CampaignError",
    "TargetError",
]


class VisionTorsionError(Exception):
    """Base class of every error vision-torsion raises for bad input or a failed fit.

    Parameters
    ----------
    *args
        The message (as for any exception).
    reason : str, optional
        A stable code saying what went wrong; the class's default when omitted.
        It survives pickling (worker processes), as instance state.
    """

    #: Default reason code of this class.
    reason: str = "error"

    def __init__(self, *args, reason: str | None = None):
        super().__init__(*args)
        if reason is not None:
            self.reason = reason


class ImageReadError(VisionTorsionError, OSError):
    """An image file is missing, unreadable, corrupt, truncated or of an unsupported kind."""

    reason = "unreadable_image"


class MarkerError(VisionTorsionError, ValueError):
    """The markers needed for a measurement were not found, or are unusable."""

    reason = "marker_error"


class FitError(VisionTorsionError, ValueError):
    """A fit could not be carried out (too few points, degenerate geometry, no convergence)."""

    reason = "fit_failed"


class SceneError(VisionTorsionError, ValueError):
    """A synthetic scene description is invalid."""

    reason = "bad_scene"


class ManifestError(VisionTorsionError, ValueError):
    """A session manifest (manifest.csv) has bad rows."""

    reason = "bad_manifest"


class SessionError(VisionTorsionError, ValueError):
    """A session folder or its session.toml is invalid."""

    reason = "bad_session"


class ReferenceTableError(VisionTorsionError, ValueError):
    """A reference table (reference.csv of an accuracy check) is invalid."""

    reason = "bad_reference_table"


class CalibrationError(VisionTorsionError, ValueError):
    """A calibration (plane or lens correction) cannot be computed or applied."""

    reason = "bad_calibration"


class AnalysisError(VisionTorsionError, ValueError):
    """Torque-angle data cannot give the requested figure."""

    reason = "analysis_failed"


class RigError(VisionTorsionError, ValueError):
    """Rig constants (arm radius, transmission ratio, sensor stiffness, ...) are invalid."""

    reason = "bad_rig"


class RecordError(VisionTorsionError, ValueError):
    """A torque/angle record (encoder rig CSV or measurements table) is invalid."""

    reason = "bad_record"


class OutputError(VisionTorsionError, OSError):
    """Results cannot be written: the output folder is read-only, not a folder, or
    the disk is full; the message names the path and the reason."""

    reason = "output_failed"


class MeasurementsError(AnalysisError, RecordError):
    """A measurements table (``measurements.csv``) is invalid.

    Raised by :func:`vision_torsion.measurements.read_measurements`; it is both an
    :class:`AnalysisError` and a :class:`RecordError`, so the analysis and the
    stiffness curve, which read the same table, keep their documented errors.
    """

    reason = "bad_measurements"


class CampaignError(VisionTorsionError, ValueError):
    """A campaign database or a report to be added to it is unusable: not a report,
    a report of another schema version, a file that is not a campaign database, a
    database that cannot be written. The message names the file."""

    reason = "bad_campaign"


class TargetError(VisionTorsionError, ValueError):
    """A target description (layout of the dots on the disk) is invalid or cannot be
    read; the message names the file and the field."""

    reason = "bad_target"
