"""Measuring a list of images: one bad image gets its reason and the others go on.

Every batch of the project (``measure`` over a folder, ``check-accuracy`` over a
reference table, ``process`` over a session) measures its images through
:func:`attempt` / :func:`measure_each`, with the measuring function passed in. So
the rule is written once: a :class:`~vision_torsion.errors.VisionTorsionError` is
that image's failure, with its message and ``reason`` code; any other exception is
a bug, reported as an ``internal error`` of that image only (its traceback logged
at DEBUG level: ``--debug`` shows it); ``KeyboardInterrupt`` and ``SystemExit`` stop the batch. Passing the
measuring function in is also the seam tests use to stand in for the measurement
core.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Callable, Iterable

from .errors import VisionTorsionError

__all__ = ["Attempt", "attempt", "measure_each", "INTERNAL_ERROR"]

logger = logging.getLogger(__name__)

#: ``reason`` of an :class:`Attempt` that failed on an unexpected exception (a bug).
INTERNAL_ERROR = "internal_error"


@dataclass(frozen=True)
class Attempt:
    """The outcome of measuring one item.

    Attributes
    ----------
    value : object or None
        What the measuring function returned; None when it failed.
    message : str
        Why it failed ("" when it did not).
    reason : str
        The error's ``reason`` code ("" when it did not fail; :data:`INTERNAL_ERROR`
        for an unexpected exception).
    """

    value: Any = None
    message: str = ""
    reason: str = ""

    @property
    def ok(self) -> bool:
        """True when the item was measured."""
        return not self.reason

    @property
    def unexpected(self) -> bool:
        """True when it failed on an unexpected exception (a bug, not bad input)."""
        return self.reason == INTERNAL_ERROR


def attempt(measure: Callable[[Any], Any], item, *, name: str = "") -> Attempt:
    """``measure(item)``, with a failure turned into an :class:`Attempt` with its reason.

    Parameters
    ----------
    measure : callable
        Takes `item`, returns its measurement.
    item : object
        What to measure (a path, an image, ...).
    name : str
        What the log calls the item when an unexpected exception is logged.

    Examples
    --------
    >>> from vision_torsion.errors import MarkerError
    >>> def measure(x):
    ...     if x < 0:
    ...         raise MarkerError(f"{x}: no markers", reason="no_markers")
    ...     return 2 * x
    >>> attempt(measure, 3)
    Attempt(value=6, message='', reason='')
    >>> attempt(measure, -1)
    Attempt(value=None, message='-1: no markers', reason='no_markers')
    """
    try:
        return Attempt(value=measure(item))
    except VisionTorsionError as exc:
        return Attempt(message=str(exc), reason=exc.reason)
    except Exception as exc:  # noqa: BLE001 - one broken image must not stop a batch
        logger.debug("unexpected error measuring %s", name or item, exc_info=exc)
        return Attempt(message=f"internal error: {type(exc).__name__}: {exc}", reason=INTERNAL_ERROR)


def measure_each(measure: Callable[[Any], Any], items: Iterable, *, names: Iterable[str] | None = None,
                 progress: bool = False, desc: str = "measuring") -> list[Attempt]:
    """:func:`attempt` on each item in order; failures are logged at DEBUG level (the
    caller reports them in its table).

    Parameters
    ----------
    measure : callable
        Takes one item, returns its measurement.
    items : iterable
        What to measure, in order.
    names : iterable of str, optional
        What the log calls each item (``str(item)`` by default).
    progress : bool
        Show a progress bar.
    desc : str
        The progress bar's label.

    Returns
    -------
    list of Attempt
        One per item, in order.
    """
    items = list(items)
    names = [str(i) for i in items] if names is None else list(names)
    out = []
    from .progress import track

    for item, name in track(list(zip(items, names)), desc=desc, unit="image", enabled=progress):
        done = attempt(measure, item, name=name)
        if not done.ok and not done.unexpected:
            logger.debug("%s", done.message)
        out.append(done)
    return out
