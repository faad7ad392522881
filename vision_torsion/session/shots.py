"""Measure single photographs the way ``process`` does, sharing its cache.

``bind`` measures a camera folder before the files are bound to rows, and
``watch`` measures each photograph as soon as the camera has finished writing it.
Both go through :class:`ShotMeasurer`: the same settings, the same cache key (image
content hash + settings + measuring code) and the same cache folder as
:func:`~vision_torsion.session.process_session`, so a photograph measured at the rig
is never measured again by ``process`` or ``report``, and the other way round.
"""

from __future__ import annotations

import json
import math
import time
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import ImageReadError
from ..images import GreyImage, read_image_bytes
from .cache import CACHE_DIRNAME, CacheLog, cache_key, merge_cache, read_cache, read_logs
from .load import Session

__all__ = ["Shot", "ShotMeasurer", "image_warnings", "blur_warning", "edge_width", "polarity_note",
           "other_polarity_mismatch", "OTHER_POLARITY_SEPARATION_PX", "OTHER_POLARITY_SEPARATION_SHARE",
           "SATURATED_FRACTION", "BLUR_RATIO"]


@dataclass(frozen=True)
class Shot:
    """One photograph measured.

    Attributes
    ----------
    path : pathlib.Path
    pair : PairMeasurement or None
        The target found, None when measuring failed.
    message : str
        Why it failed ("" when it did not).
    image : GreyImage or None
        The decoded image when it was measured now (None when cached or unreadable).
    cached : bool
        The result came from the cache.
    image_hash : str
        XXH3-128 of the file's bytes ("" when it could not be read).
    undecodable : bool
        The file could not be decoded (truncated, still being written, or not an
        image); nothing was cached for it.
    timings : dict
        Seconds spent: ``read`` (file read and hash), ``decode``, ``measure``.
    saturated_fraction : float
        Fraction of the pixels at full scale (NaN when not known: not decoded).
    """

    path: Path
    pair: object | None
    message: str
    image: GreyImage | None = None
    cached: bool = False
    timings: dict = field(default_factory=dict)
    undecodable: bool = False
    image_hash: str = ""
    saturated_fraction: float = math.nan


#: An image with more than this fraction of its pixels at full scale is saturated.
SATURATED_FRACTION = 0.005
#: Marker edges this many times as wide as in the orientation's reference: blurred.
BLUR_RATIO = 1.5


def edge_width(pair) -> float:
    """Mean fitted edge width of the pair's two markers (px; NaN when unknown)."""
    if pair is None:
        return math.nan
    widths = [getattr(m, "edge_width_px", math.nan) for m in (pair.first, pair.second)]
    widths = [w for w in widths if isinstance(w, (int, float)) and math.isfinite(w)]
    return sum(widths) / len(widths) if widths else math.nan


def image_warnings(pair, reference, saturated: float) -> list[str]:
    """The image checks of ``watch`` and ``bind``, one rule for both.

    Parameters
    ----------
    pair : PairMeasurement or None
        The image's target.
    reference : PairMeasurement or None
        Its orientation's reference image's target (None: the image is the
        reference, or the reference failed: no blur check).
    saturated : float
        Fraction of its pixels at full scale (:attr:`Shot.saturated_fraction`).

    Returns
    -------
    list of str
        "saturated: ..." when more than :data:`SATURATED_FRACTION` of the pixels
        are at full scale; "blurred: ..." when the markers' edges are more than
        :data:`BLUR_RATIO` times as wide as the reference's (camera shake, focus).
    """
    out = []
    if math.isfinite(saturated) and saturated > SATURATED_FRACTION:
        out.append(f"saturated: {100 * saturated:.1f} % of the pixels at full scale "
                   "(shorten the exposure or dim the light)")
    if reference is not None and (blur := blur_warning(edge_width(pair), edge_width(reference))):
        out.append(blur)
    return out


def blur_warning(width_px: float, reference_px: float) -> str:
    """"blurred: ..." when the marker edges (mean fitted edge width, px) are more than
    :data:`BLUR_RATIO` times as wide as the reference image's; "" otherwise or when
    either is unknown (NaN). The rule of :func:`image_warnings`, for any markers."""
    if math.isfinite(width_px) and math.isfinite(reference_px) and width_px > BLUR_RATIO * reference_px:
        return (f"blurred: marker edges {width_px:.1f} px wide against {reference_px:.1f} px in the "
                "reference (camera shake, or focus?); shoot it again")
    return ""


def polarity_note(pair, polarity: str) -> str:
    """A note when the image's markers have the other polarity than the session's.

    The markers are still measured (the fit finds an edge either way); the sign of
    their fitted contrast (negative: darker than around them) tells which they
    are. Returns "" when they are as the session says, or unknown.
    """
    if pair is None:
        return ""
    contrasts = [getattr(m, "contrast_dn", math.nan) for m in (pair.first, pair.second)]
    if not all(isinstance(c, (int, float)) and math.isfinite(c) for c in contrasts):
        return ""
    seen = "dark" if max(contrasts) < 0 else "bright" if min(contrasts) > 0 else None
    if seen is None or seen == polarity:
        return ""
    return (f"note: the markers are {seen} here, the session's are {polarity} (the lighting "
            "changed?); measured all the same")


#: A pair of the other polarity than the session's is the target's only if its
#: markers' separation is within this many px, or this share of the reference's
#: separation (the larger), of the reference's: a turned target or changed lights
#: keep the separation, two bright specks found instead of the markers do not.
OTHER_POLARITY_SEPARATION_PX = 2.0
OTHER_POLARITY_SEPARATION_SHARE = 0.02


def other_polarity_mismatch(pair, reference, polarity: str) -> str:
    """Why `pair`, whose markers have the other polarity than the session's
    (:func:`polarity_note`), is not the target seen in `reference`: its markers'
    separation differs from the reference's by more than
    :data:`OTHER_POLARITY_SEPARATION_PX` and :data:`OTHER_POLARITY_SEPARATION_SHARE`
    of it. "" when it matches, when the polarity is the session's, or when either
    pair is missing."""
    if pair is None or reference is None or not polarity_note(pair, polarity):
        return ""
    found, expected = (math.hypot(p.first.x_px - p.second.x_px, p.first.y_px - p.second.y_px)
                       for p in (pair, reference))
    if abs(found - expected) <= max(OTHER_POLARITY_SEPARATION_PX, OTHER_POLARITY_SEPARATION_SHARE * expected):
        return ""
    return (f"no target of the session's polarity ({polarity}) found, and the two markers of the other "
            f"polarity are {found:.1f} px apart where the reference's are {expected:.1f} px: not the target")


class ShotMeasurer:
    """Measures photographs of a session one at a time (use as a context manager).

    Parameters
    ----------
    session : Session
    out_dir : path-like
        The output folder whose cache is shared with ``process``.
    measure : callable, optional
        The measuring function (:func:`~vision_torsion.pair.measure_pair` by
        default; the seam ``process_session(measure=...)`` has too).
    """

    def __init__(self, session: Session, out_dir, *, measure=None):
        from ..pair import measure_pair
        from .process import session_measuring  # process's measuring function, cache key and check

        self.settings = session.settings
        self.settings_json = json.dumps(self.settings.to_dict(), sort_keys=True)
        measure, self.key, self._check = session_measuring(session, measure_pair if measure is None else measure)
        self.target = session.config.target
        self.cache_dir = Path(out_dir) / CACHE_DIRNAME
        self.cached, self._logs = read_cache(self.cache_dir, check=self._check)
        self._run = CacheLog.new_run()
        self._stack = ExitStack()
        self._measure = None if measure is measure_pair else measure

    def __enter__(self):
        from .worker import in_process

        extra = {} if self._measure is None else {"measure": self._measure}
        self._stack.enter_context(in_process(str(self.cache_dir), self._run, frozenset(self.cached), **extra))
        return self

    def __exit__(self, *exc):
        self._stack.close()
        new = CacheLog(self.cache_dir, self._run).files()
        if new or len(self._logs) > 1:
            merge_cache(self.cache_dir, {**self.cached, **read_logs(new, check=self._check)},
                        self._logs + new)
        return False

    def measure(self, path) -> Shot:
        """Measure the photograph at `path` (or take its result from the cache).

        Never raises for a bad image: an unreadable, undecodable or unmeasurable
        file gives a Shot with ``pair=None`` and the reason.
        """
        from ..pair import PairMeasurement
        from .worker import content_hash, finish_task, prepare_task

        path = Path(path)
        t0 = time.perf_counter()
        try:  # its size checked before it is read (a non-image is refused by the decoder)
            data = read_image_bytes(path, signature=False)
        except ImageReadError as exc:
            return Shot(path, None, str(exc).replace(str(path), path.name))
        image_hash = content_hash(data)
        key = cache_key(image_hash, self.key)
        t1 = time.perf_counter()
        entry = self.cached.get(key)
        image, cached = None, entry is not None
        t2 = t1
        if entry is None:
            # process's own steps (decode, candidates, measure): one key, one result
            task = (str(path), self.settings_json, self.key)
            read = prepare_task(data, task)
            t2 = time.perf_counter()
            if read.undecodable:  # not cached: it may be a file still being written
                message = str(read.error).replace(str(path), path.name)
                return Shot(path, None, message, undecodable=True, image_hash=image_hash,
                            timings={"read": t1 - t0, "decode": t2 - t1, "measure": 0.0})
            image = read.image
            if read.result is not None:  # cached by another Shot of this run
                entry = self.cached.get(key)
            if entry is None:
                _, text, _ = finish_task(read, task)
                entry = json.loads(text)
                if entry["status"] == "ok":
                    self.cached[key] = entry
        t3 = time.perf_counter()
        timings = {"read": t1 - t0, "decode": t2 - t1, "measure": t3 - t2}
        saturated = entry.get("saturated_fraction", math.nan)
        saturated = float(saturated) if isinstance(saturated, (int, float)) else math.nan
        if entry["status"] != "ok":
            message = entry.get("message", "").replace(str(path), path.name)
            return Shot(path, None, message, image, cached, timings, image_hash=image_hash,
                        saturated_fraction=saturated)
        if self.target is None:
            pair, message = PairMeasurement.from_dict(entry["pair"]), ""
        else:  # an N-marker target: two of its dots, named from the whole layout
            from .targetrows import FoundMarkers, target_pair

            pair, message = target_pair(FoundMarkers.from_dict(entry["pair"]), self.target, name=path.name)
        return Shot(path, pair, message, image, cached, timings, image_hash=image_hash,
                    saturated_fraction=saturated)
