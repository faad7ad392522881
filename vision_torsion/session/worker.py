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
from ..fileio import atomic_write_text
from ..settings import MeasureSettings

__all__ = ["measure_task", "digest", "one_thread", "one_thread_here"]

logger = logging.getLogger(__name__)


def digest(data: bytes) -> str:
    """SHA-256 of `data`, hex: file contents and cache keys (2.5x faster than
    BLAKE2b here: CPUs hash SHA-256 in hardware)."""
    return hashlib.sha256(data).hexdigest()


@lru_cache(maxsize=4)
def _settings_from(settings_json: str) -> MeasureSettings:
    return MeasureSettings.from_dict(json.loads(settings_json))


def measure_task(task: tuple[str, str, str, str]) -> tuple[str, str]:
    """Measure one image, or take it from the cache; runs in a worker process.

    Returns the cache entry as JSON text and where it came from: "measured",
    "cached" or "unread" (the file could not be read). An unexpected exception is
    reported as a failure but not cached, so it is retried on the next run.
    """
    path, settings_json, settings_key, cache_dir = task
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        return json.dumps({"status": "failed",
                           "message": f"{path}: cannot be read ({exc.strerror or exc})"}), "unread"
    image_hash = digest(data)
    key = digest(f"{image_hash}\n{settings_key}".encode())
    cache_file = Path(cache_dir) / key[:2] / f"{key}.json"
    try:
        text = cache_file.read_text(encoding="utf-8")
        if json.loads(text).get("status") in ("ok", "failed"):
            return text, "cached"
    except (OSError, ValueError, AttributeError):
        pass  # no entry, or a damaged one: measure again
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
        return json.dumps({"status": "failed", "message":
                           f"internal error: {type(exc).__name__}: {exc}"}), "measured"
    entry["image_sha256"] = image_hash
    text = json.dumps(entry, sort_keys=True)
    atomic_write_text(cache_file, text, durable=False)
    return text, "measured"


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
