"""measure_each / attempt: the one rule for measuring a list of images."""

import logging

import pytest

from vision_torsion.batch import INTERNAL_ERROR, attempt, measure_each
from vision_torsion.errors import ImageReadError, MarkerError


def _measure(x):
    if x == "unreadable":
        raise ImageReadError(f"{x}: cannot be read")
    if x == "blank":
        raise MarkerError(f"{x}: found 0 marker(s), expected 2", reason="no_markers")
    if x == "bug":
        raise ZeroDivisionError("division by zero")
    return x.upper()


def test_each_item_gets_its_value_or_its_reason(caplog):
    with caplog.at_level(logging.DEBUG, logger="vision_torsion"):
        done = measure_each(_measure, ["a", "unreadable", "blank", "bug", "b"])
    assert [d.value for d in done] == ["A", None, None, None, "B"]
    assert [d.reason for d in done] == ["", "unreadable_image", "no_markers", INTERNAL_ERROR, ""]
    assert [d.ok for d in done] == [True, False, False, False, True]
    assert done[3].unexpected and done[3].message == "internal error: ZeroDivisionError: division by zero"
    assert "blank: found 0 marker(s)" in caplog.text  # expected failures are logged
    assert any(r.levelno == logging.DEBUG and r.exc_info for r in caplog.records)  # a bug keeps its traceback


def test_an_interrupt_stops_the_batch():
    def interrupted(x):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        attempt(interrupted, "a")
