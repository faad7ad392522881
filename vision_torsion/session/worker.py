"""The worker side of ``process``: measure one image, or take it from the cache.

In two halves: :func:`read_task` reads, hashes and decodes (almost all of it C code
that releases the GIL: the file read and the PNG decoding), :func:`finish_task`
measures and logs the result (Python and numpy, holding the GIL for most of it), so
``process`` can run several readers beside one measuring thread; :func:`measure_task`
does both, in a worker process.

Kept apart from :mod:`.process` so that a worker process imports only the
measuring code (numpy, OpenCV): neither pandas nor scipy nor the rest of the
session package, which cost each run about a second before its first image.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from contextlib import contextmanager
from dataclasses import dataclass, replace
from functools import lru_cache

import cv2
import numpy as np
import xxhash
from threadpoolctl import threadpool_limits

from ..batch import attempt
from ..errors import ImageReadError, MarkerError
from ..images import GreyImage, decode_image, read_image_bytes
from ..pair import measure_pair, pair_candidates
from ..settings import MeasureSettings
from .cache import CacheLog, cache_key

__all__ = [
    "measure_task",
    "read_task",
    "prepare_task",
    "saturated_fraction",
    "finish_task",
    "either_polarity",
    "ReadImage",
    "digest",
    "content_hash",
    "start_worker",
    "exit_with",
    "in_process",
    "one_thread",
    "one_thread_here",
    "reuse_freed_memory",
]

logger = logging.getLogger(__name__)


def digest(data: bytes) -> str:
    """SHA-256 of `data`, hex (64 digits): cache keys, the measuring code, a
    correction file."""
    return hashlib.sha256(data).hexdigest()


def content_hash(data: bytes) -> str:
    """XXH3-128 of an image file's bytes, hex (32 digits): the image's part of its
    cache key.

    It tells a changed file from an unchanged one (two different files share a
    hash with probability 2⁻¹²⁸); it does not guard against a file crafted to
    collide, which no one measuring their own images needs. It hashes a 634 kB
    PNG in 0.03 ms; SHA-256 took 0.36 ms, a thirtieth of the time to decode it.
    """
    return xxhash.xxh3_128_hexdigest(data)


@lru_cache(maxsize=4)
def _settings_from(settings_json: str) -> MeasureSettings:
    return MeasureSettings.from_dict(json.loads(settings_json))


class _Cache:
    """This process's view of the cache: the keys cached when the run started, its
    own log (:class:`~.cache.CacheLog`), and the function that measures an image;
    set by :func:`start_worker` or :func:`in_process`."""

    known: frozenset = frozenset()
    log: CacheLog | None = None
    measure = staticmethod(measure_pair)


@dataclass(frozen=True)
class ReadImage:
    """One image read, hashed and decoded by :func:`read_task`, ready to measure.

    Attributes
    ----------
    key : str
        Its cache key ("" when the file could not be read).
    image_hash : str
        :func:`content_hash` of its bytes.
    image : GreyImage or None
        The decoded image; None when there is nothing to measure.
    candidates : PairCandidates or None
        The marker candidates :func:`~vision_torsion.pair.measure_pair` looks at first
        (:func:`~vision_torsion.pair.pair_candidates`).
    error : Exception or None
        Why it could not be decoded.
    result : tuple or None
        The task's result when it needs no measuring: cached, or unreadable.
    undecodable : bool
        The bytes could not be decoded as an image (`error` says why).
    """

    key: str
    image_hash: str = ""
    image: GreyImage | None = None
    candidates: object | None = None
    error: Exception | None = None
    result: tuple[str, str | None, str] | None = None
    undecodable: bool = False
    saturated: float | None = None


def read_task(task: tuple[str, str, str]) -> ReadImage:
    """Read an image, hash it and, unless its result is cached, decode it and find
    its marker candidates.

    The first half of :func:`measure_task`, nearly all of its time spent in C code
    that releases the GIL (the file read, the PNG decoding, most of the detection):
    ``process`` runs it in several threads while one thread measures
    (:func:`finish_task`). Detecting here, while the image is still in this core's
    caches, costs about half as much as in the measuring thread.
    """
    path = task[0]
    try:
        data = read_image_bytes(path, signature=False)  # its size checked before it is read; a non-image
        # is refused by decode_image below, a failure cached by the file's hash
    except ImageReadError as exc:
        why = json.dumps({"status": "failed", "message": str(exc)})
        return ReadImage("", result=("", why, "unread"))
    return prepare_task(data, task)


def prepare_task(data: bytes, task: tuple[str, str, str]) -> ReadImage:
    """:func:`read_task` on bytes already read: hash, and unless cached, decode and
    find the candidates. ``bind`` and ``watch`` (:mod:`.shots`) use it too, so an
    image is measured from the same candidates whichever command measures it."""
    path, settings_json, settings_key = task
    image_hash = content_hash(data)
    key = cache_key(image_hash, settings_key)
    if key in _Cache.known:
        return ReadImage(key, image_hash, result=(key, None, "cached"))
    try:
        image = decode_image(data, name=path, keep_integers=True)
    except Exception as exc:  # noqa: BLE001 - reported by finish_task, as if measuring failed
        return ReadImage(key, image_hash, error=exc, undecodable=True)
    # here, in a reading thread (numpy releases the GIL), not in the one measuring thread
    saturated = saturated_fraction(image)
    # the measuring function says which candidates it needs (an N-marker target's: all of them)
    find = getattr(_Cache.measure, "find_candidates", pair_candidates)
    try:
        candidates = find(image.data, _settings_from(settings_json))
    except Exception as exc:  # noqa: BLE001 - reported by finish_task, as if measuring failed
        return ReadImage(key, image_hash, image=image, error=exc, saturated=saturated)
    return ReadImage(key, image_hash, image=image, candidates=candidates, saturated=saturated)


def finish_task(read: ReadImage, task: tuple[str, str, str]) -> tuple[str, str | None, str]:
    """Measure an image :func:`read_task` read (unless it needs no measuring) and
    append the result to this process's cache log: the second half of
    :func:`measure_task`, with the same result. Not thread-safe: one thread of a
    process finishes its tasks."""
    if read.result is not None:
        return read.result
    path, settings_json, _ = task
    key = read.key

    def measure(read: ReadImage):
        if read.error is not None:
            raise read.error
        return either_polarity(_Cache.measure, read.image, settings=_settings_from(settings_json), name=path,
                               candidates=read.candidates)

    done = attempt(measure, read, name=path)
    if done.unexpected:  # a bug, not the image: not cached, so the next run tries again
        return key, json.dumps({"status": "failed", "message": done.message}), "measured"
    entry = {"status": "ok", "pair": done.value.to_dict()} if done.ok else {"status": "failed", "message": done.message}
    entry["image_xxh3_128"] = read.image_hash
    if read.saturated is not None:
        entry["saturated_fraction"] = read.saturated
    text = json.dumps(entry, sort_keys=True)
    if _Cache.log is not None:
        try:
            _Cache.log.append(key, text)
        except OSError as exc:  # the result stands; only a re-run would measure it again
            logger.warning("%s: result not cached (%s)", path, exc)
    return key, text, "measured"


def either_polarity(measure, image, *, settings: MeasureSettings, name: str, candidates):
    """``measure(image, settings=settings, name=name, candidates=candidates)``, or,
    when it finds no target (:class:`~vision_torsion.errors.MarkerError`), the
    same with the other polarity (its own candidates): the lights changed, or the
    target was turned over. That first error stands when the other polarity finds
    no target either. The markers' fitted contrast tells which polarity was
    measured (:func:`~.shots.polarity_note`), and ``process`` accepts such a pair
    only at the reference's marker separation."""
    try:
        return measure(image, settings=settings, name=name, candidates=candidates)
    except MarkerError as first:
        other = replace(settings, polarity="bright" if settings.polarity == "dark" else "dark")
        try:
            return measure(image, settings=other, name=name, candidates=None)
        except MarkerError:
            raise first from None


def saturated_fraction(image: GreyImage) -> float:
    """Fraction of `image`'s pixels at its full scale (0-1): kept with its cached
    result, so ``watch``, ``bind`` and ``process`` judge saturation from the same
    number whichever measured it (:func:`~.shots.image_warnings`)."""
    data = image.data
    # the maximum first (one vectorised pass, no temporary array): most images have
    # no pixel at full scale, and counting them took seven times as long
    if data.max() < image.full_scale:
        return 0.0
    return float(np.count_nonzero(data >= image.full_scale)) / data.size


def measure_task(task: tuple[str, str, str]) -> tuple[str, str | None, str]:
    """Measure one image unless its result is cached (:func:`read_task`, then
    :func:`finish_task`); runs in a worker process.

    Parameters
    ----------
    task : tuple of str
        (image path, measurement settings as JSON, settings key).

    Returns
    -------
    tuple
        The cache key, the entry as JSON text (None when it is cached: the caller
        has the cached entries), and where it came from: "measured", "cached" or
        "unread" (the file could not be read). A measured entry is appended to this
        process's cache log at once. An unexpected exception is reported as a
        failure but not cached, so it is retried on the next run.
    """
    return finish_task(read_task(task), task)


def start_worker(cache_dir: str, run: str, known: frozenset, measure=measure_pair, main_pid: int | None = None) -> None:
    """Worker initializer: one thread for BLAS and OpenCV (:func:`one_thread`), freed
    memory kept for reuse (:func:`reuse_freed_memory`), the keys already cached, a
    cache log of this run, the measuring function
    (:func:`~vision_torsion.pair.measure_pair` unless the caller passed another), and
    a watchdog that ends this worker when the main process `main_pid` dies
    (:func:`exit_with`)."""
    if main_pid is not None:
        exit_with(main_pid)
    one_thread()
    reuse_freed_memory()
    _Cache.known = known
    _Cache.log = CacheLog(cache_dir, run)
    _Cache.measure = staticmethod(measure)


def exit_with(main_pid: int, *, interval_s: float = 0.2) -> None:
    """End this process soon after the process `main_pid` dies.

    A worker whose main process was killed (SIGKILL, a crash, the terminal closed)
    would otherwise go on measuring the rest of its tasks for nobody. A daemon
    thread checks every `interval_s` whether the main process still exists and
    whether this process's parent changed (the fork server, the parent of workers
    started through it, exits when the main process does); then the worker exits
    at once (``os._exit``: nothing of its own is left to save, every result it
    finished is already in its cache log).
    """
    import threading
    import time

    parent = os.getppid()

    def gone() -> bool:
        if os.getppid() != parent:
            return True
        try:
            os.kill(main_pid, 0)
        except ProcessLookupError:
            return True
        except PermissionError:
            return False
        return False

    def watch():
        while not gone():
            time.sleep(interval_s)
        os._exit(1)

    threading.Thread(target=watch, name="vision-torsion-watchdog", daemon=True).start()


@contextmanager
def in_process(cache_dir: str, run: str, known: frozenset, measure=measure_pair):
    """:func:`start_worker` for measuring in this process (one thread while
    measuring, then as it was; the log closed afterwards)."""
    saved = _Cache.known, _Cache.log, _Cache.measure
    _Cache.known, _Cache.log, _Cache.measure = known, CacheLog(cache_dir, run), staticmethod(measure)
    try:
        with one_thread_here():
            yield
    finally:
        _Cache.log.close()
        _Cache.known, _Cache.log, _Cache.measure = saved


def one_thread() -> None:
    """Worker initializer: one thread for BLAS and OpenCV in each worker.

    The pool already keeps every core busy. The measuring code's small matrix
    products (8 x ~4000) are what OpenBLAS splits over threads by default, and its
    waiting threads then compete with the other workers: two workers ran 3.5x
    slower than one.
    """
    cv2.setNumThreads(1)
    threadpool_limits(1)


#: glibc's mallopt parameters (malloc.h) and the largest mmap threshold it accepts
#: (half its 64 MB heap size on 64-bit systems).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_MMAP_THRESHOLD_MAX = 32 << 20


def reuse_freed_memory(*, mmap_threshold: int = _MMAP_THRESHOLD_MAX, trim_threshold: int = 256 << 20) -> bool:
    """Keep freed memory in this process for the next allocation (glibc only): for
    a process that does nothing else, such as a command or a worker process.

    By default glibc serves every allocation at least as large as the last large
    block freed (at least 128 kB) by a fresh ``mmap`` of zeroed pages, and gives
    the pages back to the kernel when it is freed. A session run allocates such
    blocks for every image (the file's bytes, ~0.6 MB for the demo's PNGs, and the
    decoded image, ~1.4 MB) and pays a page fault for each of their 4 kB pages on
    every image: 40,000-130,000 faults and 0.2-0.45 s of system time in a run of
    the demo's 444 images (2026-11-23, 2 cores), against 15,000-40,000 for a plain
    two-thread decode of the same files (``cv2.imread`` streams the file: no block
    for its bytes). With allocations up to `mmap_threshold` bytes served from the
    heap, and the heap trimmed only when more than `trim_threshold` bytes at its top
    are free, the blocks of one image are reused by the next: ~11,000 faults and
    0.1-0.15 s of system time in most runs.

    Memory a program frees is kept (up to `trim_threshold` at the top of the heap),
    so this is not for a long-lived process that also does other work (it is not
    undone): the command line calls it for ``process``, and :func:`start_worker`
    in each worker process.

    Returns
    -------
    bool
        True when both settings were made (glibc), False elsewhere (other C
        libraries have other allocators; nothing is changed).
    """
    try:
        if not os.confstr("CS_GNU_LIBC_VERSION"):
            return False
    except (AttributeError, ValueError, OSError):  # not glibc, or not a POSIX system
        return False
    import ctypes

    mallopt = ctypes.CDLL(None).mallopt
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, mmap_threshold)) and bool(mallopt(_M_TRIM_THRESHOLD, trim_threshold))


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
