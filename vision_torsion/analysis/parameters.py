"""The options of :func:`.session.analyze_session`, checked once: :class:`AnalysisOptions`.

Every number is checked by :func:`vision_torsion.validate.check_number` (the message
names the option, its value and the allowed range); what is not a single number (a
pair that must be ordered, a list that must not be empty) has its own message naming
the option. The figure families read the options as attributes, never from a dict.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ..errors import AnalysisError
from ..measurements import TorqueRig
from ..validate import check_number
from .uncertainty import COVERAGE_FACTOR, check_rig

__all__ = ["AnalysisOptions"]


def _fraction(value, name: str, *, open_ends: bool) -> float:
    return check_number(value, name=name, error=AnalysisError, low=0, high=1, low_open=open_ends,
                        high_open=open_ends)


def _items(value, name: str, expected: str, count: int | None = None) -> list:
    """`value` as a list (of `count` items when given; else not empty), or an error naming `name` and what was
    `expected`."""
    try:
        items = list(value)
    except TypeError:
        items = []
    if (count is not None and len(items) != count) or not items:
        raise AnalysisError(f"{name} must be {expected}, got {value!r}", reason="bad_value")
    return items


def _ordered_pair(value, name: str, rule: str, *, strict_low: bool) -> tuple[float, float]:
    """Two torques (N·m), the first > 0 (`strict_low`) or >= 0, the second larger; `rule` states that."""
    lo, hi = (check_number(v, name=f"{name}[{j}]", error=AnalysisError, low=0, low_open=strict_low and j == 0,
                           unit="N·m") for j, v in enumerate(_items(value, name, f"two torques, {rule} (N·m)", 2)))
    if not lo < hi:
        raise AnalysisError(f"{name} must be two torques, {rule} (N·m), got {value}", reason="bad_value")
    return lo, hi


@dataclass(frozen=True, kw_only=True)
class AnalysisOptions:
    """What :func:`.session.analyze_session` computes and how; checked when made.

    Parameters
    ----------
    max_torque_nm : float, optional
        Maximum test torque, N·m, > 0 (default: the largest ``|torque_nm|`` of the
        usable loop images, filled in by :meth:`for_data`): the secant interval's
        fractions refer to it.
    rated_torque_nm : float, optional
        The gear's rated torque T_R, N·m, > 0: lost motion is evaluated at
        ``±fraction·T_R``. Without it, at ``±fraction·max_torque_nm`` (and the
        settings' ``lost_motion_reference`` says so).
    catalogue_breaks_nm : (float, float), optional
        The catalogue's T1, T2 (N·m, ``0 < T1 < T2``): K1, K2, K3 by linear least
        squares with these breaks fixed.
    fit_breaks : bool
        Without catalogue breaks, fit them (one or two, :mod:`.catalogue`).
    secant_interval_nm : (float, float), optional
        Secant interval in N·m, ``0 <= a < b`` (overrides ``secant_interval``).
    gear_ratio : float, optional
        Transmission ratio i (input turns per output turn), > 0: stiffnesses are also
        given on the output side, ``K_out = i²·K_in``.
    torque_correlation : {"pieces", "level", "independent"}, optional
        Error model of the torques (see :mod:`.uncertainty`). Default: ``"pieces"``
        when ``rig`` is given, else ``"level"``.
    rig : TorqueRig or mapping, optional
        Rig constants for the ``"pieces"`` model (:func:`.uncertainty.check_rig`);
        stored as a :class:`~vision_torsion.measurements.TorqueRig`.
    lost_motion_fractions : sequence of float
        Fractions in (0, 1) of T_R (or the max torque) for the lost-motion figures;
        3 % and 4 % by default (GB/T 35089 and the catalogues).
    secant_interval : (float, float)
        Secant stiffness interval as fractions ``0 <= a < b <= 1`` of ``max_torque_nm``.
    n_draws : int
        Monte Carlo draws per error source and loop, >= 10.
    seed : int
        Base seed, >= 0; loop ``i`` uses ``seed + i``.
    fit_bouc_wen : bool
        Fit the Bouc–Wen model too (slow, ≈0.1–0.5 s per loop).
    fit_preisach : bool
        Fit the Preisach model (:mod:`.preisach`), also used to find outliers.
    torque_model_declared : bool
        False when the caller has no torque-error model to declare (a table analysed
        without its rig and without explicit rig options): then, without a ``rig``,
        every figure is flagged ``TORQUE_NOT_MODELLED`` (:mod:`.rows`).

    Raises
    ------
    AnalysisError
        An option out of its range (reason ``bad_value``; the message names the
        option, its value and the range), or a rig that :func:`.uncertainty.check_rig`
        refuses.

    Examples
    --------
    >>> AnalysisOptions(n_draws=50).for_data(0.35).secant_interval_nm
    (0.175, 0.35)
    >>> AnalysisOptions(n_draws=5)
    Traceback (most recent call last):
    ...
    vision_torsion.errors.AnalysisError: n_draws must be a whole number >= 10, got 5
    """

    max_torque_nm: float | None = None
    rated_torque_nm: float | None = None
    catalogue_breaks_nm: tuple[float, float] | None = None
    fit_breaks: bool = True
    secant_interval_nm: tuple[float, float] | None = None
    gear_ratio: float | None = None
    torque_correlation: str | None = None
    rig: TorqueRig | None = None
    lost_motion_fractions: tuple[float, ...] = (0.03, 0.04)
    secant_interval: tuple[float, float] = (0.5, 1.0)
    n_draws: int = 400
    seed: int = 0
    fit_bouc_wen: bool = False
    fit_preisach: bool = True
    torque_model_declared: bool = True

    def __post_init__(self):
        def put(name, value):
            object.__setattr__(self, name, value)

        put("n_draws", check_number(self.n_draws, name="n_draws", error=AnalysisError, low=10, whole=True))
        put("seed", check_number(self.seed, name="seed", error=AnalysisError, low=0, whole=True))
        a, b = (_fraction(v, f"secant_interval[{j}]", open_ends=False)
                for j, v in enumerate(_items(self.secant_interval, "secant_interval", "two fractions (a, b)", 2)))
        if not a < b:
            raise AnalysisError(f"secant_interval must be fractions 0 <= a < b <= 1 of the max torque, got "
                                f"{self.secant_interval}", reason="bad_value")
        put("secant_interval", (a, b))
        fractions = tuple(_fraction(v, f"lost_motion_fractions[{j}]", open_ends=True)
                          for j, v in enumerate(_items(self.lost_motion_fractions, "lost_motion_fractions",
                                                 "a non-empty list of fractions in (0, 1)")))
        put("lost_motion_fractions", fractions)
        for name in ("max_torque_nm", "rated_torque_nm", "gear_ratio"):
            value = getattr(self, name)
            if value is not None:
                put(name, check_number(value, name=name, error=AnalysisError, low=0, low_open=True,
                                       unit="" if name == "gear_ratio" else "N·m"))
        if self.catalogue_breaks_nm is not None:
            put("catalogue_breaks_nm", _ordered_pair(self.catalogue_breaks_nm, "catalogue_breaks_nm",
                                                     "(T1, T2) with 0 < T1 < T2", strict_low=True))
        if self.secant_interval_nm is not None:
            put("secant_interval_nm", _ordered_pair(self.secant_interval_nm, "secant_interval_nm",
                                                    "(a, b) with 0 <= a < b", strict_low=False))
        for name in ("fit_breaks", "fit_bouc_wen", "fit_preisach", "torque_model_declared"):
            put(name, bool(getattr(self, name)))
        if self.rig is not None:
            put("rig", check_rig(self.rig))
        if self.torque_correlation is None:
            put("torque_correlation", "level" if self.rig is None else "pieces")

    def for_data(self, data_max_nm: float) -> AnalysisOptions:
        """These options with what the data decide filled in: ``max_torque_nm`` (when not given, the data's
        largest ``|torque|``, N·m) and ``secant_interval_nm`` (when not given, ``secant_interval`` of it)."""
        top = float(data_max_nm) if self.max_torque_nm is None else self.max_torque_nm
        interval = self.secant_interval_nm
        if interval is None:
            interval = (self.secant_interval[0] * top, self.secant_interval[1] * top)
        return dataclasses.replace(self, max_torque_nm=top, secant_interval_nm=interval)

    @property
    def lost_motion_reference_nm(self) -> float:
        """The torque the lost-motion fractions refer to (N·m): T_R when given, else the max torque."""
        return self.rated_torque_nm if self.rated_torque_nm is not None else self.max_torque_nm

    @property
    def torque_modelled(self) -> bool:
        """False when the torques' error model is missing (not declared, and no rig)."""
        return self.torque_model_declared or self.rig is not None

    def settings(self) -> dict:
        """The options as summary.json's ``settings`` (after :meth:`for_data`)."""
        return {
            "max_torque_nm": self.max_torque_nm,
            "torque_correlation": self.torque_correlation,
            "lost_motion_fractions": list(self.lost_motion_fractions),
            "lost_motion_reference_nm": self.lost_motion_reference_nm,
            "lost_motion_reference": "rated torque T_R"
            if self.rated_torque_nm is not None
            else "maximum test torque (no rated torque given)",
            "rated_torque_nm": self.rated_torque_nm,
            "secant_interval": list(self.secant_interval),
            "secant_interval_nm": list(self.secant_interval_nm),
            "catalogue_breaks_nm": None if self.catalogue_breaks_nm is None else list(self.catalogue_breaks_nm),
            "fit_breaks": self.fit_breaks,
            "gear_ratio": self.gear_ratio,
            "n_draws": self.n_draws,
            "seed": self.seed,
            "fit_bouc_wen": self.fit_bouc_wen,
            "fit_preisach": self.fit_preisach,
            "coverage_factor": COVERAGE_FACTOR,
            "rig": None if self.rig is None else self.rig.to_dict(),
            "torque_uncertainty_modelled": self.torque_modelled,
        }
