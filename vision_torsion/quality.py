"""Flags on measurements that succeeded but should not be trusted as they are.

A marker whose fit residual is far above the noise of its sequence marks the image
``suspect``: its angle is kept (so the user can look) but it is not used as good
data. The noise level is the sequence's own: the median over its images of the
markers' edge residual (``residual_rms_px``: the RMS radial distance of the edge
points from the fitted circle), so a camera, a lens and a target that are simply
noisier raise it for every image alike, and a corrupt reference image does not set
it. What raises one image's residual: a JPEG whose damage the decoder did not notice
(single flipped bytes of a JPEG gave angles 9-15 sigma off with residuals 2.8-2.9
times the others'), a speck or a smear on a marker, motion blur.

Threshold: :data:`SUSPECT_RESIDUAL_RATIO` (2). Over the seven ready scenes (12
renders each, clean), the largest ratio was 1.20.

An image is also suspect when one of its target markers lay beside a region as dark
(bright) as itself, which was cut from its ring (:attr:`Marker.steep_cut
<vision_torsion.markers.Marker.steep_cut>`): its centre is then good to
:data:`STEEP_CUT_PX` (0.4 px), more than the angle's std allows for.
"""

from __future__ import annotations

import math

__all__ = ["residual_flags", "SUSPECT_RESIDUAL_RATIO", "SUSPECT", "STEEP_CUT_PX"]

#: A marker residual this many times the sequence's typical one makes its image suspect.
SUSPECT_RESIDUAL_RATIO = 2.0
#: The status of a suspect measurement.
SUSPECT = "suspect"


def _residuals(pair) -> list[float] | None:
    out = []
    for marker in (getattr(pair, "first", None), getattr(pair, "second", None)):
        r = getattr(marker, "residual_rms_px", None)
        if r is None or not math.isfinite(r) or r <= 0:
            return None
        out.append(float(r))
    return out


#: Error (px) an ``ok`` marker whose ring held a surround as dark as itself
#: (:attr:`~vision_torsion.pixelfit.DiscFit.steep_cut`) is good to, which its
#: marker's message (:data:`vision_torsion.markers.STEEP_CUT_MESSAGE`) and its image's
#: ``suspect`` flag state: on rendered shadow edges across markers of 8-35 px radius
#: the fits of that kind left ``ok`` (``markers._uneven_light``,
#: ``markers._steep_edge_bent``) were up to 0.39 px off
#: (``benchmarks/bench_light_edge.py``; 0.07-0.13 px beside a card's edge).
STEEP_CUT_PX = 0.4


def _steep_cut(pair) -> str:
    """"" or why `pair`'s image is suspect for a marker fitted beside a dark surround."""
    for k, marker in enumerate((getattr(pair, "first", None), getattr(pair, "second", None)), start=1):
        if getattr(marker, "steep_cut", False):
            return (f"suspect: marker {k} lies beside a region as dark (bright) as itself, such as an edge or "
                    f"a shadow, cut from its fit: its centre may be off by up to {STEEP_CUT_PX} px, more than the "
                    "angle's std allows for")
    return ""


def _median(values: list[float]) -> float:
    """The middle value, or the mean of the two middle ones: numpy's and statistics'
    median to the bit, without their imports (statistics pulls in fractions and
    decimal; numpy's median, numpy.ma: 3-10 ms of every process run)."""
    ordered = sorted(values)
    mid = len(ordered) // 2
    return float(ordered[mid]) if len(ordered) % 2 else (ordered[mid - 1] + ordered[mid]) / 2


def residual_flags(pairs) -> list[str]:
    """Per pair: "" or why its image is suspect (see the module docstring).

    Parameters
    ----------
    pairs : sequence of PairMeasurement or None
        The marker pairs of one sequence (one camera, one target); None for images
        that failed. Fewer than three usable pairs: nothing is flagged.

    Returns
    -------
    list of str
        ``"suspect: marker K's edge residual R px is N times the sequence's typical
        T px (a damaged or corrupt image, or something on the marker?)"``, or that
        marker K lies beside a dark surround (whatever the number of pairs), or "".
    """
    steep = [_steep_cut(p) for p in pairs]
    residuals = [None if p is None else _residuals(p) for p in pairs]
    levels = [sum(r) / 2 for r in residuals if r is not None]
    if len(levels) < 3:
        return steep
    typical = _median(levels)
    flags = []
    for r, surround in zip(residuals, steep):
        if surround or r is None or not max(r) > SUSPECT_RESIDUAL_RATIO * typical:
            flags.append(surround)
            continue
        k = 1 if r[0] >= r[1] else 2
        flags.append(f"suspect: marker {k}'s edge residual {max(r):.3g} px is {max(r) / typical:.1f} "
                     f"times the sequence's typical {typical:.3g} px (a damaged or corrupt image, or "
                     "something on the marker?)")
    return flags
