"""Figures to PNG or SVG: the one way a matplotlib figure becomes image bytes or a file.

Figures are :class:`matplotlib.figure.Figure` objects drawn by the Agg canvas, never
``pyplot``: no global backend or figure registry is touched (safe in threads, no
``matplotlib.use`` at import). Files are written atomically
(:func:`vision_torsion.fileio.atomic_write_bytes`).

:func:`fixed_figure` gives a figure with its margins fixed in inches. The report's
figures use it instead of a layout engine: constrained layout measures every tick
label and title before it draws, which took a third of ``vision-torsion analyze``'s
time (``benchmarks/bench_analyze.py``); margins sized for the labels the figures
carry do the same job for a fixed cost.
"""

from __future__ import annotations

import io

import matplotlib as mpl
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .fileio import atomic_write_bytes

__all__ = ["png_bytes", "svg_bytes", "save_figure", "fixed_figure"]


#: zlib level of the PNG files: 3 encodes a report figure in about two thirds of the default
#: level 6's time for ~6 % more bytes (measured on the demo report's figures).
PNG_COMPRESS_LEVEL = 3


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
    fig.savefig(buffer, format="png", dpi=dpi if dpi is not None else "figure",
                pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    return buffer.getvalue()


def svg_bytes(fig: Figure) -> bytes:
    """Render `fig` to SVG bytes (vector: sharp at any size and in print).

    Text is drawn as glyph outlines (``svg.fonttype = "path"``), so the figure looks
    the same whatever fonts the viewer has, and the file is reproducible: no date in
    its metadata, a fixed salt for its element ids. On the report's figures it takes
    about four fifths of the PNG's time (no glyph rasterising, no compression).

    Examples
    --------
    >>> fig = Figure(figsize=(1, 1))
    >>> b"<svg" in svg_bytes(fig)
    True
    """
    from matplotlib.backends.backend_svg import FigureCanvasSVG

    FigureCanvasSVG(fig)
    buffer = io.BytesIO()
    with mpl.rc_context({"svg.fonttype": "path", "svg.hashsalt": "vision-torsion"}):
        fig.savefig(buffer, format="svg", metadata={"Date": None})
    return buffer.getvalue()


def save_figure(fig: Figure, path, *, dpi: float | None = None):
    """Write `fig` as a PNG file, atomically; returns the path.

    Raises
    ------
    OutputError
        The file cannot be written (see :func:`vision_torsion.fileio.atomic_write_bytes`).
    """
    return atomic_write_bytes(path, png_bytes(fig, dpi=dpi))


def fixed_figure(width_in: float, height_in: float, *, left: float = 0.75, right: float = 0.2, bottom: float = 0.55,
                 top: float = 0.45, wspace: float | None = None, hspace: float | None = None, **kwargs) -> Figure:
    """A figure of `width_in` × `height_in` inches whose subplot margins are fixed, in inches.

    Parameters
    ----------
    width_in, height_in : float
        Figure size (inches).
    left, right, bottom, top : float
        Margins from the figure's edges to the subplots (inches): room for the tick
        labels and axis label (left, bottom) and the title (top).
    wspace, hspace : float, optional
        Space between subplots, as a fraction of the mean subplot width / height.
    **kwargs
        Passed to :class:`matplotlib.figure.Figure` (e.g. ``dpi``).

    Examples
    --------
    >>> fig = fixed_figure(6.0, 4.0, left=0.6, top=0.4)
    >>> round(fig.subplotpars.left, 3), round(fig.subplotpars.top, 3)
    (0.1, 0.9)
    """
    fig = Figure(figsize=(width_in, height_in), layout=None, **kwargs)
    fig.subplots_adjust(left=left / width_in, right=1.0 - right / width_in, bottom=bottom / height_in,
                        top=1.0 - top / height_in, wspace=wspace, hspace=hspace)
    return fig
