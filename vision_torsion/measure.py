"""Measuring a folder of images against a reference image: ``vision-torsion measure``.

Images are measured in file-name order (numbers in names compare as numbers). With
``order="sequence"`` (the default) that is taken as the order they were taken in:
marker identity is tracked and the angle unwrapped along it, and with two equal
markers an image that turned more than ``max_step_deg`` (30° by default) from the
previous one gets status ``ambiguous`` instead of a guess
(:func:`vision_torsion.angle.sequence_angles`). With ``order="independent"`` every
image is the smallest rotation from the reference (for independent rotations within
±90°, such as a rotary-stage check shot in any order). One bad image gets its own
status and message and the run goes on. The table is written atomically to ``angles.csv`` in the output folder, which is
the only place anything is written.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .angle import MAX_STEP_DEG, ORDERS, sequence_angles
from .batch import measure_each
from .correction import load_correction
from .errors import ImageReadError, OutputError, VisionTorsionError
from .fileio import check_output_dir, same_folder, write_csv
from .images import IMAGE_SUFFIXES
from .measurements import output_folder
from .pair import measure_pair
from .quality import SUSPECT, residual_flags
from .settings import MeasureSettings

__all__ = ["MeasureResult", "measure_folder", "measure_sequence", "list_images", "natural_key", "ANGLE_COLUMNS",
           "pair_columns"]

logger = logging.getLogger(__name__)

_MARKER_FIELDS = ("x_px", "y_px", "radius_px", "x_std_px", "y_std_px", "residual_rms_px", "n_edge_points")

#: Columns of angles.csv, in order.
ANGLE_COLUMNS = ["image", "angle_deg", "angle_std_deg", "status", "message"] + [
    f"marker{k}_{f}" for k in (1, 2) for f in _MARKER_FIELDS
]


@dataclass(frozen=True)
class MeasureResult:
    """Outcome of :func:`measure_folder`: the table, where it was written, and counts."""

    table: pd.DataFrame
    path: Path
    n_ok: int
    n_failed: int


def natural_key(name: str):
    """Sort key of a file name with numbers compared as numbers (IMG_2 < IMG_10).

    >>> sorted(["IMG_10.png", "IMG_2.png", "img_1.png"], key=natural_key)
    ['img_1.png', 'IMG_2.png', 'IMG_10.png']
    """
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def list_images(folder) -> list[Path]:
    """Image files directly in `folder`, in natural name order.

    Raises
    ------
    ImageReadError
        The folder does not exist or holds no image files.
    """
    p = Path(folder)
    if not p.is_dir():
        raise ImageReadError(f"{p}: no such folder")
    files = [f for f in p.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES]
    if not files:
        raise ImageReadError(f"{p}: no image files ({', '.join(IMAGE_SUFFIXES)})")
    return sorted(files, key=lambda f: natural_key(f.name))


def printable_name(name: str) -> str:
    """A file name as text that can be written anywhere: bytes that are not UTF-8
    (a file name from another system's encoding) shown as ``\\xNN`` escapes."""
    try:
        name.encode("utf-8")
        return name
    except UnicodeEncodeError:
        return name.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


def pair_columns(pair, swapped: bool) -> dict:
    """marker1_*/marker2_* columns of a pair, marker 1 being the reference's first marker."""
    if pair is None:
        return {}
    a, b = (pair.second, pair.first) if swapped else (pair.first, pair.second)
    return {f"marker{k}_{f}": getattr(m, f) for k, m in ((1, a), (2, b)) for f in _MARKER_FIELDS}


def measure_sequence(reference_pair, images, *, settings, correction=None, progress=False, measure=measure_pair,
                     order: str = "sequence", max_step_deg: float | None = MAX_STEP_DEG, predictions=None):
    """Measure images in order against a reference pair; one bad image never stops it.

    Parameters
    ----------
    reference_pair : PairMeasurement
        The reference image's target.
    images : sequence of (path, name)
        Images in sequence order and the names messages use.
    settings : MeasureSettings
        How markers are found.
    correction : PlaneCorrection, optional
        Applied to the centres before the angles.
    progress : bool
        Show a progress bar.
    measure : callable
        Measures one image: ``measure(path, settings=..., name=...)`` returns its
        :class:`~vision_torsion.pair.PairMeasurement`
        (:func:`~vision_torsion.pair.measure_pair` by default).
    order, max_step_deg, predictions
        How marker identity is resolved: see :func:`~vision_torsion.angle.sequence_angles`.

    Returns
    -------
    (list, list, list)
        Per image: the PairMeasurement or None, the AngleResult or None (check its
        ``ambiguous``), and the failure message or "" (see
        :func:`vision_torsion.batch.attempt` for what counts as a failure).
    """
    images = list(images)
    done = measure_each(lambda item: measure(item[0], settings=settings, name=item[1]), images,
                        names=[name for _, name in images], progress=progress)
    pairs = [d.value for d in done]
    # an internal error's message does not name the image (a bug's text rarely does)
    messages = [f"{name}: {d.message}" if d.unexpected else d.message for (_, name), d in zip(images, done)]
    angles = sequence_angles(reference_pair, pairs, correction=correction, order=order,
                             max_step_deg=max_step_deg, predictions=predictions)
    return pairs, angles, messages


def measure_folder(
    image_dir,
    *,
    reference,
    out_dir=None,
    settings: MeasureSettings | None = None,
    progress: bool = False,
    order: str = "sequence",
    max_step_deg: float | None = MAX_STEP_DEG,
) -> MeasureResult:
    """Measure every image of a folder against a reference image.

    Parameters
    ----------
    image_dir : str or os.PathLike
        Folder of images (PNG, TIFF, BMP, JPEG), measured in natural name order.
    reference : str or os.PathLike
        The reference image (angle 0); it may lie inside or outside `image_dir`.
    out_dir : str or os.PathLike, optional
        Where ``angles.csv`` goes; ``IMAGE_DIR/results`` by default.
    settings : MeasureSettings, optional
        Marker polarity, radius range, fit method, pair choice, and the path of a
        saved plane/lens correction (``settings.correction``) applied to the centres.
    progress : bool
        Show a progress bar.
    order : {"sequence", "independent"}
        ``sequence``: images in name order are a sequence of small steps (identity
        tracked, angles unwrapped); ``independent``: each image is the smallest
        rotation from the reference.
    max_step_deg : float or None
        In ``sequence`` order with two equal markers, an image more than this (deg)
        from the previous certain angle gets status ``ambiguous``; None never flags.

    Returns
    -------
    MeasureResult
        The table (:data:`ANGLE_COLUMNS`): angle in degrees counter-clockwise as
        displayed with its standard uncertainty, status ``ok``/``failed``/``suspect``
        (measured, but a marker's fit residual is far above the folder's typical one:
        :mod:`vision_torsion.quality`; counted in ``n_failed``)/``ambiguous`` (marker
        identity not certain: angle withheld, both candidates in the message), message,
        and both markers' centres (px), radii, uncertainties and residuals.

    Raises
    ------
    ImageReadError, MarkerError
        The folder has no images, or the reference image is unusable.
    VisionTorsionError
        Unknown `order`, or `max_step_deg` not in (0°, 90°).
    CalibrationError
        ``settings.correction`` cannot be loaded.
    """
    if order not in ORDERS:
        raise VisionTorsionError(f"order must be one of {ORDERS}, got {order!r}")
    if max_step_deg is not None and not 0 < max_step_deg < 90:
        raise VisionTorsionError(f"max_step_deg must be between 0 and 90 degrees, got {max_step_deg!r}")
    settings = settings or MeasureSettings()
    correction = load_correction(settings.correction)
    files = list_images(image_dir)
    out = output_folder(image_dir, out_dir)
    if same_folder(out, image_dir):
        raise OutputError(f"{out}: the output folder cannot be the image folder itself; use a "
                          "subfolder such as results/")
    check_output_dir(out, replaces=["angles.csv"])
    ref_pair = measure_pair(reference, settings=settings, name=f"reference {reference}")
    pairs, angles, messages = measure_sequence(
        ref_pair, [(f, f.name) for f in files], settings=settings, correction=correction, progress=progress,
        order=order, max_step_deg=max_step_deg,
    )
    flags = residual_flags([ref_pair, *pairs])[1:]  # the reference counts towards the typical residual
    rows = []
    for f, pair, ang, msg, flag in zip(files, pairs, angles, messages, flags):
        row = {"image": printable_name(f.name), "angle_deg": np.nan, "angle_std_deg": np.nan, "status": "failed",
               "message": msg}
        if ang is not None and ang.ambiguous:
            logger.warning("%s: %s", f.name, ang.ambiguous)
            row.update(status="ambiguous", message=ang.ambiguous)
        elif ang is not None:
            row.update(
                angle_deg=ang.angle_deg, angle_std_deg=ang.angle_std_deg, status=SUSPECT if flag else "ok", message=flag
            )
            row.update(pair_columns(pair, ang.swapped))
        rows.append(row)
    table = pd.DataFrame(rows, columns=ANGLE_COLUMNS)
    write_csv(out / "angles.csv", table)
    n_ok = int((table["status"] == "ok").sum())
    return MeasureResult(table=table, path=out / "angles.csv", n_ok=n_ok, n_failed=len(table) - n_ok)
