"""The target: choosing the two markers whose line gives the angle.

By default the target is the two largest round markers of matching radius. When a
third marker of the same size is present the choice would be a guess, so it is an
error instead (the right pair or a clear error, never a wrong pair): narrow
``radius_range`` in the settings, or cover the extra circle.

With ``pair="distinct"`` the target is two markers of clearly different radii (the
largest usable marker and the next largest, at most :data:`DISTINCT_RATIO` of its
radius): marker identity then follows the radius and is certain at any angle
(:mod:`vision_torsion.angle`). The recommended target when images are not taken in
small steps.

Coordinates are image pixels (x, y), origin at the centre of the top-left pixel,
y downwards.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from functools import lru_cache

import numpy as np

from .detect import default_radius_range, detect_blobs
from .errors import MarkerError
from .images import grey_array_and_blocks
from .markers import Marker, find_candidates, find_marker_list, is_frame
from .settings import MeasureSettings

__all__ = [
    "PairMeasurement",
    "PairCandidates",
    "measure_pair",
    "pair_candidates",
    "select_pair",
    "radius_tolerance",
    "DISTINCT_RATIO",
    "PAIR_CHOICES",
]

#: Largest radius ratio (small/large) of a ``pair="distinct"`` target: 0.85 keeps the
#: two radii apart by many times their uncertainty (~0.01 px) and by more than the
#: matching tolerance (6 %) at any size.
DISTINCT_RATIO = 0.85
#: Named pair choices (a tuple of two row indices is also accepted).
PAIR_CHOICES = ("largest", "distinct")


def radius_tolerance(r: float) -> float:
    """Largest radius difference (px) for two markers to count as a matching pair: max(1.5 px, 6 %)."""
    return max(1.5, 0.06 * r)


@dataclass(frozen=True)
class PairMeasurement:
    """The two target markers found in one image.

    Attributes
    ----------
    first, second : Marker
        The two markers, in a canonical order (smaller x first). Which one is which
        between images is decided by the angle (:mod:`vision_torsion.angle`),
        not by this order.
    n_candidates : int
        Marker candidates examined, of any status (:func:`measure_pair` stops
        examining smaller ones once they cannot change the pair).
    """

    first: Marker
    second: Marker
    n_candidates: int = 2

    @property
    def markers(self) -> tuple[Marker, Marker]:
        return self.first, self.second

    def to_dict(self) -> dict:
        """JSON-safe dict (NaN written as None)."""

        names = _marker_fields()

        def clean(m):
            # flat fields: no recursive copy (dataclasses.asdict) needed
            return {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                    for k, v in ((k, getattr(m, k)) for k in names)}

        return {"first": clean(self.first), "second": clean(self.second), "n_candidates": self.n_candidates}

    @classmethod
    def from_dict(cls, d: dict) -> "PairMeasurement":
        """Rebuild from :meth:`to_dict` output."""
        names = set(_marker_fields())

        def marker(m):
            return Marker(**{k: (np.nan if v is None else v) for k, v in m.items() if k in names})

        return cls(first=marker(d["first"]), second=marker(d["second"]), n_candidates=int(d.get("n_candidates", 2)))


@lru_cache(maxsize=1)
def _marker_fields() -> tuple[str, ...]:
    return tuple(f.name for f in fields(Marker))


def _as_markers(table) -> list[Marker]:
    if is_frame(table):
        names = list(_marker_fields())
        missing = [c for c in ("x_px", "y_px", "radius_px", "status") if c not in table.columns]
        if missing:
            raise MarkerError(f"marker table lacks column(s) {missing}")
        rows = table.to_dict("records")
        return [Marker(**{k: r[k] for k in names if k in r}) for r in rows]
    return list(table)


def select_pair(markers, *, pair="largest", name: str = "image") -> PairMeasurement:
    """Pick the target's two markers from a marker table.

    Parameters
    ----------
    markers : pandas.DataFrame or list of Marker
        Output of :func:`~vision_torsion.markers.find_markers`.
    pair : "largest", "distinct" or tuple of int
        ``"largest"``: the two largest ``ok`` markers of matching radius (within
        :func:`radius_tolerance`); ``"distinct"``: the largest ``ok`` marker and the
        next largest, which must be at most :data:`DISTINCT_RATIO` of its radius; a
        tuple picks rows by position.
    name : str
        What to call the image in messages.

    Returns
    -------
    PairMeasurement

    Raises
    ------
    MarkerError
        Fewer than two usable markers (the message lists what was found and why the
        others were rejected), no two of matching radius, or a third marker as large
        as the pair (ambiguous).
    """
    ms = _as_markers(markers)
    if isinstance(pair, (tuple, list)):
        if len(pair) != 2:
            raise MarkerError(f"{name}: pair must name two markers, got {pair!r}")
        try:
            chosen = [ms[int(i)] for i in pair]
        except IndexError:
            raise MarkerError(f"{name}: pair {tuple(pair)} but only {len(ms)} markers were found") from None
        bad = [m for m in chosen if not m.ok]
        if bad:
            raise MarkerError(f"{name}: chosen marker is unusable ({bad[0].status}: {bad[0].message})")
    elif pair == "distinct":
        chosen = _distinct_pair(ms, name)
    elif pair == "largest":
        ok = sorted((m for m in ms if m.ok), key=lambda m: -m.radius_px)
        if len(ok) < 2:
            rejected = [f"{m.status} at ({m.x_px:.0f}, {m.y_px:.0f}): {m.message}" for m in ms if not m.ok]
            why = f"; rejected: {'; '.join(rejected)}" if rejected else ""
            raise MarkerError(f"{name}: found {len(ok)} usable marker(s), need 2{why}")
        chosen = None
        for i in range(len(ok) - 1):
            a, b = ok[i], ok[i + 1]
            if abs(a.radius_px - b.radius_px) <= radius_tolerance(a.radius_px):
                chosen = [a, b]
                if i + 2 < len(ok) and abs(ok[i + 2].radius_px - b.radius_px) <= radius_tolerance(b.radius_px):
                    raise MarkerError(
                        f"{name}: ambiguous target: {3 if i + 3 >= len(ok) else 'more than 2'} markers of radius "
                        f"≈{b.radius_px:.1f} px; narrow radius_range to pick two"
                    )
                break
        if chosen is None:
            radii = ", ".join(f"{m.radius_px:.1f}" for m in ok)
            raise MarkerError(f"{name}: no two markers of matching radius (radii {radii} px)")
    else:
        raise MarkerError(f"{name}: pair must be 'largest', 'distinct' or two indices, got {pair!r}")
    chosen.sort(key=lambda m: (m.x_px, m.y_px))
    return PairMeasurement(first=chosen[0], second=chosen[1], n_candidates=len(ms))


def _distinct_pair(ms, name):
    """The largest usable marker and the next largest of clearly smaller radius
    (``pair="distinct"``), or MarkerError."""
    ok = sorted((m for m in ms if m.ok), key=lambda m: -m.radius_px)
    if len(ok) < 2:
        rejected = [f"{m.status} at ({m.x_px:.0f}, {m.y_px:.0f}): {m.message}" for m in ms if not m.ok]
        why = f"; rejected: {'; '.join(rejected)}" if rejected else ""
        raise MarkerError(f"{name}: found {len(ok)} usable marker(s), need 2{why}")
    big, small = ok[0], ok[1]
    if small.radius_px > DISTINCT_RATIO * big.radius_px:
        raise MarkerError(
            f"{name}: pair 'distinct' needs two markers of clearly different radii, but the two largest are "
            f"{big.radius_px:.1f} and {small.radius_px:.1f} px (the smaller must be at most "
            f"{DISTINCT_RATIO:g}x the larger)"
        )
    if len(ok) > 2 and abs(ok[2].radius_px - small.radius_px) <= radius_tolerance(small.radius_px):
        raise MarkerError(
            f"{name}: ambiguous target: more than one marker of radius ≈{small.radius_px:.1f} px beside the "
            f"{big.radius_px:.1f} px one; narrow radius_range to pick two"
        )
    return [big, small]


def measure_pair(image, *, settings: MeasureSettings | None = None, name: str | None = None,
                 candidates=None) -> PairMeasurement:
    """Find the target's two markers in one image.

    Parameters
    ----------
    image : path, GreyImage or array_like
        The image (a file is loaded and validated by :func:`~vision_torsion.images.load_image`).
    settings : MeasureSettings, optional
        Polarity, radius range, fit method and pair choice; defaults otherwise.
    name : str, optional
        What to call the image in messages (the file name by default).
    candidates : PairCandidates or list of Blob, optional
        The image's candidates when already found (a session's reading threads find
        them while the image is still in their caches): :func:`pair_candidates`, or
        :func:`~vision_torsion.markers.find_candidates` with these settings.

    Returns
    -------
    PairMeasurement

    Raises
    ------
    ImageReadError
        The file is missing, corrupt or not an image.
    MarkerError
        The pair cannot be found (see :func:`select_pair`).
    """
    settings = settings or MeasureSettings()
    if name is None:
        is_path = isinstance(image, (str, bytes)) or hasattr(image, "__fspath__")
        name = str(image) if is_path else getattr(image, "path", "image")
    enough = _enough_rule(settings)
    img, block_px = grey_array_and_blocks(image, name=name, keep_integers=True)
    coarse = None
    if isinstance(candidates, PairCandidates):
        coarse, candidates = (candidates.blobs, None) if candidates.coarse else (None, candidates.blobs)
    if candidates is None and enough is not None and settings.radius_range is None:
        quick = _coarse_pair(img, settings, enough, name, blobs=coarse, block_px=block_px)
        if quick is not None:
            return quick
    markers = find_marker_list(img, settings, enough=enough, candidates=candidates, block_px=block_px)
    return select_pair(markers, pair=settings.pair, name=name)


#: Smallest radius (px) of the coarse first look of :func:`measure_pair` (a quarter
#: of the resolution, as fast as detection was before small markers were looked for).
_COARSE_MIN_RADIUS_PX = 10.0


@dataclass(frozen=True)
class PairCandidates:
    """Marker candidates found ahead of :func:`measure_pair` (a session's reading
    threads find them while the decoded image is still in their core's caches).

    Attributes
    ----------
    blobs : list of Blob
        The candidates, largest first.
    coarse : bool
        True: the coarse first look of :func:`measure_pair` (markers of 10 px and
        more, 4x reduced detection), which the full detection follows only when it
        does not settle the pair; False: the full detection of
        :func:`~vision_torsion.markers.find_candidates`.
    """

    blobs: list
    coarse: bool


def pair_candidates(img, settings: MeasureSettings) -> PairCandidates:
    """The candidates :func:`measure_pair` looks at first, for `img` (a validated 2-D
    grey array) and `settings`: the coarse first look when the radius range is the
    image's default and the pair rule can be settled from the largest markers, the
    full detection otherwise. Passed back as ``measure_pair(..., candidates=)``, they
    give the same pair as ``measure_pair`` finding them itself."""
    if settings.radius_range is None and _enough_rule(settings) is not None:
        blobs = _coarse_blobs(img, settings)
        if blobs is not None:
            return PairCandidates(blobs, True)
    return PairCandidates(find_candidates(img, settings), False)


def _coarse_blobs(img, settings: MeasureSettings):
    """Candidates of 10 px and more (4x reduced detection), or None when the image's
    default range does not reach 10 px (no coarse look is possible)."""
    r_max = default_radius_range(img.shape)[1]
    if r_max <= _COARSE_MIN_RADIUS_PX:
        return None
    return detect_blobs(img, polarity=settings.polarity, radius_range=(_COARSE_MIN_RADIUS_PX, r_max))


def _enough_rule(settings: MeasureSettings):
    """The early-stop rule of the settings' pair choice, or None (a custom choice)."""
    if not isinstance(settings.pair, str):
        return None
    return {"largest": _pair_settled, "distinct": _distinct_settled}.get(settings.pair)


def _coarse_pair(img, settings, enough, name, *, blobs=None, block_px=None):
    """The target from candidates of 10 px and more (4x reduced detection; `blobs`
    when already found), or None when they do not settle it.

    Settled means: the pair rule picks two markers from them, and both are so much
    larger than 10 px that no smaller marker, which only the full detection would
    find, could match them (and make the choice ambiguous). Then the full-resolution
    search for small markers cannot change the answer, and is skipped."""
    if blobs is None:
        blobs = _coarse_blobs(img, settings)
        if blobs is None:
            return None
    try:
        pair = select_pair(
            find_marker_list(img, settings, enough=enough, candidates=blobs, block_px=block_px), pair=settings.pair,
            name=name
        )
    except MarkerError:
        return None
    small = min(pair.first.radius_px, pair.second.radius_px)
    return pair if small - radius_tolerance(small) - 2.0 > _COARSE_MIN_RADIUS_PX else None


def _pair_settled(markers, blob) -> bool:
    """True when no smaller candidate can change the "largest" choice.

    That is when the two largest usable markers match each other and the next
    candidate (coarse radius, good to ~1 px) is clearly too small to match them,
    so it can be neither part of the pair nor make it ambiguous.
    """
    ok = sorted((m.radius_px for m in markers if m.ok), reverse=True)
    if len(ok) < 2 or ok[0] - ok[1] > radius_tolerance(ok[0]):
        return False
    return blob.radius < ok[1] - radius_tolerance(ok[1]) - 2.0


def _distinct_settled(markers, blob) -> bool:
    """True when no smaller candidate can change the "distinct" choice: the two
    largest usable markers differ clearly and the next candidate is clearly too
    small to match the smaller one (so cannot make it ambiguous)."""
    ok = sorted((m.radius_px for m in markers if m.ok), reverse=True)
    if len(ok) < 2 or ok[1] > DISTINCT_RATIO * ok[0]:
        return False
    return blob.radius < ok[1] - radius_tolerance(ok[1]) - 2.0
