"""Atomic result writing: every result file appears whole or not at all.

A result is written to a temporary file in the destination folder and renamed over
the destination (``os.replace`` is atomic on POSIX and Windows), so an interrupted
run never leaves a half-written CSV or JSON behind.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["atomic_write_bytes", "atomic_write_text", "write_json", "write_csv"]


def atomic_write_bytes(path, data: bytes, *, durable: bool = True) -> Path:
    """Write `data` to `path` atomically, creating parent folders; return the path.

    With `durable` (the default) the data is flushed to the disk (fsync) before
    the rename, so that after a power cut the file holds either the old or the new
    content. Without it, a power cut may leave it empty; for files whose reader
    checks them anyway (cache entries) that saves a disk flush per file.
    """
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            if durable:
                fh.flush()
                os.fsync(fh.fileno())
        os.replace(tmp, p)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return p


def atomic_write_text(path, text: str, *, durable: bool = True) -> Path:
    """Write UTF-8 `text` to `path` atomically (see :func:`atomic_write_bytes`)."""
    return atomic_write_bytes(path, text.encode("utf-8"), durable=durable)


def _json_default(obj):
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return None if not np.isfinite(obj) else float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot write {type(obj).__name__} as JSON")


def _finite(obj):
    """Replace non-finite floats by None (JSON has no NaN); never by 0."""
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def write_json(path, obj) -> Path:
    """Write `obj` as indented JSON atomically; NaN and inf become null."""
    text = json.dumps(_finite(obj), indent=2, default=_json_default, allow_nan=False)
    return atomic_write_text(path, text + "\n")


def write_csv(path, frame) -> Path:
    """Write a pandas DataFrame as CSV (no index) atomically."""
    return atomic_write_text(path, frame.to_csv(index=False, lineterminator="\n"))
