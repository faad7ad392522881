"""The worker side of ``process``: measure one image, or take it from the cache.

Kept apart from :mod:`.process` so that a worker process imports only the
measuring code (numpy, OpenCV): neither pandas nor scipy nor the rest of the
session package, which cost each run about a second before its first image.
"""

from __future__ import annotations

import hashlib
import json
import logging
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path

import cv2
from threadpoolctl import threadpool_limits

from ..errors import VisionTorsionError
from ..settings import MeasureSettings
from .cache import CacheLog

__all__ = ["measure_task", "digest", "start_worker", "in_process", "one_thread", "one_thread_here"]

logger = logging.getLogger(__name__)


def digest(data: bytes) -> str:
    """SHA-256 of `data`, hex: file contents and cache keys (2.5x faster than
    BLAKE2b here: CPUs hash SHA-256 in hardware)."""
    return hashlib.sha256(data).hexdigest()


@lru_cache(maxsize=4)
def _settings_from(settings_json: str) -> MeasureSettings:
    return MeasureSettings.from_dict(json.loads(settings_json))


class _Cache:
    """This process's view of the cache: the keys cached when the run started, and
    its own log (:class:`~.cache.CacheLog`); set by :func:`start_worker` or
    :func:`in_process`."""

    known: frozenset = frozenset()
    log: CacheLog | None = None


def measure_task(task: tuple[str, str, str]) -> tuple[str, str | None, str]:
    """Measure one image unless its result is cached; runs in a worker process.

    Returns the cache key, the entry as JSON text (None when it is cached: the
    caller has the cached entries), and where it came from: "measured", "cached" or
    "unread" (the file could not be read). A measured entry is appended to this
    process's cache log at once. An unexpected exception is reported as a failure
    but not cached, so it is retried on the next run.
    """
    path, settings_json, settings_key = task
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        return "", json.dumps({"status": "failed",
                               "message": f"{path}: cannot be read ({exc.strerror or exc})"}), "unread"
    image_hash = digest(data)
    key = digest(f"{image_hash}\n{settings_key}".encode())
    if key in _Cache.known:
        return key, None, "cached"
    from ..images import decode_image
    from ..pair import measure_pair

    try:
        image = decode_image(data, name=path, keep_integers=True)
        del data
        pair = measure_pair(image, settings=_settings_from(settings_json), name=path)
        entry = {"status": "ok", "pair": pair.to_dict()}
    except VisionTorsionError as exc:
        entry = {"status": "failed", "message": str(exc)}
    except Exception as exc:  # noqa: BLE001 - one broken image must not stop a batch
        logger.exception("unexpected error measuring %s", path)
        return key, json.dumps({"status": "failed", "message":
                                f"internal error: {type(exc).__name__}: {exc}"}), "measured"
    entry["image_sha256"] = image_hash
    text = json.dumps(entry, sort_keys=True)
    if _Cache.log is not None:
        try:
            _Cache.log.append(key, text)
        except OSError as exc:  # the result stands; only a re-run would measure it again
            logger.warning("%s: result not cached (%s)", path, exc)
    return key, text, "measured"


def start_worker(cache_dir: str, run: str, known: frozenset) -> None:
    """Worker initializer: one thread for BLAS and OpenCV (:func:`one_thread`), the
    keys already cached, and a cache log of this run."""
    one_thread()
    _Cache.known = known
    _Cache.log = CacheLog(cache_dir, run)


@contextmanager
def in_process(cache_dir: str, run: str, known: frozenset):
    """:func:`start_worker` for measuring in this process (one thread while
    measuring, then as it was; the log closed afterwards)."""
    saved = _Cache.known, _Cache.log
    _Cache.known, _Cache.log = known, CacheLog(cache_dir, run)
    try:
        with one_thread_here():
            yield
    finally:
        _Cache.log.close()
        _Cache.known, _Cache.log = saved


def one_thread() -> None:
    """Worker initializer: one thread for BLAS and OpenCV in each worker.

    The pool already keeps every core busy. The measuring code's small matrix
    products (8 x ~4000) are what OpenBLAS splits over threads by default, and its
    waiting threads then compete with the other workers: two workers ran 3.5x
    slower than one.
    """
    cv2.setNumThreads(1)
    threadpool_limits(1)


@contextmanager
def one_thread_here():
    """:func:`one_thread` for this process while measuring in it, then as it was."""
    threads = cv2.getNumThreads()
    try:
        with threadpool_limits(1):
            cv2.setNumThreads(1)
            yield
    finally:
        cv2.setNumThreads(threads)
