"""Process a session folder into ``measurements.csv``: parallel, streaming, resumable.

Steps
-----
1. :func:`~vision_torsion.session.load.load_session` validates the whole session
   (configuration, every manifest row, every image file) before anything is
   measured.
2. Every image is read, hashed (XXH3-128 of its bytes) and, unless the cache
   (``OUT_DIR/.vision-torsion-cache/``, :mod:`.cache`) held a result for that image hash and those
   measurement settings when the run started, decoded and measured by
   :func:`vision_torsion.pair.measure_pair`. With up to three jobs this happens in
   this process: `jobs` threads read, decode and find the marker candidates at most
   two images each ahead of this thread, which measures (measuring holds the GIL,
   reading, decoding and most of the detection do not); with more, in a pool of
   worker processes. Images are never all in memory.
   Each result (or the reason it failed) is appended to the process's cache log
   right away, one line in one write (without a disk flush: a line a kill or a
   power cut left incomplete is ignored, and that image measured again). So an
   interrupted run keeps everything it finished, and a re-run (after an
   interruption, after images were added or replaced, after the settings changed)
   measures only what is new or changed. At the end, the logs are merged into one.
3. Per orientation, in manifest order, :func:`vision_torsion.angle.sequence_angles`
   turns the marker pairs into unwrapped angles relative to the orientation's
   reference image (its ``reference`` row, else its first row), multiplied by the
   session's ``angle_sign``. This step is cheap and is not cached.
4. ``measurements.csv`` is written atomically. Its content depends only on the
   cached results, so an interrupted-and-resumed run writes byte for byte the same
   file as an uninterrupted one.

Only the output folder (``SESSION_DIR/results/`` by default) is written.
"""

from __future__ import annotations

import errno
import json
import logging
import math
import os
import pickle
from collections import defaultdict, deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from itertools import islice
from pathlib import Path

from ..angle import sequence_angles
from ..correction import load_correction
from ..errors import SessionError, VisionTorsionError
from ..fileio import check_output_dir, same_folder, write_records_csv
from ..measurements import MEASUREMENTS_NAME, RESULT_COLUMNS, TARGET_RESULT_COLUMNS, output_folder
from ..pair import PairMeasurement, measure_pair
from ..quality import SUSPECT, residual_flags
from ..settings import MeasureSettings
from ..validate import check_number
from .cache import CACHE_DIRNAME, CacheLog, merge_cache, read_cache, read_logs
from .load import Session, load_session, unlisted_images
from .shots import image_warnings, other_polarity_mismatch, polarity_note
from .worker import digest, finish_task, in_process, measure_task, read_task, start_worker

__all__ = ["ProcessResult", "process_session", "OUTPUT_COLUMNS", "MEASUREMENTS_NAME", "session_measuring",
           "code_fingerprint", "MAX_THREAD_JOBS", "PROCESS_MIN_IMAGES"]

logger = logging.getLogger(__name__)

#: Columns added after the manifest's own (whose torque_nm/torque_std_nm, if any,
#: are replaced by these): :data:`vision_torsion.measurements.RESULT_COLUMNS`.
OUTPUT_COLUMNS = RESULT_COLUMNS
#: Bump when the cache entry layout, or the way an entry is measured, changes; part of
#: every cache key.
_CACHE_FORMAT = 6
#: Up to this many jobs run as threads of the calling process (jobs threads read,
#: decode and find candidates, the calling thread measures) when fewer than
#: :data:`PROCESS_MIN_IMAGES` images are to be measured; more jobs, or more images,
#: run as worker processes.
MAX_THREAD_JOBS = 3
#: Images to measure (present, less the results the cache holds) from which even
#: 2-3 jobs run as worker processes. Threads share one interpreter lock, which the
#: measuring (~2 ms of an image's ~6 ms, on the demo's PNGs) holds: two threads
#: reached 1.3x a plain decode of the demo's 444 images where two processes take
#: 1.0x. A worker process costs ~0.2 s to start (its fork server's imports): a
#: 20-image session took 0.43 s with threads, 0.62 s with processes.
PROCESS_MIN_IMAGES = 150


@dataclass(frozen=True)
class ProcessResult:
    """Summary of :func:`process_session`.

    Attributes
    ----------
    measurements_path : pathlib.Path
        The ``measurements.csv`` written.
    n_images, n_ok, n_failed : int
        Rows of the manifest, and how many got status ``ok`` / any other but
        ``pending``: ``failed``, ``suspect`` (measured, but a marker's fit residual
        is far above the session's noise: :mod:`vision_torsion.quality`), or an
        N-marker target's identity statuses (:mod:`.targetrows`).
    n_measured, n_cached : int
        Images measured in this run, and images whose result came from the cache.
    failures : tuple of (str, str)
        (image, message) of every failed or suspect row, in manifest order.
    pending : tuple of (str, str)
        (image, message) of every row not photographed yet (status ``pending``),
        or whose orientation's reference image is not: a partly shot session.
    unlisted : tuple of str
        Image files in the session (or bound camera) folder that no row names.
    suspect : tuple of str
        The images among `failures` whose status is ``suspect`` (the others failed).
    failure_statuses : tuple of str
        The status of each of `failures`, in the same order.
    """

    measurements_path: Path
    n_images: int
    n_ok: int
    n_failed: int
    n_measured: int
    n_cached: int
    failures: tuple[tuple[str, str], ...]
    pending: tuple[tuple[str, str], ...] = ()
    unlisted: tuple[str, ...] = ()
    suspect: tuple[str, ...] = ()
    failure_statuses: tuple[str, ...] = ()

    @property
    def n_pending(self) -> int:
        """Rows not photographed yet (or waiting for their reference image)."""
        return len(self.pending)

    @property
    def complete(self) -> bool:
        """True when no row is pending."""
        return not self.pending

    @property
    def ok(self) -> bool:
        """True when no image failed (pending rows are not failures)."""
        return self.n_failed == 0


#: Subpackages that only use measurements; everything else in vision_torsion may
#: change what an image measures, so its source is part of the cache key.
_DOWNSTREAM = ("session", "cli", "analysis", "stiffness", "report", "synthetic")


def code_fingerprint() -> str:
    """Digest of the measuring code's source (every module outside `_DOWNSTREAM`).

    A version number is not bumped for every change to the measuring code, so the
    source itself keys the cache: after an upgrade or an edit, images are measured
    again instead of mixing results of two versions in one table. Unknown new
    subpackages are included, which can only cause needless re-measuring.
    """
    root = Path(__file__).resolve().parents[1]
    parts = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root)
        if rel.parts[0] not in _DOWNSTREAM:
            parts.append(rel.as_posix().encode() + b"\0" + path.read_bytes())
    return digest(b"\0".join(parts))


def _settings_key(settings: MeasureSettings, measure=measure_pair) -> str:
    """JSON identifying how images are measured: settings, correction content, code,
    and the measuring function when it is not the default."""
    d = settings.to_dict()
    if d.get("correction"):
        d["correction"] = digest(Path(d["correction"]).read_bytes())
    key = {"settings": d, "code": code_fingerprint(), "cache": _CACHE_FORMAT}
    if measure is not measure_pair:
        key["measure"] = f"{getattr(measure, '__module__', '')}.{getattr(measure, '__qualname__', repr(measure))}"
    return json.dumps(key, sort_keys=True)


def session_measuring(session: Session, measure):
    """How the images of `session` are measured, shared by ``process``, ``bind`` and
    ``watch`` so that one cache key gives one result whichever measured first.

    Returns
    -------
    (callable, str, callable)
        The measuring function (`measure`, or for an N-marker target, ``[target]``,
        every marker found: :mod:`.targetrows`), the settings part of the cache key
        (the target's layout included), and the check a cache entry must pass.
    """
    if session.config.target is None:
        return measure, _settings_key(session.settings, measure), _valid_entry
    from .targetrows import measure_target_markers, target_settings_key, valid_target_entry

    measure = measure_target_markers if measure is measure_pair else measure
    return measure, target_settings_key(_settings_key(session.settings, measure), session.config.target), \
        valid_target_entry


def _valid_entry(entry: dict) -> bool:
    """The cache's schema check: a failure carries its message, a result a marker
    pair that rebuilds (:meth:`~vision_torsion.pair.PairMeasurement.from_dict`)."""
    if entry.get("status") == "failed":
        return isinstance(entry.get("message"), str)
    try:
        pair = PairMeasurement.from_dict(entry["pair"])
    except (KeyError, TypeError, ValueError, AttributeError):
        return False
    markers = [m for m in (getattr(pair, "first", None), getattr(pair, "second", None)) if m is not None]
    return all(isinstance(getattr(m, f), (int, float)) for m in markers
               for f in ("x_px", "y_px", "radius_px"))


def _default_jobs() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _pool_context():
    """Start method of the worker processes: forkserver where available, else spawn.

    Not fork: the parent may hold threads (tqdm's monitor, BLAS) and forking a
    threaded process can deadlock (Python 3.12 warns, 3.14 no longer forks by
    default). The fork server preloads the worker's modules (:mod:`.worker` and the
    measuring code, ~0.2 s of numpy and OpenCV), so each worker starts by a cheap
    fork instead of importing them again; this sets the process-wide preload list
    of :mod:`multiprocessing`'s fork server, keeping its default ``__main__`` entry.
    """
    import multiprocessing  # here: only more than MAX_THREAD_JOBS jobs start processes

    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["__main__", "vision_torsion.session.worker", "vision_torsion.pair"])
    return context


def _start_server() -> None:
    """Start the fork server now, in the background: its ~0.2 s of imports then
    overlap with this process validating the session and reading the cache,
    instead of delaying the first worker."""
    if _pool_context().get_start_method() == "forkserver":
        from multiprocessing import forkserver

        forkserver.ensure_running()


def _progress_bar(total: int, progress: bool):
    """A bar on a terminal, lines elsewhere (:func:`vision_torsion.progress.progress_bar`)."""
    from ..progress import progress_bar

    return progress_bar(total, desc="measuring", unit="image", enabled=progress)


def _workers(jobs: int, n_tasks: int, n_cached: int, measure) -> tuple[int, bool]:
    """(jobs, whether they are worker processes) to measure `n_tasks` images, of
    which about `n_cached` have their results in the cache, with `measure`.

    Threads of this process for up to :data:`MAX_THREAD_JOBS` jobs and fewer than
    :data:`PROCESS_MIN_IMAGES` images to measure, or where worker processes would
    start slowly (no fork server: each would import the measuring code again);
    else worker processes, unless `measure` cannot be sent to them (it does not
    pickle) or the open-file limit has no room for them: then threads, logged when
    `jobs` is above :data:`MAX_THREAD_JOBS`."""
    if jobs <= 1 or n_tasks <= 1:
        return jobs, False
    if jobs <= MAX_THREAD_JOBS and (n_tasks - n_cached < PROCESS_MIN_IMAGES
                                    or _pool_context().get_start_method() != "forkserver"):
        return jobs, False
    try:
        pickle.dumps(measure)
    except (pickle.PicklingError, AttributeError, TypeError):  # a lambda, a local function, a lock
        if jobs > MAX_THREAD_JOBS:
            logger.warning("the measuring function %r cannot be sent to worker processes; measuring with %d "
                           "threads of this process instead", measure, MAX_THREAD_JOBS)
        return min(jobs, MAX_THREAD_JOBS), False
    if _room_for_workers(jobs):
        return jobs, True
    if jobs > MAX_THREAD_JOBS:
        logger.warning("only %d files may be open (ulimit -n), too few for %d worker processes; measuring "
                       "with %d threads of this process instead", _open_file_limit(), jobs, MAX_THREAD_JOBS)
    return min(jobs, MAX_THREAD_JOBS), False


def _run_tasks(tasks, *, jobs: int, processes: bool, progress: bool, cache_dir: str, run: str, known: frozenset,
               measure):
    """Yield each task's result in task order: in `jobs` worker processes when
    `processes` (:func:`_workers`), else in this process (:func:`_read_ahead`, or
    one by one for one job)."""
    bar = _progress_bar(len(tasks), progress)
    try:
        if not processes:
            with in_process(cache_dir, run, known, measure):
                results = (_read_ahead(tasks, readers=jobs) if jobs > 1
                           else map(measure_task, tasks))
                for result in results:
                    yield result
                    bar.update()
            return
        from concurrent.futures import ProcessPoolExecutor

        context = _pool_context()
        # small chunks (~60 ms of work): at the end one worker waits at most
        # that long for the other; the messages cost ~0.2 ms each
        chunksize = max(1, min(4, len(tasks) // (jobs * 8)))
        pool = ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=start_worker,
                                   initargs=(cache_dir, run, known, measure, os.getpid()))
        try:
            for result in pool.map(measure_task, tasks, chunksize=chunksize):
                yield result
                bar.update()
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
    except OSError as exc:
        if exc.errno != errno.EMFILE:
            raise
        raise SessionError(f"too many open files (the limit is {_open_file_limit()}, `ulimit -n`): run with "
                           "fewer --jobs, or raise the limit", reason="too_many_open_files") from None
    finally:
        bar.close()


#: Open files a worker process costs its parent (its sentinel and pipes), and the
#: files kept free for everything else (images being read, cache logs, results).
_FILES_PER_WORKER, _FILES_RESERVED = 3, 8


def _open_file_limit() -> int | None:
    """The soft limit on open files (``ulimit -n``), or None where there is none."""
    try:
        import resource
    except ImportError:  # not a POSIX system
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    return None if soft == resource.RLIM_INFINITY else soft


def _room_for_workers(jobs: int) -> bool:
    """Whether the open-file limit leaves room for `jobs` worker processes."""
    limit = _open_file_limit()
    if limit is None:
        return True
    try:
        in_use = len(os.listdir("/proc/self/fd"))
    except OSError:  # no /proc: the standard streams at least
        in_use = 3
    return in_use + _FILES_RESERVED + _FILES_PER_WORKER * jobs <= limit


def _read_ahead(tasks, *, readers: int):
    """Yield each task's result in task order: `readers` threads read, hash, decode
    and find the candidates (:func:`~.worker.read_task`) at most 2·readers images
    ahead, and this thread measures them (:func:`~.worker.finish_task`).

    Reading, decoding and most of the detection run in C without the GIL;
    measuring holds it, so the threads wait for each other on many images
    (:data:`PROCESS_MIN_IMAGES`); on a few, no process start-up beats that."""
    todo = iter(tasks)
    pool = ThreadPoolExecutor(max_workers=readers, thread_name_prefix="vision-torsion-read")
    try:
        ahead = deque((task, pool.submit(read_task, task)) for task in islice(todo, 2 * readers))
        while ahead:
            task, read = ahead.popleft()
            for following in islice(todo, 1):
                ahead.append((following, pool.submit(read_task, following)))
            yield finish_task(read.result(), task)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _relative_message(message: str, absolute: Path, relative: str) -> str:
    """Name the image by its manifest path rather than the absolute one."""
    return message.replace(str(absolute), relative)


#: Largest turn (deg) between consecutive images of one orientation taken as certain
#: with two equal markers; beyond it the image fails as ambiguous. A real gear winds up
#: by well under a degree; the first loaded image after the reference (at +Tmax) is
#: the largest step. Wider than measure's 30°: a swap still needs a true turn of 120°.
SESSION_MAX_STEP_DEG = 60.0


def _angles(session: Session, entries: list[dict], correction=None) -> list[tuple[float, float, str, str]]:
    """Per row: (angle_deg, angle_std_deg, message or "", status).

    The cache holds image-space marker pairs; the plane correction (if any) is
    applied here, so changing it re-measures nothing. A row whose image does not
    exist yet, or whose orientation's reference image does not, is ``pending``.
    """
    rows = session.manifest.rows
    out: list[tuple[float, float, str, str]] = [(math.nan, math.nan, "", "ok")] * len(rows)
    groups: dict[float, list[int]] = defaultdict(list)
    for i, row in enumerate(rows):
        groups[row.orientation_deg].append(i)
    sign = session.config.angle_sign
    for orientation, idx in groups.items():
        ref = next((i for i in idx if rows[i].phase == "reference"), idx[0])
        pairs = [PairMeasurement.from_dict(entries[i]["pair"])
                 if entries[i]["status"] == "ok" else None for i in idx]
        if entries[ref]["status"] == "pending":
            why = (f"waiting for the reference image {rows[ref].image} (line {rows[ref].line}) "
                   f"of orientation {orientation:g}: no angle can be measured without it")
            for i in idx:
                out[i] = (math.nan, math.nan, entries[i].get("message") if entries[i]["status"] == "pending"
                          else why, "pending")
            continue
        if pairs[idx.index(ref)] is None:
            why = (f"reference image {rows[ref].image} (line {rows[ref].line}) of "
                   f"orientation {orientation:g} failed, so no angle can be measured")
            for i in idx:
                pending = entries[i]["status"] == "pending"
                out[i] = (math.nan, math.nan, entries[i].get("message") or why,
                          "pending" if pending else "failed")
            continue
        try:
            angles = sequence_angles(pairs[idx.index(ref)], pairs, correction=correction,
                                     max_step_deg=SESSION_MAX_STEP_DEG)
        except VisionTorsionError as exc:
            angles = [None] * len(idx)
            reason = f"angles of orientation {orientation:g} failed: {exc}"
        else:
            reason = "no angle relative to the reference (marker identity lost)"
        flags = residual_flags(pairs)
        reference = pairs[idx.index(ref)]
        for i, pair, angle, flag in zip(idx, pairs, angles, flags):
            if angle is not None and not flag:  # blur, saturation: the rule watch and bind apply
                flag = "; ".join(image_warnings(pair, None if i == ref else reference,
                                                entries[i].get("saturated_fraction", math.nan)))
            if angle is not None and angle.ambiguous:
                out[i] = (math.nan, math.nan, angle.ambiguous, "failed")
            elif angle is not None and (why := other_polarity_mismatch(pair, reference, session.settings.polarity)):
                out[i] = (math.nan, math.nan, why, "failed")
            elif angle is not None:
                note = flag or polarity_note(pair, session.settings.polarity)
                out[i] = (sign * angle.angle_deg + 0.0, angle.angle_std_deg, note, SUSPECT if flag else "ok")
            elif entries[i]["status"] == "pending":
                out[i] = (math.nan, math.nan, entries[i]["message"], "pending")
            else:
                out[i] = (math.nan, math.nan, entries[i].get("message") or reason, "failed")
    return out


def _table(session: Session, entries: list[dict], correction=None) -> tuple[list[str], list[dict]]:
    """The columns and rows of measurements.csv (manifest columns, then the results)."""
    manifest = session.manifest
    keep = [c for c in manifest.columns if c not in OUTPUT_COLUMNS]
    records, extras, extra_columns = [], None, ()
    if session.config.target is None:
        results = _angles(session, entries, correction)
    else:  # an N-marker target: the rigid fit of all markers, the axis motion (.targetrows)
        from .targetrows import target_rows

        done = target_rows(session, entries, correction)
        results = [(r.angle_deg, r.angle_std_deg, r.message, r.status) for r in done]
        extras, extra_columns = [r.extra for r in done], TARGET_RESULT_COLUMNS
    for k, (row, (angle, angle_std, why, status)) in enumerate(zip(manifest.rows, results)):
        torque = session.torque(row)
        rec = {c: v for c, v in row.fields if c in keep}
        rec.update(torque_nm=torque.torque_nm, torque_std_nm=torque.torque_std_nm,
                   torque_common_std_nm=torque.torque_common_std_nm,
                   torque_source="weights" if row.torque_nm is None else "measured",
                   angle_deg=angle, angle_std_deg=angle_std,
                   status=status,
                   message=_relative_message(why, manifest.image_path(row), row.image) if why else "")
        if extras is not None:
            rec.update(extras[k])
        records.append(rec)
    return keep + list(OUTPUT_COLUMNS) + list(extra_columns), records


def process_session(session_dir, *, out_dir=None, jobs: int | None = None,
                    progress: bool = False, measure=measure_pair) -> ProcessResult:
    """Measure every image of a session and write ``measurements.csv``.

    Parameters
    ----------
    session_dir : str or os.PathLike
        The session folder (session.toml, manifest.csv, images).
    out_dir : str or os.PathLike, optional
        Output folder; ``SESSION_DIR/results`` by default. It holds
        ``measurements.csv`` and the cache ``.vision-torsion-cache/``.
    jobs : int, optional
        Images read and decoded at once; all available cores by default. 1
        measures in this process alone; up to 3 (``MAX_THREAD_JOBS``) run as
        reading threads of this process beside the measuring one while fewer than
        ``PROCESS_MIN_IMAGES`` (150) images are to be measured; more jobs or more
        images run as worker processes.
    progress : bool
        Show a progress bar (on stderr).
    measure : callable
        Measures one image: ``measure(image, *, settings, name, candidates)``
        returns its :class:`~vision_torsion.pair.PairMeasurement`. The default,
        :func:`~vision_torsion.pair.measure_pair`, is the measurement core; another
        function (a stand-in in tests, an experimental fit) keys the cache apart from
        it by its qualified name; one that does not pickle runs in threads of this
        process only.
        For a session of an N-marker target (``[target]`` in session.toml) the
        default is :func:`~.targetrows.measure_target_markers` (every marker), and
        the rows come from the rigid fit of all of them (:mod:`.targetrows`: status
        ``marker_missing``, ``ambiguous``, ``layout_mismatch`` or a ``suspect`` bump
        with its reason, and the columns
        :data:`~vision_torsion.measurements.TARGET_RESULT_COLUMNS`).

    Returns
    -------
    ProcessResult
        Counts of ok/failed rows and of measured/cached images. One image failing
        does not stop the run; it gets status ``failed`` and a message. A partly
        shot session is not an error: a row whose image does not exist yet gets
        status ``pending`` (so do the rows of an orientation whose reference image
        does not exist yet), and image files no row names are listed
        (:attr:`ProcessResult.unlisted`).

    Raises
    ------
    SessionError
        Invalid session folder or session.toml, or `out_dir` is the session folder or a
        folder of its images.
    ManifestError
        Any problem with manifest.csv or the image files it names (all listed);
        an image that does not exist is not a problem but a pending row.
    """
    if jobs is not None:
        jobs = check_number(jobs, name="jobs", error=SessionError, low=1, whole=True)
    jobs = jobs or _default_jobs()
    if jobs > MAX_THREAD_JOBS:
        _start_server()  # its imports overlap with checking the session
    session = load_session(session_dir, missing="pending")
    out = output_folder(session.folder, out_dir)
    if same_folder(out, session.folder):
        raise SessionError(f"{out}: the output folder cannot be the session folder itself; "
                           "use a subfolder such as results/")
    image_dirs = {session.manifest.image_path(row).parent for row in session.manifest.rows}
    if any(same_folder(out, d) for d in image_dirs):  # the photographs are only read
        raise SessionError(f"{out}: the output folder cannot be a folder of the session's images; "
                           "use a folder of its own such as results/")
    # before measuring: a run must not do its work and then fail to write it
    check_output_dir(out, replaces=[MEASUREMENTS_NAME])
    settings = session.settings
    # a bad correction file is unusable input: say so before measuring anything
    correction = load_correction(settings.correction)
    settings_json = json.dumps(settings.to_dict(), sort_keys=True)
    measure, key, check = session_measuring(session, measure)
    cache_dir = out / CACHE_DIRNAME
    cached, logs = read_cache(cache_dir, check=check)
    run = CacheLog.new_run()
    pending = set(session.manifest.pending)
    present = [row for row in session.manifest.rows if row.line not in pending]
    tasks = [(str(session.manifest.image_path(row)), settings_json, key) for row in present]
    measured, sources = [], []
    jobs, processes = _workers(max(1, min(jobs, len(tasks))), len(tasks), len(cached), measure)
    logger.debug("%d images, the cache holds %d results: measuring with %s", len(tasks), len(cached),
                 f"{jobs} worker processes" if processes else
                 f"{jobs} reading threads" if jobs > 1 else "this process alone")
    if processes:
        _start_server()
    for image_key, text, source in _run_tasks(tasks, jobs=jobs, processes=processes, progress=progress,
                                              cache_dir=str(cache_dir), run=run,
                                              known=frozenset(cached), measure=measure):
        measured.append(cached[image_key] if text is None else json.loads(text))
        sources.append(source)
    found = iter(measured)
    entries = [{"status": "pending", "message": f"not photographed yet ({row.image}: no such file)"}
               if row.line in pending else next(found) for row in session.manifest.rows]
    columns, records = _table(session, entries, correction)
    path = write_records_csv(out / MEASUREMENTS_NAME, columns, records)
    new_logs = CacheLog(cache_dir, run).files()
    if len(logs) + len(new_logs) > 1:
        # one log for the next run; the old logs' entries were read at the start (a
        # single log, e.g. of a first run in this process, is one already)
        merge_cache(cache_dir, {**cached, **read_logs(new_logs, check=check)}, logs + new_logs)
    # a suspect angle is not good data, nor an N-marker target's marker_missing, ambiguous, layout_mismatch
    failed = [r for r in records if r["status"] not in ("ok", "pending")]
    waiting = [r for r in records if r["status"] == "pending"]
    failures = tuple((r["image"], r["message"]) for r in failed)
    # report figures in the default output folder are not shots, whichever -o this run has
    unlisted = tuple(unlisted_images(session, exclude=[out, output_folder(session.folder)]))
    n_ok = len(records) - len(failed) - len(waiting)
    logger.debug("%s: %d images, %d ok, %d failed, %d pending (%d measured, %d from the cache)",
                path, len(records), n_ok, len(failed), len(waiting),
                sources.count("measured"), sources.count("cached"))
    return ProcessResult(measurements_path=path, n_images=len(records),
                         n_ok=n_ok, n_failed=len(failed),
                         n_measured=sources.count("measured"),
                         n_cached=sources.count("cached"),
                         failures=failures,
                         pending=tuple((r["image"], r["message"]) for r in waiting),
                         unlisted=unlisted,
                         suspect=tuple(r["image"] for r in failed if r["status"] == SUSPECT),
                         failure_statuses=tuple(r["status"] for r in failed))
