"""Measurement settings: what the marker finder and the angle need to know.

One frozen dataclass so that every command (``measure``, ``process``,
``check-accuracy``) measures the same way and a session cache can be keyed on the
settings (:meth:`MeasureSettings.to_dict`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

from .errors import VisionTorsionError

__all__ = ["MeasureSettings", "FIT_METHODS", "POLARITIES"]

#: Marker-fit methods by name: ``"pixels"`` (default: maximum-likelihood fit of the
#: blurred-disc model to the pixels, :mod:`vision_torsion.pixelfit`), and three fits
#: to sub-pixel edge points (:mod:`vision_torsion.edges`): ``"geometric"``
#: (orthogonal-distance circle fit with outlier rejection), ``"algebraic"`` (the
#: paper's Kasa fit of Q = sum[(x-a)^2 + (y-b)^2 - r^2]^2) and ``"ellipse"`` (for
#: oblique views).
FIT_METHODS = ("pixels", "geometric", "algebraic", "ellipse")
POLARITIES = ("dark", "bright")


@dataclass(frozen=True)
class MeasureSettings:
    """How markers are found and fitted.

    Parameters
    ----------
    polarity : {"dark", "bright"}
        Dark markers on a bright disk, or bright markers on a dark disk.
    radius_range : tuple of float, optional
        (smallest, largest) marker radius in pixels; None accepts 3 px up to a fifth
        of the shorter image side (:func:`vision_torsion.detect.default_radius_range`).
    fit : {"pixels", "geometric", "algebraic", "ellipse"}
        Marker-fit method (see :data:`FIT_METHODS`).
    pair : {"largest", "distinct"} or tuple of int
        Which two markers make the target: ``"largest"`` picks the two largest
        round markers of matching radius; ``"distinct"`` the largest and the next
        largest of clearly smaller radius (a two-radii target, whose identity is
        certain at any angle; see :mod:`vision_torsion.pair`).
    correction : str, optional
        Path of a saved plane/lens correction (TOML or JSON) applied to the marker
        centres before the angle is computed.
    """

    polarity: str = "dark"
    radius_range: tuple[float, float] | None = None
    fit: str = "pixels"
    pair: str = "largest"
    correction: str | None = None

    def __post_init__(self):
        if self.polarity not in POLARITIES:
            raise VisionTorsionError(
                f"polarity must be one of {POLARITIES}, got {self.polarity!r}"
            )
        if self.fit not in FIT_METHODS:
            raise VisionTorsionError(f"fit must be one of {FIT_METHODS}, got {self.fit!r}")
        if self.radius_range is not None:
            lo, hi = (float(v) for v in self.radius_range)
            if not (0 < lo < hi):
                raise VisionTorsionError(
                    f"radius_range must be (smallest, largest) with 0 < smallest < largest, "
                    f"got {self.radius_range!r}"
                )
            object.__setattr__(self, "radius_range", (lo, hi))

    def to_dict(self) -> dict:
        """Plain, JSON-safe dict (used as part of cache keys)."""
        d = asdict(self)
        if d["radius_range"] is not None:
            d["radius_range"] = list(d["radius_range"])
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "MeasureSettings":
        """Build from a dict such as the ``[markers]`` table of a session.toml."""
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise VisionTorsionError(
                f"unknown measurement setting(s): {', '.join(sorted(unknown))}"
            )
        d = dict(d)
        if d.get("radius_range") is not None:
            d["radius_range"] = tuple(d["radius_range"])
        return cls(**d)
