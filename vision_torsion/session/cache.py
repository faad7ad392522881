"""The results cache of ``process``: append-only logs of one line per measured image.

Layout, in ``OUT_DIR/.vision-torsion-cache/``: files ``merged.jsonl`` and
``run-RUN-PID.jsonl``, each line ``KEY SUM ENTRY`` where
KEY is the 64-hex-digit cache key (SHA-256 of the image bytes' XXH3-128 hash, the
measurement settings and the measuring code), SUM the 16-hex-digit XXH3-64 checksum
of ``KEY ENTRY``, and ENTRY the JSON of the image's result or of why it failed. A
worker appends each result to its own log with one ``write`` as soon as it is
measured; a line cut short (a killed run, a power cut) fails to parse and is
ignored, so that image is measured again. At the end of a run the logs are merged
into one file, written atomically, and the merged logs are removed.

The cache verifies itself: a line whose checksum does not match (a changed digit,
a bad disk block, an edit by hand), or whose entry fails the caller's schema check
(``check``: ``process`` rebuilds the marker pair from it), is never used: it is
ignored with a logged note and that image is measured again. A line of an older
layout (no checksum) is ignored the same way.

One small file per image cost each image half a millisecond of file creation and
renaming, about a twentieth of decoding it.

The cache touches only files it can prove it wrote (the folder contract,
:mod:`vision_torsion.fileio`): a log is created new (never opened if a file of its
name is there) and recorded in the folder's record at once; only logs of its own
name pattern that the record proves ours are read, merged and removed, and the
merged file is never written over a file of that name the record does not prove
ours. Anything else in the folder is left alone. The folder's name is the tool's
own, not ``.cache``, so ``-o ~`` does not write into a user's ``~/.cache``.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
from pathlib import Path

import xxhash

from ..fileio import atomic_write_text, is_ours, record_created

logger = logging.getLogger(__name__)

__all__ = ["CacheLog", "read_cache", "read_logs", "merge_cache", "count_entries", "cache_line", "cache_key",
           "CACHE_DIRNAME"]

#: Name of the cache folder inside the output folder.
CACHE_DIRNAME = ".vision-torsion-cache"
_KEY_CHARS = 64
_SUM_CHARS = 16
_MERGED = "merged.jsonl"
_LOG_NAME = re.compile(r"run-.+-[0-9]+\.jsonl")
_DONE = ("ok", "failed")


def _checksum(key: str, entry_json: str) -> str:
    return xxhash.xxh3_64_hexdigest(f"{key} {entry_json}".encode("utf-8"))


def cache_key(image_hash: str, settings_key: str) -> str:
    """The cache key of one image: SHA-256 (hex, 64 digits) of its bytes' XXH3-128
    hash and `settings_key` (the JSON of the settings, the measuring code and the
    cache format).

    The one place a key is made: ``process``, ``bind`` and ``watch`` all measure an
    image through :func:`~vision_torsion.session.worker.finish_task` with the same
    candidates, so one key stands for one result whichever command measured first.
    """
    return hashlib.sha256(f"{image_hash}\n{settings_key}".encode()).hexdigest()


def cache_line(key: str, entry_json: str) -> str:
    """One cache line, ``KEY SUM ENTRY\\n`` (see the module docstring)."""
    return f"{key} {_checksum(key, entry_json)} {entry_json}\n"


def _entries(path: Path, check=None, rejected=None):
    """(key, entry dict) of every complete line of one log that passes its checksum
    and `check`; the others are counted in `rejected` (a dict reason -> count)."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return
    lines = text.split("\n")[:-1]  # the part after the last newline is cut short
    for line in lines:
        key = line[:_KEY_CHARS]
        total = line[_KEY_CHARS + 1:_KEY_CHARS + 1 + _SUM_CHARS]
        entry = line[_KEY_CHARS + _SUM_CHARS + 2:]
        if (len(key) != _KEY_CHARS or line[_KEY_CHARS:_KEY_CHARS + 1] != " "
                or line[_KEY_CHARS + _SUM_CHARS + 1:_KEY_CHARS + _SUM_CHARS + 2] != " "):
            why = "unreadable line"
        elif _checksum(key, entry) != total:
            why = "checksum mismatch"
        else:
            try:
                value = json.loads(entry)
            except ValueError:
                value = None
            if not (isinstance(value, dict) and value.get("status") in _DONE):
                why = "not a result"
            elif check is not None and not check(value):
                why = "wrong shape"
            else:
                yield key, value
                continue
        if rejected is not None:
            rejected[why] = rejected.get(why, 0) + 1


def read_logs(files, *, check=None) -> dict[str, dict]:
    """Every valid entry of the logs `files`, by cache key (a later line, or a later
    file's, wins over an earlier one with the same key).

    Parameters
    ----------
    files : iterable of path
        Log files.
    check : callable, optional
        ``check(entry) -> bool``: the entry has the shape its user needs. Entries
        failing it, or their checksum, are ignored with one logged note per log.
    """
    entries: dict[str, dict] = {}
    for path in files:
        rejected: dict[str, int] = {}
        entries.update(_entries(Path(path), check, rejected))
        if rejected:
            logger.warning("%s: %s ignored; those images are measured again", path,
                           ", ".join(f"{n} cache line(s): {why}" for why, n in sorted(rejected.items())))
    return entries


def read_cache(folder, *, check=None) -> tuple[dict[str, dict], list[Path]]:
    """Every valid entry of the cache in `folder`, and the log files read.

    Returns
    -------
    entries : dict
        Cache key -> entry (:func:`read_logs`).
    files : list of pathlib.Path
        The logs read (to merge them later with :func:`merge_cache`): only the
        cache's own (its names, proven by the folder's record).
    """
    folder = Path(folder)
    files = sorted(f for f in folder.glob("*.jsonl") if _own_log(f)) if folder.is_dir() else []
    return read_logs(files, check=check), files


def _own_log(path: Path) -> bool:
    """A log of this cache: one of its names, and the folder's record proves it ours."""
    return (path.name == _MERGED or _LOG_NAME.fullmatch(path.name) is not None) and is_ours(path)


def count_entries(folder) -> int:
    """Number of valid entries in the cache `folder` (distinct keys)."""
    return len(read_cache(folder)[0])


def merge_cache(folder, entries: dict[str, dict], files) -> Path:
    """Write `entries` (as read from the logs `files` by :func:`read_logs`) as one
    log of the cache `folder`, sorted by key and atomically, then remove `files`.
    Logs not listed (another run's), and any file the folder's record does not prove
    the cache's own, are left alone.

    Raises
    ------
    OutputError
        ``reason="not_ours"``: a ``merged.jsonl`` is there that this tool did not
        write (never replaced, not even with ``--force``).
    """
    folder = Path(folder)
    text = "".join(cache_line(key, json.dumps(entry, sort_keys=True)) for key, entry in sorted(entries.items()))
    merged = atomic_write_text(folder / _MERGED, text, durable=False, force=False)
    for path in map(Path, files):
        if path != merged and _own_log(path):
            try:
                os.unlink(path)
            except FileNotFoundError:
                pass
    return merged


class CacheLog:
    """One process's append-only log in the cache folder, opened on the first entry.

    Parameters
    ----------
    folder : str or os.PathLike
        The cache folder (created when needed).
    run : str
        A name for the run, shared by its processes' logs (so the run can find them).
    """

    def __init__(self, folder, run: str):
        self.folder = Path(folder)
        self.run = run
        self._fd: int | None = None

    @staticmethod
    def new_run() -> str:
        """A fresh, unique run name (12 hex digits of os.urandom, as
        ``secrets.token_hex(6)`` makes them, without importing secrets and hmac at
        every start-up)."""
        return os.urandom(6).hex()

    def files(self) -> list[Path]:
        """Logs of this run in the cache folder (of any of its processes)."""
        return sorted(self.folder.glob(f"run-{self.run}-*.jsonl"))

    def append(self, key: str, entry_json: str) -> None:
        """Append one entry: a single ``write`` of a whole line, without fsync.

        The log is created on the first entry; a file already of its name (not this
        run's) is never opened: :class:`FileExistsError`."""
        if self._fd is None:
            self.folder.mkdir(parents=True, exist_ok=True)
            path = self.folder / f"run-{self.run}-{os.getpid()}.jsonl"
            self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND, 0o644)
            record_created(path)
        line = cache_line(key, entry_json).encode("utf-8")
        if os.write(self._fd, line) != len(line):  # a full disk: a cut line is ignored on reading
            raise OSError(f"{self.folder}: short write to the cache log")

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
