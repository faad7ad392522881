"""One checker for every number a user gives: finite, representable, in its range.

Every number read from a user (a session.toml key, a command-line option, a rig
constant, a manifest cell) is checked here, so each refusal reads the same way and
names three things: the parameter, its value and the range it must lie in::

    rig.arm_radius_m must be a finite number > 0 (m), got -0.05

:func:`number_problem` returns that text without raising (for readers that list
every problem of a file at once); :func:`check_number` raises it as the caller's
:class:`~vision_torsion.errors.VisionTorsionError` subclass with reason
``bad_value``.

Magnitudes
----------
Besides the caller's range, every number must satisfy ``|value| <=``
:data:`MAX_MAGNITUDE` (1e12). No physical input of the toolkit (N·m, kg, m,
degrees, N·m/rad, pulses per revolution) comes near it, and products of a few such
numbers stay far below float64's largest value (1.8e308), so arithmetic on checked
inputs cannot overflow to ``inf``. An integer too large for a float (a 400-digit
TOML integer) is refused by the same rule, not by an ``OverflowError``.
"""

from __future__ import annotations

import math
import numbers

from .errors import VisionTorsionError

__all__ = ["MAX_MAGNITUDE", "describe_range", "number_problem", "check_number"]

#: Largest magnitude any user-given number may have (see the module docstring).
MAX_MAGNITUDE = 1e12


def describe_range(*, low=None, high=None, low_open: bool = False, high_open: bool = False,
                   whole: bool = False, unit: str = "", nonzero: bool = False) -> str:
    """The allowed range as the messages state it.

    >>> describe_range(low=0, low_open=True, unit="m")
    'a finite number > 0 (m)'
    >>> describe_range(low=1, whole=True)
    'a whole number >= 1'
    >>> describe_range(low=1e-3, high=2.0, unit="m")
    'a finite number in [0.001, 2] (m)'
    """
    kind = "a whole number" if whole else "a finite number"
    if low is not None and high is not None:
        text = f"{kind} in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    elif low is not None:
        text = f"{kind} {'>' if low_open else '>='} {low:g}"
    elif high is not None:
        text = f"{kind} {'<' if high_open else '<='} {high:g}"
    else:
        text = kind
    if nonzero:
        text += ", not 0"
    return f"{text} ({unit})" if unit else text


def number_problem(value, *, low=None, high=None, low_open: bool = False, high_open: bool = False,
                   whole: bool = False, nonzero: bool = False, unit: str = "") -> str | None:
    """Why `value` is not an acceptable number, or None when it is.

    Parameters
    ----------
    value : object
        The value as given: an ``int`` or ``float`` (not a ``bool``), or a numpy
        scalar; text, ``None``, lists and booleans are refused.
    low, high : float, optional
        The bounds of the range; inclusive unless `low_open` / `high_open`.
    whole : bool
        The value must be a whole number (``3`` or ``3.0``).
    nonzero : bool
        Zero is refused (a transmission ratio, whose sign is meaningful).
    unit : str
        Shown after the range (``"m"``, ``"N·m"``).

    Returns
    -------
    str or None
        ``"must be <range>, got <value>"``, where the range is
        :func:`describe_range` and a number beyond :data:`MAX_MAGNITUDE` adds
        "(its magnitude is limited to 1e+12)" unless the range is narrower; None
        when the value is acceptable.

    Examples
    --------
    >>> number_problem(0.05, low=0, low_open=True) is None
    True
    >>> number_problem("2,5,10", low=0)
    "must be a finite number >= 0, got '2,5,10'"
    >>> number_problem(10**400, low=0)
    'must be a finite number >= 0 (its magnitude is limited to 1e+12), got an integer of about 400 digits'
    """
    expected = describe_range(low=low, high=high, low_open=low_open, high_open=high_open,
                              whole=whole, unit=unit, nonzero=nonzero)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return f"must be {expected}, got {_shown(value)}"
    # the general limit is stated unless the range itself is narrower
    limited = expected if (low is not None and high is not None and -MAX_MAGNITUDE <= low
                           and high <= MAX_MAGNITUDE) else f"{expected} (its magnitude is limited to {MAX_MAGNITUDE:g})"
    try:
        v = float(value)
    except OverflowError:  # an integer beyond float's range
        return f"must be {limited}, got {_shown(value)}"
    if not math.isfinite(v):
        return f"must be {expected}, got {_shown(value)}"
    if abs(v) > MAX_MAGNITUDE:
        return f"must be {limited}, got {_shown(value)}"
    bad = ((whole and not v.is_integer())
           or (nonzero and v == 0)
           or (low is not None and (v <= low if low_open else v < low))
           or (high is not None and (v >= high if high_open else v > high)))
    return f"must be {expected}, got {_shown(value)}" if bad else None


def check_number(value, *, name: str, error: type[VisionTorsionError] = VisionTorsionError,
                 low=None, high=None, low_open: bool = False, high_open: bool = False,
                 whole: bool = False, nonzero: bool = False, unit: str = ""):
    """`value` as a float (an int when `whole`), or raise naming `name`, the value and the range.

    Parameters
    ----------
    value : object
        The number to check (see :func:`number_problem`).
    name : str
        The parameter as the user knows it (``"rig.arm_radius_m"``,
        ``"--step-mass"``, ``"rig constant teeth"``).
    error : VisionTorsionError subclass
        The error the caller documents; raised with reason ``bad_value``.
    low, high, low_open, high_open, whole, nonzero, unit
        The allowed range, as for :func:`number_problem`.

    Returns
    -------
    float or int

    Raises
    ------
    error
        ``"<name> must be <range>, got <value>"``.

    Examples
    --------
    >>> check_number(3.0, name="steps", low=1, whole=True)
    3
    >>> check_number(-0.05, name="rig.arm_radius_m", low=0, low_open=True, unit="m")
    Traceback (most recent call last):
    ...
    vision_torsion.errors.VisionTorsionError: rig.arm_radius_m must be a finite number > 0 (m), got -0.05
    """
    problem = number_problem(value, low=low, high=high, low_open=low_open, high_open=high_open,
                             whole=whole, nonzero=nonzero, unit=unit)
    if problem is not None:
        raise error(f"{name} {problem}", reason="bad_value")
    return int(value) if whole else float(value)


def _shown(value) -> str:
    """The value for a message; a huge integer by its digit count, long text cut."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 10**20:
        # by its bit length: str() of an integer of over 4300 digits raises
        return f"an integer of about {round(abs(value).bit_length() * math.log10(2))} digits"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
