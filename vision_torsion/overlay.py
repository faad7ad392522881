"""See what was detected: an image with its markers and fitted circles drawn.

Like trackpy's ``annotate``: :func:`annotate` draws on a matplotlib Axes (for a
notebook), :func:`overlay_image` returns an RGB array drawn with OpenCV (fast, for
files: ``measure --overlay DIR`` and the session report), :func:`write_overlay`
writes it as a PNG.

What is drawn, in image coordinates (origin at the centre of the top-left pixel,
x right, y down; OpenCV and matplotlib's ``imshow`` use the same convention, and
circles are drawn with sub-pixel precision):

- every usable marker: its fitted circle (green) and a cross at its centre;
- the pair chosen as the target: thicker circles, joined by the marker line
  (blue), with the measured direction of the line;
- every rejected candidate: an orange circle at its coarse radius with its status
  ("cut by the border", "not round", ...), so a user sees why a marker was missed.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from .images import as_grey_array
from .settings import MeasureSettings

__all__ = ["overlay_image", "write_overlay", "write_overlays", "annotate", "detections",
           "overlay_section"]

_SHIFT = 4  # OpenCV's sub-pixel drawing: coordinates in 1/16 px
_GREEN, _BLUE, _ORANGE, _RED = (40, 170, 60), (30, 90, 220), (240, 140, 20), (210, 30, 30)


def detections(image, *, settings: MeasureSettings | None = None, name: str = "image"):
    """The marker table and the chosen pair of an image.

    Returns
    -------
    (pandas.DataFrame, PairMeasurement or None, str)
        :func:`~vision_torsion.markers.find_markers`'s table, the pair
        :func:`~vision_torsion.pair.select_pair` chooses from it (None when it
        cannot), and why not ("" when it can).
    """
    from .errors import MarkerError
    from .markers import find_markers
    from .pair import select_pair

    settings = settings or MeasureSettings()
    table = find_markers(image, settings=settings)
    try:
        return table, select_pair(table, pair=settings.pair, name=name), ""
    except MarkerError as exc:
        return table, None, str(exc)


def _rgb(grey: np.ndarray, full_scale: float) -> np.ndarray:
    g = np.clip(grey.astype(np.float32) * (255.0 / full_scale), 0, 255).astype(np.uint8)
    return np.repeat(g[:, :, None], 3, axis=2)


def _pt(x, y):
    return (int(round(x * (1 << _SHIFT))), int(round(y * (1 << _SHIFT))))


def overlay_image(image, *, settings: MeasureSettings | None = None, name: str = "image",
                  thickness: int | None = None) -> np.ndarray:
    """The image as RGB (8 bit) with its detections drawn (module docstring).

    Parameters
    ----------
    image : path, GreyImage or array_like
        The image (a file is read and validated).
    settings : MeasureSettings, optional
        How markers are found (polarity, radius range, fit, pair choice).
    name : str
        What to call the image in the drawn messages.
    thickness : int, optional
        Line width in pixels (default: about 1/500 of the image's larger side, ≥ 1).

    Returns
    -------
    numpy.ndarray
        ``(height, width, 3)`` uint8, RGB; the input is not modified.
    """
    grey = as_grey_array(image, name=name, keep_integers=True)
    full = 255.0 if grey.dtype == np.uint8 else float(2 ** 16 - 1) if grey.dtype == np.uint16 \
        else float(max(np.nanmax(grey), 1.0))
    table, pair, why = detections(grey, settings=settings, name=name)
    out = _rgb(grey, full)
    t = thickness or max(1, round(max(grey.shape) / 500))
    font = 0.4 + max(grey.shape) / 2500
    for m in table.itertuples():
        if not (math.isfinite(m.x_px) and math.isfinite(m.y_px)):
            continue
        r = m.radius_px if math.isfinite(m.radius_px) and m.radius_px > 0 else 3.0
        centre = _pt(m.x_px, m.y_px)
        if m.status == "ok":
            cv2.circle(out, centre, int(round(r * (1 << _SHIFT))), _GREEN, t, cv2.LINE_AA, _SHIFT)
            arm = int(round(0.3 * r * (1 << _SHIFT)))
            cv2.line(out, (centre[0] - arm, centre[1]), (centre[0] + arm, centre[1]), _GREEN, t, cv2.LINE_AA, _SHIFT)
            cv2.line(out, (centre[0], centre[1] - arm), (centre[0], centre[1] + arm), _GREEN, t, cv2.LINE_AA, _SHIFT)
        else:
            cv2.circle(out, centre, int(round(r * (1 << _SHIFT))), _ORANGE, t, cv2.LINE_AA, _SHIFT)
            cv2.putText(out, str(m.status), (int(m.x_px + r + 3), int(m.y_px)), cv2.FONT_HERSHEY_SIMPLEX,
                        font, _ORANGE, max(1, t // 2), cv2.LINE_AA)
    if pair is not None:
        a, b = pair.first, pair.second
        for m in (a, b):
            cv2.circle(out, _pt(m.x_px, m.y_px), int(round(m.radius_px * (1 << _SHIFT))), _BLUE, 2 * t,
                       cv2.LINE_AA, _SHIFT)
        cv2.line(out, _pt(a.x_px, a.y_px), _pt(b.x_px, b.y_px), _BLUE, t, cv2.LINE_AA, _SHIFT)
        from .angle import line_direction_deg

        label = f"marker line {line_direction_deg((a.x_px, a.y_px), (b.x_px, b.y_px)):+.3f} deg (CCW)"
        cv2.putText(out, label, (10, int(30 * font / 0.5)), cv2.FONT_HERSHEY_SIMPLEX, font, _BLUE,
                    max(1, t), cv2.LINE_AA)
    else:
        cv2.putText(out, f"no pair: {why[:90]}", (10, int(30 * font / 0.5)), cv2.FONT_HERSHEY_SIMPLEX,
                    font, _RED, max(1, t), cv2.LINE_AA)
    return out


def write_overlay(path, image, **kwargs) -> Path:
    """Write :func:`overlay_image` of `image` as a PNG (atomically); return the path."""
    from .fileio import atomic_write_bytes

    rgb = overlay_image(image, **kwargs)
    ok, buf = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    return atomic_write_bytes(path, buf.tobytes())


def annotate(image, *, settings: MeasureSettings | None = None, ax=None, name: str = "image"):
    """Show the image with its detections on a matplotlib Axes (like trackpy.annotate).

    Parameters
    ----------
    image : path, GreyImage or array_like
    settings : MeasureSettings, optional
    ax : matplotlib.axes.Axes, optional
        Where to draw (a new figure's Axes by default).
    name : str
        What to call the image in messages.

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        from matplotlib.figure import Figure

        ax = Figure(figsize=(8, 6)).add_subplot()
    ax.imshow(overlay_image(image, settings=settings, name=name))
    ax.set_title(f"{name}: detected markers (green), the pair (blue), rejected (orange)")
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    return ax


def write_overlays(images, out_dir, *, settings: MeasureSettings | None = None,
                   inputs=()) -> list[Path]:
    """Write ``OUT_DIR/<name>_overlay.png`` for every image (:func:`write_overlay`).

    Parameters
    ----------
    images : iterable of path
        The images.
    out_dir : path-like
        Where the overlays go (created).
    settings : MeasureSettings, optional
    inputs : iterable of path-like
        Input folders `out_dir` must not be (an input folder is never written).

    Returns
    -------
    list of pathlib.Path
        The files written; an image that cannot be read gets no overlay (its
        failure is reported where it is measured).

    Raises
    ------
    OutputError
        `out_dir` is one of `inputs`; it cannot be created or written, or holds a file
        under an overlay's name that vision-torsion did not write (all checked before
        the first overlay is drawn); a write fails.
    """
    from .errors import OutputError, VisionTorsionError
    from .fileio import check_output_dir, same_folder

    out = Path(out_dir)
    if any(same_folder(out, p) for p in inputs):
        raise OutputError(f"{out}: the overlay folder cannot be an input folder (it is never "
                          "written); name another folder")
    images = [Path(image) for image in images]
    # before the first is drawn: a folder that cannot take them, or a user's file under
    # one of their names, stops them all by name (it was skipped without a word)
    check_output_dir(out, replaces=[f"{image.stem}_overlay.png" for image in images])
    written = []
    for image in images:
        try:
            written.append(write_overlay(out / f"{image.stem}_overlay.png", image, settings=settings,
                                         name=image.name))
        except OutputError:
            raise
        except VisionTorsionError:  # cannot be read: reported where it is measured
            continue
    return written


def overlay_section(images, *, settings: MeasureSettings | None = None, width_px: int = 640):
    """A report section: each (title, image path) drawn with its detections, as
    (section title, trusted HTML). Images are scaled to `width_px` and embedded as
    JPEG (a full-size PNG of each would make the report tens of MB)."""
    import html

    from .errors import VisionTorsionError
    from .htmlpage import image_tag

    parts = ["<p>Each orientation's reference image with what was detected: fitted marker "
             "circles and centres (green), the pair used for the angle joined by the marker line "
             "(blue), rejected candidates with the reason (orange).</p>"]
    for title, path in images:
        try:
            rgb = overlay_image(path, settings=settings, name=Path(path).name)
        except VisionTorsionError as exc:
            parts.append(f"<p>{html.escape(title)}: no overlay ({html.escape(str(exc))})</p>")
            continue
        scale = min(1.0, width_px / rgb.shape[1])
        small = cv2.resize(rgb, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) if scale < 1 else rgb
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(small, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 85])
        parts.append(f'<figure>{image_tag(buf.tobytes(), title, mime="image/jpeg")}'
                     f"<figcaption>{html.escape(title)}</figcaption></figure>")
    return "Detected markers on the reference images", "\n".join(parts)
