"""Figures to PNG: the one way a matplotlib figure becomes PNG bytes or a file.

Figures are :class:`matplotlib.figure.Figure` objects drawn by the Agg canvas, never
``pyplot``: no global backend or figure registry is touched (safe in threads, no
``matplotlib.use`` at import). Files are written atomically
(:func:`vision_torsion.fileio.atomic_write_bytes`).
"""

from __future__ import annotations

import io

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .fileio import atomic_write_bytes

__all__ = ["png_bytes", "save_figure"]


def png_bytes(fig: Figure, *, dpi: float | None = None) -> bytes:
    """Render `fig` to PNG bytes at `dpi` (dots per inch; the figure's own by default).

    Examples
    --------
    >>> fig = Figure(figsize=(1, 1), dpi=50)
    >>> png_bytes(fig)[1:4]
    b'PNG'
    """
    FigureCanvasAgg(fig)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi if dpi is not None else "figure")
    return buffer.getvalue()


def save_figure(fig: Figure, path, *, dpi: float | None = None):
    """Write `fig` as a PNG file, atomically; returns the path.

    Raises
    ------
    OutputError
        The file cannot be written (see :func:`vision_torsion.fileio.atomic_write_bytes`).
    """
    return atomic_write_bytes(path, png_bytes(fig, dpi=dpi))
