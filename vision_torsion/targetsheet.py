"""A printable target: the dots of a :class:`~vision_torsion.targets.Target` as a vector
PDF at true scale, with a scale bar to check the print.

The page is drawn in millimetres (matplotlib's PDF backend writes the circles as
Bézier curves, so the dots stay exact at any printer resolution). The target's
origin, the shaft axis, is at the middle of the page and marked by a thin cross;
the page's y axis points down, as the layout's does. A 50 mm scale bar with 10 mm
ticks sits below the target: a print whose bar is not 50 mm long was scaled by the
printer ("fit to page") and must be printed again at actual size, or the images'
scale taken from the bar.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

from .errors import OutputError, TargetError
from .fileio import atomic_write_bytes
from .targets import Target, load_target

__all__ = ["write_target_pdf", "PAGES_MM", "SCALE_BAR_MM"]

#: Page sizes (width, height) in mm.
PAGES_MM = {"a4": (210.0, 297.0), "a3": (297.0, 420.0), "letter": (215.9, 279.4)}
#: Length of the scale bar (mm).
SCALE_BAR_MM = 50.0
_MM_PER_IN = 25.4
_MARGIN_MM = 12.0


def write_target_pdf(path, target, *, page: str = "a4", overwrite: bool = False) -> Path:
    """Write `target` as a one-page vector PDF at true scale.

    Parameters
    ----------
    path : str or os.PathLike
        The PDF to write (atomically).
    target : Target, str or os.PathLike
        The target, a target file or a ready target's name.
    page : {"a4", "a3", "letter"}
        Paper size; the target, its cross and the scale bar must fit within 12 mm
        margins.
    overwrite : bool
        Replace an existing file at `path`.

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    TargetError
        An unknown page, or a target too large for it (reason ``too_large``).
    OutputError
        `path` exists and `overwrite` is false (reason ``exists``), or cannot be written.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> out = write_target_pdf(pathlib.Path(tempfile.mkdtemp()) / "ring16.pdf", "ring16")
    >>> out.read_bytes()[:5]
    b'%PDF-'
    """
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    target = target if isinstance(target, Target) else load_target(target)
    key = str(page).lower()
    if key not in PAGES_MM:
        raise TargetError(f"page must be one of {', '.join(PAGES_MM)}, got {page!r}", reason="bad_value")
    width, height = PAGES_MM[key]
    extent = target.extent_mm
    need_w = 2 * extent + 2 * _MARGIN_MM
    need_h = 2 * extent + 2 * _MARGIN_MM + 30.0  # the scale bar and the caption below
    if need_w > width or need_h > height:
        raise TargetError(f"target {target.name!r} ({2 * extent:.1f} mm across) does not fit the {key} page "
                          f"({width:g} x {height:g} mm) with its scale bar; choose a larger page or a smaller "
                          "target", reason="too_large")
    out = Path(path)
    if out.exists() and not overwrite:
        raise OutputError(f"{out}: already exists; choose another name or overwrite (--force)", reason="exists")
    fig = Figure(figsize=(width / _MM_PER_IN, height / _MM_PER_IN))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, width)
    ax.set_ylim(height, 0)  # y down, as the layout's
    ax.set_aspect("equal")
    ax.axis("off")
    cx, cy = width / 2.0, _MARGIN_MM + extent
    for x, y, d in zip(target.x_mm, target.y_mm, target.diameter_mm):
        ax.add_patch(Circle((cx + x, cy + y), d / 2.0, facecolor="black", edgecolor="none"))
    arm = max(2.0, 0.05 * extent)
    line = dict(color="black", linewidth=0.3)
    ax.plot([cx - arm, cx + arm], [cy, cy], **line)
    ax.plot([cx, cx], [cy - arm, cy + arm], **line)
    y_bar = cy + extent + 10.0
    x0 = cx - SCALE_BAR_MM / 2.0
    ax.plot([x0, x0 + SCALE_BAR_MM], [y_bar, y_bar], color="black", linewidth=0.6)
    for k in range(int(SCALE_BAR_MM // 10) + 1):
        ax.plot([x0 + 10 * k] * 2, [y_bar - 1.5, y_bar + 1.5], color="black", linewidth=0.4)
    ax.text(cx, y_bar + 5.0, f"{SCALE_BAR_MM:g} mm: measure this bar; print at actual size (100 %), not fit to page",
            ha="center", va="top", fontsize=7)
    index = f", index dot {', '.join(map(str, target.index))}" if target.index else ", no index mark"
    ax.text(cx, y_bar + 10.0, f"vision-torsion target {target.name!r}: {target.n_markers} dots, {target.layout}"
            f"{index}; the cross marks the shaft axis", ha="center", va="top", fontsize=7)
    buf = io.BytesIO()
    fig.savefig(buf, format="pdf")
    return atomic_write_bytes(out, buf.getvalue())


def parse_length_mm(text, *, name: str) -> float:
    """A length such as ``80mm``, ``8cm``, ``3.15in`` or ``80`` (mm) in mm.

    Raises
    ------
    TargetError
        Not a positive length (the parameter named).

    Examples
    --------
    >>> parse_length_mm("8cm", name="--diameter"), parse_length_mm("80", name="--diameter")
    (80.0, 80.0)
    """
    s = str(text).strip().lower()
    factor = 1.0
    for unit, f in (("mm", 1.0), ("cm", 10.0), ("in", _MM_PER_IN)):
        if s.endswith(unit):
            s, factor = s[: -len(unit)].strip(), f
            break
    try:
        value = float(s) * factor
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value <= 0:
        raise TargetError(f"{name} must be a positive length such as 80mm, 8cm or 3in, got {text!r}",
                          reason="bad_value")
    return value
