"""Target descriptions: where the dots are on the printed target, in millimetres.

A target is a set of round dots on the torque disk: a **ring** of N equal dots around
the shaft, a **grid** of rows × columns, or any list of **dots**. Which dot is which
must be certain in every image, so a ring or a grid carries an *index mark*: one dot
(dot 0) of a clearly different diameter. A ring of identical dots repeats every
360°/N and a square grid every 90°; such a target is still accepted (its images are
reported ``ambiguous``, see :mod:`vision_torsion.rigid`), and
:meth:`Target.symmetry_turns_deg` says so before anything is photographed.

Coordinates are those of the printed page seen from the camera: x to the right,
y **downwards** (like image coordinates), in mm, with the origin on the shaft axis
(the ring's centre, the grid's centre). A dot's angular position on a ring is
counter-clockwise as displayed from the +x axis, dot 0 at 0°.

TOML layout (one ``[target]`` table, in its own file or in session.toml)::

    [target]
    layout = "ring"            # "ring", "grid" or "dots"
    markers = 16               # ring: number of dots
    diameter_mm = 80.0         # ring: diameter of the circle through the dot centres
    rows = 5                   # grid: rows and columns, centre to centre pitch_mm
    columns = 5
    pitch_mm = 10.0
    x_mm = [...]               # dots: centres (mm)
    y_mm = [...]
    dot_diameter_mm = 9.6      # every dot (a list of one per dot for "dots")
    index_diameter_mm = 12.0   # ring/grid: diameter of dot 0, the index mark (omit: none)

Ready targets ship with the package (``vision_torsion/targets/*.toml``) and are named
by their stem (``ring16``, ``ring8``, ``grid5``, ``pair_distinct``), see
:func:`load_target`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import TargetError
from .resources import TARGETS, available, named_file
from .textfiles import read_toml

__all__ = [
    "Target",
    "ring_target",
    "ring_dot_diameter_mm",
    "grid_target",
    "dots_target",
    "target_from_dict",
    "load_target",
    "ready_targets",
    "LAYOUTS",
    "MIN_INDEX_RATIO",
]

#: Layouts a description may name.
LAYOUTS = ("ring", "grid", "dots")
#: Smallest ratio (larger/smaller) of the index dot's diameter to the others': the
#: dots' fitted radii are good to well under 1 %, and 15 % keeps the index certain
#: under a few per cent of print and perspective error.
MIN_INDEX_RATIO = 1.15
#: Relative diameter difference below which two dots count as the same size when the
#: symmetry of a layout is judged.
_SAME_SIZE = 0.05


@dataclass(frozen=True)
class Target:
    """A printed target: dot centres and diameters in mm (x right, y down, origin on the shaft axis).

    Attributes
    ----------
    name : str
        Name (the ready file's stem, or the file's).
    layout : {"ring", "grid", "dots"}
        How the dots were laid out.
    x_mm, y_mm : tuple of float
        Dot centres (mm).
    diameter_mm : tuple of float
        Dot diameters (mm).
    index : tuple of int
        Dots that carry the identity (the index mark): their size differs from the
        others'. Empty for a layout without one.
    spec : tuple of (str, value)
        The description's keys it was made from (for :meth:`to_toml`).
    """

    name: str
    layout: str
    x_mm: tuple
    y_mm: tuple
    diameter_mm: tuple
    index: tuple = ()
    spec: tuple = field(default=(), repr=False, compare=False)

    def to_toml(self) -> str:
        """The ``[target]`` table that describes this target (for session.toml or a file).

        Examples
        --------
        >>> print(ring_target(8, diameter_mm=80, dot_diameter_mm=12, index_diameter_mm=15).to_toml())
        [target]
        layout = "ring"
        markers = 8
        diameter_mm = 80.0
        dot_diameter_mm = 12.0
        index_diameter_mm = 15.0
        """
        items = dict(self.spec) or {"layout": "dots", "x_mm": list(self.x_mm), "y_mm": list(self.y_mm),
                                    "dot_diameter_mm": list(self.diameter_mm)}

        def fmt(v):
            if isinstance(v, (list, tuple)):
                return "[" + ", ".join(fmt(x) for x in v) + "]"
            if isinstance(v, str):
                return f'"{v}"'
            return repr(v)

        return "[target]\n" + "\n".join(f"{k} = {fmt(v)}" for k, v in items.items() if v is not None)

    @property
    def n_markers(self) -> int:
        """Number of dots."""
        return len(self.x_mm)

    @property
    def centres_mm(self) -> np.ndarray:
        """(n, 2) dot centres (mm), x right, y down."""
        return np.column_stack([self.x_mm, self.y_mm]).astype(np.float64)

    @property
    def radii_mm(self) -> np.ndarray:
        """(n,) dot radii (mm)."""
        return np.asarray(self.diameter_mm, dtype=np.float64) / 2.0

    @property
    def min_spacing_mm(self) -> float:
        """Smallest centre-to-centre distance (mm)."""
        c = self.centres_mm
        d = np.hypot(*(c[:, None, :] - c[None, :, :]).transpose(2, 0, 1))
        d[np.diag_indices_from(d)] = np.inf
        return float(d.min())

    @property
    def extent_mm(self) -> float:
        """Radius (mm) of the smallest circle about the origin that holds every dot."""
        c = self.centres_mm
        return float(np.max(np.hypot(c[:, 0], c[:, 1]) + self.radii_mm))

    def symmetry_turns_deg(self) -> tuple:
        """Turns (deg, 0 < turn < 360) about the origin that map the target onto itself.

        A target with any such turn cannot tell its images' identities apart: dot
        sizes within 5 % count as equal, positions within 1 % of the smallest spacing.
        Empty for a target whose identity is certain.

        Examples
        --------
        >>> ring_target(8, diameter_mm=80, dot_diameter_mm=8).symmetry_turns_deg()
        (45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0)
        >>> ring_target(8, diameter_mm=80, dot_diameter_mm=8, index_diameter_mm=10).symmetry_turns_deg()
        ()
        """
        c = self.centres_mm
        tol = 0.01 * self.min_spacing_mm
        rho = np.hypot(c[:, 0], c[:, 1])
        off_axis = np.flatnonzero(rho > tol)
        if off_axis.size == 0:
            return ()
        # a self-map sends an anchor dot onto a dot at the same distance from the axis
        anchor = off_axis[0]
        polar = np.degrees(np.arctan2(-c[:, 1], c[:, 0]))  # counter-clockwise as displayed
        turns = set()
        for k in off_axis[1:]:
            if abs(rho[k] - rho[anchor]) > tol:
                continue
            turn = float((polar[k] - polar[anchor]) % 360.0)
            if 1e-6 < turn < 360.0 - 1e-6 and self._maps_onto_itself(turn, tol):
                turns.add(round(turn, 9))
        return tuple(sorted(turns))

    def _maps_onto_itself(self, turn_deg: float, tol: float) -> bool:
        a = math.radians(turn_deg)
        c, s = math.cos(a), math.sin(a)
        pts, r = self.centres_mm, self.radii_mm
        # counter-clockwise as displayed with y down
        moved = np.column_stack([c * pts[:, 0] + s * pts[:, 1], -s * pts[:, 0] + c * pts[:, 1]])
        d = np.hypot(*(moved[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
        near = d.argmin(axis=1)
        if np.any(d[np.arange(len(pts)), near] > tol):
            return False
        return bool(np.all(np.abs(r[near] - r) <= _SAME_SIZE * np.maximum(r[near], r)))


def _check_positive(value, field: str, where: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TargetError(f"{where}[target] {field} must be a number, got {value!r}", reason="bad_value") from None
    if isinstance(value, bool) or not math.isfinite(v) or v <= 0:
        raise TargetError(f"{where}[target] {field} must be a positive number (mm), got {value!r}",
                          reason="bad_value")
    return v


def _check_count(value, field: str, where: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or int(value) != value or value < minimum:
        raise TargetError(f"{where}[target] {field} must be a whole number >= {minimum}, got {value!r}",
                          reason="bad_value")
    return int(value)


def _finish(name, layout, x, y, d, index, where, spec) -> Target:
    target = Target(name=name, layout=layout, x_mm=tuple(float(v) for v in x), y_mm=tuple(float(v) for v in y),
                    diameter_mm=tuple(float(v) for v in d), index=tuple(index), spec=spec)
    c, r = target.centres_mm, target.radii_mm
    for i in range(target.n_markers):
        for j in range(i + 1, target.n_markers):
            gap = math.hypot(*(c[i] - c[j])) - r[i] - r[j]
            if gap <= 0:
                raise TargetError(f"{where}[target] dots {i} and {j} overlap (gap {gap:.3g} mm): "
                                  "make the dots smaller or the layout larger", reason="overlapping_dots")
    return target


def _index_diameter(doc, dot, where):
    if doc.get("index_diameter_mm") in (None, 0, 0.0):
        return None
    idx = _check_positive(doc["index_diameter_mm"], "index_diameter_mm", where)
    if max(idx, dot) / min(idx, dot) < MIN_INDEX_RATIO:
        raise TargetError(f"{where}[target] index_diameter_mm {idx:g} is within {MIN_INDEX_RATIO:g}x of "
                          f"dot_diameter_mm {dot:g}: the index mark must differ clearly in size",
                          reason="weak_index")
    return idx


def ring_dot_diameter_mm(markers: int, diameter_mm: float) -> float:
    """Dot diameter (mm) for a ring: as large as leaves a gap of one dot radius
    beside an index dot 1.25 times larger, and at most 12 % of the ring's diameter.

    The angle's noise falls as 1/(ring radius·√(N·r)) with r the dots' radius;
    dots larger than this gain little more and crowd the neighbours' edges.

    Examples
    --------
    >>> round(ring_dot_diameter_mm(16, 80.0), 2), round(ring_dot_diameter_mm(4, 80.0), 2)
    (9.6, 9.6)
    """
    chord = diameter_mm * math.sin(math.pi / markers)
    return min(0.12 * diameter_mm, 2.0 * chord / 3.25)


def ring_target(markers: int, *, diameter_mm: float, dot_diameter_mm: float,
                index_diameter_mm: float | None = None, name: str = "") -> Target:
    """A ring of `markers` dots equally spaced on a circle of `diameter_mm` about the shaft.

    Parameters
    ----------
    markers : int
        Number of dots (>= 2).
    diameter_mm : float
        Diameter of the circle through the dot centres (mm).
    dot_diameter_mm : float
        Diameter of each dot (mm).
    index_diameter_mm : float, optional
        Diameter of dot 0 (at 0°, on the +x axis), the index mark; at least
        :data:`MIN_INDEX_RATIO` times larger or smaller than the others. Without it
        the ring repeats every 360°/`markers`.
    name : str
        Name of the target.

    Returns
    -------
    Target

    Raises
    ------
    TargetError
        A count or size out of range, dots that overlap, an index too close in size.

    Examples
    --------
    >>> t = ring_target(16, diameter_mm=80, dot_diameter_mm=9.6, index_diameter_mm=12)
    >>> t.n_markers, t.index, round(t.x_mm[4], 9), round(t.y_mm[4], 9)
    (16, (0,), 0.0, -40.0)
    """
    return target_from_dict({"layout": "ring", "markers": markers, "diameter_mm": diameter_mm,
                             "dot_diameter_mm": dot_diameter_mm, "index_diameter_mm": index_diameter_mm},
                            name=name or f"ring{markers}")


def grid_target(rows: int, columns: int, *, pitch_mm: float, dot_diameter_mm: float,
                index_diameter_mm: float | None = None, name: str = "") -> Target:
    """A grid of `rows` × `columns` dots, `pitch_mm` apart, centred on the shaft.

    Dot 0 (the top-left corner as printed) is the index mark when
    `index_diameter_mm` is given. Parameters, Raises as :func:`ring_target`.

    Examples
    --------
    >>> grid_target(3, 4, pitch_mm=10, dot_diameter_mm=4, index_diameter_mm=6).n_markers
    12
    """
    return target_from_dict({"layout": "grid", "rows": rows, "columns": columns, "pitch_mm": pitch_mm,
                             "dot_diameter_mm": dot_diameter_mm, "index_diameter_mm": index_diameter_mm},
                            name=name or f"grid{rows}x{columns}")


def dots_target(x_mm, y_mm, diameter_mm, *, name: str = "dots") -> Target:
    """A target of any dots (mm, x right, y down, origin on the shaft axis).

    Dots whose diameter differs from the most common one by at least
    :data:`MIN_INDEX_RATIO` are its index marks. Raises as :func:`ring_target`.
    """
    return target_from_dict({"layout": "dots", "x_mm": list(x_mm), "y_mm": list(y_mm),
                             "dot_diameter_mm": list(diameter_mm)}, name=name)


def target_from_dict(doc: dict, *, name: str = "target", where: str = "") -> Target:
    """A :class:`Target` from the keys of a ``[target]`` table (see the module docstring).

    Parameters
    ----------
    doc : dict
        The table.
    name : str
        Name given to the target.
    where : str
        Prefix of the messages (the file), e.g. ``"session.toml: "``.

    Raises
    ------
    TargetError
        An unknown layout or key, a missing or invalid field (named), overlapping dots.
    """
    if not isinstance(doc, dict):
        raise TargetError(f"{where}[target] must be a table, got {type(doc).__name__}", reason="bad_value")
    layout = doc.get("layout")
    if layout not in LAYOUTS:
        raise TargetError(f"{where}[target] layout must be one of {', '.join(LAYOUTS)}, got {layout!r}",
                          reason="bad_value")
    known = {"ring": {"markers", "diameter_mm"}, "grid": {"rows", "columns", "pitch_mm"},
             "dots": {"x_mm", "y_mm"}}[layout] | {"layout", "dot_diameter_mm", "index_diameter_mm", "name"}
    unknown = sorted(set(doc) - known)
    if unknown:
        raise TargetError(f"{where}[target] unknown key(s) for layout {layout!r}: {', '.join(unknown)} "
                          f"(known: {', '.join(sorted(known))})", reason="unknown_key")
    missing = sorted(k for k in known - {"index_diameter_mm", "name"} if doc.get(k) is None)
    if missing:
        raise TargetError(f"{where}[target] layout {layout!r} needs {', '.join(missing)}", reason="missing_key")
    name = str(doc.get("name") or name)
    if layout == "dots":
        x, y, d = doc["x_mm"], doc["y_mm"], doc["dot_diameter_mm"]
        if not isinstance(d, list):
            d = [d] * (len(x) if isinstance(x, list) else 0)
        if not (isinstance(x, list) and isinstance(y, list)) or not len(x) == len(y) == len(d) or len(x) < 2:
            raise TargetError(f"{where}[target] x_mm, y_mm and dot_diameter_mm must be lists of one value per "
                              f"dot, at least 2 dots", reason="bad_value")
        for key, values in (("x_mm", x), ("y_mm", y)):
            bad = [v for v in values if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)]
            if bad:
                raise TargetError(f"{where}[target] {key} must hold finite numbers (mm), got {bad[0]!r}",
                                  reason="bad_value")
        x, y = [float(v) for v in x], [float(v) for v in y]
        d = [_check_positive(v, "dot_diameter_mm", where) for v in d]
        common = float(np.median(d))
        index = [i for i, v in enumerate(d) if max(v, common) / min(v, common) >= MIN_INDEX_RATIO]
        spec = (("layout", "dots"), ("x_mm", x), ("y_mm", y), ("dot_diameter_mm", d))
        return _finish(name, layout, x, y, d, index, where, spec)
    dot = _check_positive(doc["dot_diameter_mm"], "dot_diameter_mm", where)
    idx = _index_diameter(doc, dot, where)
    if layout == "ring":
        n = _check_count(doc["markers"], "markers", where, 2)
        rad = _check_positive(doc["diameter_mm"], "diameter_mm", where) / 2.0
        phi = 2.0 * np.pi * np.arange(n) / n
        x, y = rad * np.cos(phi), -rad * np.sin(phi)
        x[np.abs(x) < 1e-12] = 0.0
        y[np.abs(y) < 1e-12] = 0.0
    else:
        rows = _check_count(doc["rows"], "rows", where, 1)
        cols = _check_count(doc["columns"], "columns", where, 1)
        if rows * cols < 2:
            raise TargetError(f"{where}[target] a grid needs at least 2 dots, got {rows}x{cols}", reason="bad_value")
        pitch = _check_positive(doc["pitch_mm"], "pitch_mm", where)
        yy, xx = np.mgrid[0:rows, 0:cols]
        x = (xx.ravel() - (cols - 1) / 2.0) * pitch
        y = (yy.ravel() - (rows - 1) / 2.0) * pitch
    d = [dot] * len(x)
    index = []
    if idx is not None:
        d[0] = idx
        index = [0]
    shape = (("markers", n), ("diameter_mm", 2.0 * rad)) if layout == "ring" else \
        (("rows", rows), ("columns", cols), ("pitch_mm", pitch))
    spec = (("layout", layout), *shape, ("dot_diameter_mm", dot), ("index_diameter_mm", idx))
    return _finish(name, layout, x, y, d, index, where, spec)


def ready_targets() -> list[str]:
    """Names of the targets shipped with the package."""
    return available(TARGETS)


def load_target(path) -> Target:
    """Read a target: a TOML file with a ``[target]`` table, or a ready target's name.

    Parameters
    ----------
    path : str or os.PathLike
        A file, or a ready target's name (:func:`ready_targets`).

    Returns
    -------
    Target

    Raises
    ------
    TargetError
        No such file or ready target, an unreadable file, no ``[target]`` table, or
        an invalid description (the field named).

    Examples
    --------
    >>> t = load_target("ring16")
    >>> t.n_markers, t.index, t.symmetry_turns_deg()
    (16, (0,), ())
    """
    file = named_file(path, TARGETS, error=TargetError, what="target")
    doc = read_toml(file, what="a target description", error=TargetError)
    if "target" not in doc:
        raise TargetError(f"{file}: no [target] table", reason="missing_key")
    return target_from_dict(doc["target"], name=file.stem, where=f"{file}: ")
