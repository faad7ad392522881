"""Progress of long work: a bar on a terminal, plain lines everywhere else.

A progress bar redraws one line with carriage returns; in a CI log, a pipe or a
file that is noise, and without it a long command (the demo renders and measures
for minutes) prints nothing until it ends. :func:`progress_bar` therefore gives
tqdm's bar when the stream is a terminal and :class:`LineProgress` otherwise: one
line ``rendering: 120/444 images (27 %), 40 s, about 1 min 48 s left`` every
`interval_s` seconds, the first after `interval_s` (work that ends sooner prints
nothing, as before), and a last line when it ends.

The library never decides to show progress: callers pass ``enabled`` (the command
line: unless ``--quiet``).
"""

from __future__ import annotations

import sys
import time

__all__ = ["progress_bar", "track", "LineProgress", "PROGRESS_INTERVAL_S"]

#: Seconds between two progress lines when the output is not a terminal.
PROGRESS_INTERVAL_S = 5.0


def _duration(seconds: float) -> str:
    """``"1 min 48 s"``, ``"40 s"``."""
    s = int(round(seconds))
    return f"{s // 60} min {s % 60} s" if s >= 60 else f"{s} s"


class LineProgress:
    """Progress as plain lines, at most one per `interval_s` seconds.

    Parameters
    ----------
    total : int or None
        Items expected (None: unknown; no percentage or estimate).
    desc, unit : str
        What is done, and what an item is ("rendering", "image").
    stream : file-like
        Where the lines go (stderr by default).
    interval_s : float, optional
        Seconds between lines (:data:`PROGRESS_INTERVAL_S` by default); the first
        comes after one interval.
    clock : callable
        Seconds, monotonic (a parameter for tests).

    Examples
    --------
    >>> import io
    >>> t = iter(range(0, 100, 3))
    >>> out = io.StringIO()
    >>> bar = LineProgress(10, desc="rendering", unit="image", stream=out, interval_s=5, clock=lambda: next(t))
    >>> for _ in range(10):
    ...     bar.update()
    >>> bar.close()
    >>> print(out.getvalue().strip())
    rendering: 2/10 images (20 %), 6 s, about 24 s left
    rendering: 4/10 images (40 %), 12 s, about 18 s left
    rendering: 6/10 images (60 %), 18 s, about 12 s left
    rendering: 8/10 images (80 %), 24 s, about 6 s left
    rendering: 10/10 images (100 %), 30 s, about 0 s left
    rendering: done, 10 images in 33 s
    """

    def __init__(self, total=None, *, desc: str, unit: str = "image", stream=None,
                 interval_s: float | None = None, clock=time.monotonic):
        self.total, self.desc, self.unit = total, desc, unit
        self.stream = stream if stream is not None else sys.stderr
        self.interval_s = PROGRESS_INTERVAL_S if interval_s is None else interval_s
        self.clock = clock
        self.n = 0
        self.start = self.last = clock()
        self.printed = False

    def _plural(self, n) -> str:
        return self.unit if n == 1 else self.unit + "s"

    def update(self, n: int = 1) -> None:
        """`n` more items done; print a line when an interval has passed."""
        self.n += n
        now = self.clock()
        if now - self.last < self.interval_s:
            return
        self.last = now
        elapsed = now - self.start
        text = f"{self.desc}: {self.n}"
        if self.total:
            left = elapsed * (self.total - self.n) / self.n if self.n else None
            text += (f"/{self.total} {self._plural(self.total)} ({100 * self.n // self.total} %), "
                     f"{_duration(elapsed)}" + ("" if left is None else f", about {_duration(left)} left"))
        else:
            text += f" {self._plural(self.n)}, {_duration(elapsed)}"
        print(text, file=self.stream, flush=True)
        self.printed = True

    def close(self) -> None:
        """A last line, when any was printed (short work stays silent)."""
        if self.printed:
            print(f"{self.desc}: done, {self.n} {self._plural(self.n)} in {_duration(self.clock() - self.start)}",
                  file=self.stream, flush=True)
            self.printed = False

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


class _Quiet:
    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # a closed or unusual stream
        return False


def progress_bar(total=None, *, desc: str, unit: str = "image", enabled: bool = True, stream=None,
                 interval_s: float | None = None):
    """A progress indicator with ``update(n=1)`` and ``close()``.

    Returns
    -------
    tqdm.tqdm, LineProgress or a silent stand-in
        tqdm's bar when `enabled` and `stream` (stderr) is a terminal; plain lines
        (:class:`LineProgress`) when `enabled` and it is not; nothing otherwise.
    """
    if not enabled:
        return _Quiet()
    stream = stream if stream is not None else sys.stderr
    if _is_terminal(stream):
        from tqdm import tqdm  # here: importing it costs a quiet run 30-50 ms

        return tqdm(total=total, desc=desc, unit=unit, file=stream)
    return LineProgress(total, desc=desc, unit=unit, stream=stream, interval_s=interval_s)


def track(iterable, *, desc: str, unit: str = "image", enabled: bool = True, total=None, stream=None):
    """Iterate `iterable`, showing progress as :func:`progress_bar` does."""
    if total is None and hasattr(iterable, "__len__"):
        total = len(iterable)
    bar = progress_bar(total, desc=desc, unit=unit, enabled=enabled, stream=stream)
    try:
        for item in iterable:
            yield item
            bar.update()
    finally:
        bar.close()
