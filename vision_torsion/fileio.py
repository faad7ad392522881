"""Writing results: atomically, following the umask, as a set, with errors that name the file.

- Every result file is written to a temporary file in the destination folder and
  renamed over the destination (``os.replace`` is atomic on POSIX and Windows), so an
  interrupted run never leaves a half-written CSV or JSON behind. The file gets the
  mode a plain ``open()`` would give it (``0o666`` less the umask), not ``mkstemp``'s
  private ``0o600``, so colleagues can read results.
- Inside :func:`output_set`, the files written are staged and renamed into place
  together at the end: either every file of the set is replaced, or (when one cannot
  be) none is, and the error says so. Commands that write several files that belong
  together (``stiffness``, ``report``, ``check-accuracy``) use it.
- :func:`check_output_dir` is called by every command before it measures anything:
  the output folder is created, a file is written into it and removed, so a
  read-only folder, a file where the folder should be, or a full disk are reported
  at once (naming the path and the reason) instead of after the work.
- Every ``OSError`` while writing becomes an :class:`~vision_torsion.errors.OutputError`
  naming the file and the reason in words.
- **The folder contract.** Every file written here is recorded in the record of
  its folder, :data:`RECORD_NAME` (one line per write: the name, its size and the
  XXH3-128 hash of the bytes written). A file already at the destination is
  replaced only when the record proves this tool wrote it, byte for byte; a file
  the tool did not write, or one changed since, is refused with an
  :class:`~vision_torsion.errors.OutputError` (``reason="not_ours"``) naming it and
  explaining ``--force`` (:func:`replacing_others`). New files need no proof;
  :func:`check_replaceable` lets a command refuse before its work.
"""

from __future__ import annotations

import errno
import json
import math
import os
import shutil
import tempfile
from contextlib import contextmanager
from contextvars import ContextVar
from functools import lru_cache
from pathlib import Path

from .errors import OutputError

__all__ = [
    "atomic_write_bytes",
    "atomic_write_text",
    "write_json",
    "json_text",
    "write_csv",
    "output_set",
    "check_output_dir",
    "os_reason",
    "file_mode",
    "format_float",
    "write_records_csv",
    "MIN_FREE_BYTES",
    "RECORD_NAME",
    "is_ours",
    "check_replaceable",
    "record_created",
    "replacing_others",
    "same_folder",
]

#: An output folder with less free space than this is refused before any work.
MIN_FREE_BYTES = 1 << 20

_REASONS = {
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "permission denied",
    errno.ENOSPC: "no space left on the device",
    errno.EDQUOT: "disk quota exceeded",
    errno.ENOTDIR: "a file is in the way where a folder should be",
    errno.EISDIR: "a folder is in the way where the file should be",
    errno.EEXIST: "a file is in the way where a folder should be",
    errno.ENAMETOOLONG: "file name too long",
    errno.ETXTBSY: "the file is in use",
}


def os_reason(exc: OSError) -> str:
    """The reason of an ``OSError`` in words (``"read-only file system"``, ...)."""
    return _REASONS.get(exc.errno, exc.strerror or str(exc))


@lru_cache(maxsize=1)
def file_mode() -> int:
    """The mode of a file this package creates: ``0o666`` less the process's umask.

    The umask is read once (setting it is the only way to read it) and kept; a
    program that changes its umask afterwards calls ``file_mode.cache_clear()``.
    """
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


_staged: ContextVar[list | None] = ContextVar("vision_torsion_staged_outputs", default=None)
_force: ContextVar[bool] = ContextVar("vision_torsion_replace_others", default=False)

#: The record, in every folder this tool writes into, of the files it wrote there.
RECORD_NAME = ".vision-torsion-files"
_RECORD_HEADER = "# vision-torsion: files this tool wrote in this folder (name, size, xxh3-128)\n"
#: The hash field of a file created to be appended to (a log): its name is proof enough.
_APPENDED = "appended"
_FORCE_HINT = ("move it away, choose another output folder, or give --force to replace "
               "files vision-torsion did not write")


@contextmanager
def replacing_others(allowed: bool = True):
    """Inside, files the tool cannot prove it wrote may be replaced (``--force``).

    Writers that must never replace another program's file (the cache) pass
    ``force=False`` to :func:`atomic_write_bytes` and are not affected.
    """
    token = _force.set(bool(allowed))
    try:
        yield
    finally:
        _force.reset(token)


def _digest(data: bytes) -> str:
    import xxhash  # here: a command that writes nothing does not import it

    return xxhash.xxh3_128_hexdigest(data)


def _read_record(folder: Path) -> dict[str, tuple[int, str]] | None:
    """name -> (size, hash) of the record in `folder` (the last line of a name wins);
    ``{}`` when there is no record, None when a file of that name is not a record.
    An unreadable record raises its ``OSError``."""
    try:
        # surrogateescape: a file name that is not UTF-8 reads back as it was written
        text = (folder / RECORD_NAME).read_bytes().decode("utf-8", "surrogateescape")
    except FileNotFoundError:
        return {}
    if not text.startswith(_RECORD_HEADER):
        return None
    entries: dict[str, tuple[int, str]] = {}
    for line in text[len(_RECORD_HEADER):].split("\n")[:-1]:  # a cut last line is ignored
        parts = line.rsplit("\t", 2)
        if len(parts) == 3 and parts[1].isdigit():
            entries[parts[0]] = (int(parts[1]), parts[2])
    return entries


def _append_record(folder: Path, lines: list[str]) -> None:
    """Append record lines with one ``write`` (O_APPEND: concurrent writers do not
    interleave lines); a record that is not ours is never written to."""
    path = folder / RECORD_NAME
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND, file_mode())
        data = _RECORD_HEADER
    except FileExistsError:
        try:
            ours = _read_record(folder) is not None
            fd = os.open(path, os.O_WRONLY | os.O_APPEND) if ours else -1
        except OSError as exc:
            raise OutputError(f"{path}: cannot write ({os_reason(exc)})") from exc
        if not ours:
            raise OutputError(f"{path}: not replaced: vision-torsion keeps its record of the files it "
                              "wrote under this name, and this file is not that record; move it away",
                              reason="not_ours") from None
        data = ""
    except OSError as exc:
        raise OutputError(f"{path}: cannot write ({os_reason(exc)})") from exc
    try:
        os.write(fd, (data + "".join(lines)).encode("utf-8", "surrogateescape"))
        size = os.fstat(fd).st_size
    except OSError as exc:
        raise OutputError(f"{path}: cannot write ({os_reason(exc)})") from exc
    finally:
        os.close(fd)
    if size > _RECORD_COMPACT_BYTES:
        _compact_record(folder)


#: A record longer than this is rewritten with the last line of each name only.
_RECORD_COMPACT_BYTES = 1 << 18


def _compact_record(folder: Path) -> None:
    """Rewrite the record with one line per name still present. A line appended by
    another process during the rewrite may be lost: that file is then refused as
    not proven ours (the safe side), never replaced unproven."""
    try:
        entries = _read_record(folder)
    except OSError:  # the long record still holds: compaction is only tidiness
        return
    if not entries:
        return
    text = _RECORD_HEADER + "".join(_record_line(name, size, digest)
                                    for name, (size, digest) in entries.items()
                                    if os.path.lexists(folder / name))
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{RECORD_NAME}.", suffix=".tmp", dir=folder)
    except OSError:  # the long record still holds: compaction is only tidiness
        return
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(text.encode("utf-8", "surrogateescape"))
        os.replace(tmp, folder / RECORD_NAME)
    except OSError:
        _unlink(tmp)


def _record_line(name: str, size: int, digest: str) -> str:
    if "\n" in name or "\t" in name:  # a name the record cannot hold is never proven ours
        return ""
    return f"{name}\t{size}\t{digest}\n"


def record_created(path) -> None:
    """Record `path` as a file this tool created to append to (a cache log): its name
    in the record proves it ours, whatever it holds."""
    p = Path(path)
    line = _record_line(p.name, 0, _APPENDED)
    if line:
        _append_record(p.parent, [line])


def is_ours(path) -> bool:
    """Whether the record of `path`'s folder proves this tool wrote the file there now
    (the same size and hash as recorded; for a log, its name recorded)."""
    p = Path(path)
    try:
        entry = (_read_record(p.parent) or {}).get(p.name)
        if entry is None:
            return False
        size, digest = entry
        if digest == _APPENDED:
            return True
        if os.stat(p).st_size != size:
            return False
        return _digest(p.read_bytes()) == digest
    except OSError:
        return False


def check_replaceable(paths, *, force: bool | None = None) -> None:
    """Refuse, before any work, to replace a file in `paths` the tool did not write.

    Parameters
    ----------
    paths : iterable of path
        Files a command is about to write. Missing ones are fine.
    force : bool, optional
        Replace them anyway; default: inside :func:`replacing_others`.

    Raises
    ------
    OutputError
        ``reason="not_ours"``: a file is there that the folder's record does not
        prove this tool wrote (another program's, or changed since); the message
        names it and explains ``--force``.
    """
    if _force.get() if force is None else force:
        return
    for path in paths:
        p = Path(path)
        if os.path.lexists(p) and not p.is_dir() and not is_ours(p):
            raise OutputError(f"{p}: not replaced: vision-torsion did not write this file (or it "
                              f"was changed since); {_FORCE_HINT}", reason="not_ours")


def atomic_write_bytes(path, data: bytes, *, durable: bool = True, force: bool | None = None) -> Path:
    """Write `data` to `path` atomically, creating parent folders; return the path.

    With `durable` (the default) the data is flushed to the disk (fsync) before
    the rename, so that after a power cut the file holds either the old or the new
    content. Without it, a power cut may leave it empty; for files whose reader
    checks them anyway (cache entries) that saves a disk flush per file. Inside
    :func:`output_set` the file is only staged; it is renamed into place with the
    rest of the set. The write is recorded in the folder's record; a file at `path`
    the record does not prove ours is refused (the folder contract, module docstring)
    unless `force` (default: inside :func:`replacing_others`).

    Raises
    ------
    OutputError
        The file or its folder cannot be written; the message names the path and
        the reason (read-only, permission, no space, a file or folder in the way,
        ``reason="not_ours"``: a file this tool did not write).
    """
    p = Path(path)
    check_replaceable([p], force=force)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    except OSError as exc:
        raise OutputError(f"{p}: cannot write ({os_reason(exc)})") from exc
    try:
        with os.fdopen(fd, "wb") as fh:
            os.fchmod(fh.fileno(), file_mode())
            fh.write(data)
            if durable:
                fh.flush()
                os.fsync(fh.fileno())
        line = _record_line(p.name, len(data), _digest(data))
        staged = _staged.get()
        if staged is not None:
            staged.append((Path(tmp), p, line))
            return p
        os.replace(tmp, p)
    except BaseException as exc:
        _unlink(tmp)
        if isinstance(exc, OSError):
            raise OutputError(f"{p}: cannot write ({os_reason(exc)})") from exc
        raise
    if line:
        _append_record(p.parent, [line])
    return p


def _unlink(path) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


@contextmanager
def output_set():
    """Files written inside are replaced together at the end, or none of them is.

    Every :func:`atomic_write_bytes` (and the writers built on it) inside the block
    writes its temporary file as usual but defers the rename. When the block ends
    without error, every destination is checked (a folder in the way), the files
    already there are kept as hard-linked backups, and the temporary files are
    renamed into place; if one rename fails, the ones done are undone from the
    backups. When the block raises, no file is replaced. Nested blocks join the
    outermost one.

    Raises
    ------
    OutputError
        A file of the set cannot be written; the message names it and says that
        no file of the set was replaced.
    """
    if _staged.get() is not None:
        yield
        return
    staged: list[tuple[Path, Path, str]] = []
    token = _staged.set(staged)
    try:
        yield
    except BaseException:
        for tmp, _, _ in staged:
            _unlink(tmp)
        raise
    finally:
        _staged.reset(token)
    _commit(staged)


def _commit(staged: list[tuple[Path, Path, str]]) -> None:
    n = len(staged)

    def fail(dest: Path, why: str, cause=None):
        for tmp, _, _ in staged:
            _unlink(tmp)
        raise OutputError(f"{dest}: cannot write ({why}); none of the {n} result files of "
                          "this set was replaced") from cause

    for _, dest, _ in staged:
        if dest.is_dir():
            fail(dest, "a folder is in the way where the file should be")
    backups: dict[Path, Path | None] = {}
    done: list[Path] = []
    try:
        for tmp, dest, _ in staged:
            backup = None
            if dest.exists():  # a fresh name: nothing of anyone else's is removed
                backup = dest.with_name(f".{dest.name}.{os.getpid()}.{os.urandom(6).hex()}.bak")
                try:
                    os.link(dest, backup)
                except OSError:
                    shutil.copy2(dest, backup)
            backups[dest] = backup
        for tmp, dest, _ in staged:
            os.replace(tmp, dest)
            done.append(dest)
    except OSError as exc:
        for dest in done:  # undo: the old file back, or no file where there was none
            backup = backups.get(dest)
            try:
                if backup is not None:
                    os.replace(backup, dest)
                else:
                    os.unlink(dest)
            except OSError:
                pass
        failed = staged[len(done)][1] if len(done) < n else staged[-1][1]
        for backup in backups.values():
            if backup is not None:
                _unlink(backup)
        fail(failed, os_reason(exc), exc)
    for backup in backups.values():
        if backup is not None:
            _unlink(backup)
    by_folder: dict[Path, list[str]] = {}
    for _, dest, line in staged:
        if line:
            by_folder.setdefault(dest.parent, []).append(line)
    for folder, lines in by_folder.items():
        _append_record(folder, lines)


def same_folder(a, b) -> bool:
    """Whether paths `a` and `b` name the same place, symbolic links followed as far
    as they go. Never raises: a link that loops compares as itself (``Path.resolve``
    raises RuntimeError for one before Python 3.13), so the output folder's own check
    can name it."""
    return os.path.realpath(a) == os.path.realpath(b)


def check_output_dir(path, *, need_bytes: int = MIN_FREE_BYTES, replaces=()) -> Path:
    """Create the output folder `path` if needed and make sure results can be written there.

    Called before any measuring, so that a run never does its work and then fails
    to write it.

    Parameters
    ----------
    path : str or os.PathLike
        The output folder.
    need_bytes : int
        Free space required (bytes); less is refused as "no space".
    replaces : iterable of str
        Names (relative to `path`) of the files the command will write: one there
        that this tool cannot prove it wrote is refused now (:func:`check_replaceable`).

    Returns
    -------
    pathlib.Path

    Raises
    ------
    OutputError
        The path is a file (or lies under one) or a symbolic link that leads
        nowhere, the folder cannot be created or
        written (read-only file system, permission denied), or the disk has less
        than `need_bytes` free; or (``reason="not_ours"``) a file of `replaces` is
        not the tool's own. The message names the path and the reason.
    """
    p = Path(path)
    check_replaceable(p / name for name in replaces)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{p}: cannot write results there: it is a file, not a folder")
    if p.is_symlink() and not p.exists():
        raise OutputError(f"{p}: cannot create the output folder: a symbolic link that leads nowhere "
                          "(it loops, or its target is missing)")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{p}: cannot create the output folder ({os_reason(exc)})") from exc
    try:
        fd, probe = tempfile.mkstemp(prefix=".write-test.", dir=p)
    except OSError as exc:
        raise OutputError(f"{p}: cannot write into the output folder ({os_reason(exc)})") from exc
    try:
        os.write(fd, b"\0")
    except OSError as exc:
        raise OutputError(f"{p}: cannot write into the output folder ({os_reason(exc)})") from exc
    finally:
        os.close(fd)
        _unlink(probe)
    free = shutil.disk_usage(p).free
    if free < need_bytes:
        raise OutputError(f"{p}: no space left on the device for the results "
                          f"({free // 1024} kB free, {need_bytes // 1024} kB needed)")
    return p


def format_float(x: float) -> str:
    """The shortest text that reads back as `x` rounded to 15 significant digits.

    ``0.36 * 0.981`` is ``0.35316000000000003`` in binary floating point; written as
    ``0.35316``. 15 digits keep everything a double holds reliably (the 16th and
    17th digits only carry the rounding of the arithmetic). NaN is written empty.
    """
    if not math.isfinite(x):
        return "" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    return repr(float(f"{x:.15g}"))


def _json_default(obj):
    import numpy as np

    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return None if not np.isfinite(obj) else float(f"{float(obj):.15g}")
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot write {type(obj).__name__} as JSON")


def _finite(obj):
    """Non-finite floats become None (JSON has no NaN; never 0); finite ones are
    rounded to 15 significant digits (:func:`format_float`)."""
    if isinstance(obj, float):
        return float(f"{obj:.15g}") if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def atomic_write_text(path, text: str, *, durable: bool = True, force: bool | None = None) -> Path:
    """Write UTF-8 `text` to `path` atomically (see :func:`atomic_write_bytes`); a
    character UTF-8 cannot hold (a non-UTF-8 file name's byte) is written as an
    escape, never a crash."""
    return atomic_write_bytes(path, text.encode("utf-8", "backslashreplace"), durable=durable, force=force)


def json_text(obj) -> str:
    """`obj` as indented JSON text, as :func:`write_json` writes it: NaN and inf
    become null, floats 15 significant digits, numpy values and paths as plain ones."""
    return json.dumps(_finite(obj), indent=2, default=_json_default, allow_nan=False) + "\n"


def write_json(path, obj) -> Path:
    """Write `obj` as indented JSON atomically (:func:`json_text`); NaN and inf become null."""
    return atomic_write_text(path, json_text(obj))


def write_csv(path, frame) -> Path:
    """Write a pandas DataFrame as CSV (no index) atomically; floats by
    :func:`format_float` (shortest text, 15 significant digits), NaN empty."""
    floats = [c for c in frame.columns if frame[c].dtype.kind == "f"]
    if floats:
        frame = frame.copy()
        for c in floats:
            frame[c] = [float(f"{x:.15g}") for x in frame[c].to_numpy()]
    return atomic_write_text(path, frame.to_csv(index=False, lineterminator="\n"))


def write_records_csv(path, columns, records) -> Path:
    """Write dict `records` under `columns` as CSV atomically, without pandas.

    The same text :func:`write_csv` writes for the same table (floats by
    :func:`format_float`, NaN and None empty, minimal quoting, ``\\n`` line ends), for
    commands that need no other part of pandas (``process`` saves its ~0.4 s import).
    """
    import csv
    import io

    def cell(value):
        if value is None:
            return ""
        if isinstance(value, float):
            return format_float(value) if math.isfinite(value) else ("" if math.isnan(value) else format_float(value))
        return value

    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for rec in records:
        writer.writerow([cell(rec.get(c)) for c in columns])
    return atomic_write_text(path, buf.getvalue())
