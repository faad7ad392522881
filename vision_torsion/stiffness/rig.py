"""Rig constants of a torque-angle test stand and the input-to-output angle conversion.

The encoder/torque-sensor rig of the stiffness paper drives the input shaft of the
gear with a stepper motor and measures the output torque with a torque sensor
between the output shaft and the frame. The output twist of the gear is the input
angle divided by the transmission ratio, minus the twist of the torque sensor
itself (the sensor is a spring in series with the gear)::

    theta_in  = 2*pi * N / P                       [rad]
    theta_out = theta_in / i  -  T / K_sensor      [rad]

with N the input pulses, P the pulses per input revolution, i the transmission
ratio (input angle / output angle), T the measured torque (N·m) and K_sensor the
torsional stiffness of the sensor (N·m/rad).

Rig constants come from a TOML file with two tables::

    [rig]
    pulses_per_rev = 51200              # input pulses per input revolution
    transmission_ratio = 100            # i = input angle / output angle
    sensor_stiffness_nm_per_rad = 20000 # K_sensor; omit for a rig without sensor twist

    [meshing]
    teeth = 160                          # flexspline tooth count z
    tooth_stiffness_nm_per_rad = 330     # single-tooth stiffness Ks, or instead:
    # reference_torque_nm = 10           # calibrate Ks from a reference point:
    # reference_pairs = 37               #   Ks = K(reference_torque) / reference_pairs
    # check_torque_nm = [2, 5, 10, 20]   # independent meshing-pair counts (e.g. from a
    # check_pairs = [15, 28, 37, 46]     #   simulation) for the K-against-n linearity check

Every key is optional; the checks that need a constant say which one is missing.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..errors import RigError
from ..textfiles import read_toml
from ..validate import check_number

__all__ = ["RigConstants", "load_rig", "pulses_to_input_deg", "output_angle_deg"]

_TABLES = {
    "rig": ("pulses_per_rev", "transmission_ratio", "sensor_stiffness_nm_per_rad"),
    "meshing": (
        "teeth",
        "tooth_stiffness_nm_per_rad",
        "reference_torque_nm",
        "reference_pairs",
        "check_torque_nm",
        "check_pairs",
    ),
}


def _positive(name: str, value, *, allow_none: bool = True) -> float | None:
    """A scalar constant: finite and > 0 (None when not given)."""
    if value is None and allow_none:
        return None
    return check_number(value, name=f"rig constant {name}", error=RigError, low=0, low_open=True)


@dataclass(frozen=True)
class RigConstants:
    """Constants of a torque-angle rig and of the gear's meshing model.

    Parameters
    ----------
    pulses_per_rev : float, optional
        Input pulses per revolution of the input shaft (stepper steps times
        microsteps, or encoder counts). Needed only for a record with pulses.
    transmission_ratio : float
        i = input angle / output angle (dimensionless). Must be finite and non-zero;
        a negative ratio means the output turns the other way.
    sensor_stiffness_nm_per_rad : float, optional
        Torsional stiffness of the torque sensor, N·m/rad. None means the rig has no
        sensor in series (its twist is not subtracted).
    teeth : int, optional
        Flexspline tooth count z.
    tooth_stiffness_nm_per_rad : float, optional
        Equivalent torsional stiffness Ks of one fully meshing tooth pair, N·m/rad.
    reference_torque_nm, reference_pairs : float, optional
        A reference point (torque, effective meshing pairs) to calibrate Ks from the
        measured stiffness when Ks is not given.
    check_torque_nm, check_pairs : tuple of float, optional
        Independent meshing-pair counts at given torques (at least 3) for the check
        that K against n is linear.

    Raises
    ------
    RigError
        A constant is not a finite positive number (a zero transmission ratio, a
        negative stiffness, ...), or the paired constants are incomplete.

    Examples
    --------
    >>> rig = RigConstants(pulses_per_rev=51200, transmission_ratio=100)
    >>> rig.transmission_ratio
    100.0
    >>> RigConstants(transmission_ratio=0)
    Traceback (most recent call last):
    ...
    vision_torsion.errors.RigError: rig constant transmission_ratio must be a finite number, not 0, got 0
    """

    pulses_per_rev: float | None = None
    transmission_ratio: float = 1.0
    sensor_stiffness_nm_per_rad: float | None = None
    teeth: int | None = None
    tooth_stiffness_nm_per_rad: float | None = None
    reference_torque_nm: float | None = None
    reference_pairs: float | None = None
    check_torque_nm: tuple[float, ...] | None = None
    check_pairs: tuple[float, ...] | None = None

    def __post_init__(self):
        r = check_number(self.transmission_ratio, name="rig constant transmission_ratio", error=RigError,
                         nonzero=True)
        object.__setattr__(self, "transmission_ratio", r)
        for name in (
            "pulses_per_rev",
            "sensor_stiffness_nm_per_rad",
            "tooth_stiffness_nm_per_rad",
            "reference_torque_nm",
            "reference_pairs",
        ):
            object.__setattr__(self, name, _positive(name, getattr(self, name)))
        if self.teeth is not None:
            object.__setattr__(self, "teeth", check_number(self.teeth, name="rig constant teeth", error=RigError,
                                                           low=1, whole=True))
        if (self.reference_torque_nm is None) != (self.reference_pairs is None):
            raise RigError(
                "rig constants reference_torque_nm and reference_pairs must be given together"
            )
        self._check_table()

    def _check_table(self):
        torque, pairs = self.check_torque_nm, self.check_pairs
        if torque is None and pairs is None:
            return
        if torque is None or pairs is None:
            raise RigError("rig constants check_torque_nm and check_pairs must be given together")
        for name, value in (("check_torque_nm", torque), ("check_pairs", pairs)):
            if isinstance(value, (str, bytes, dict)) or np.ndim(value) != 1:
                raise RigError(f"rig constant {name} must be a list of numbers, got {value!r}")
        torque = tuple(check_number(v, name=f"rig constant check_torque_nm[{i}]", error=RigError)
                       for i, v in enumerate(torque))
        pairs = tuple(_positive(f"check_pairs[{i}]", v) for i, v in enumerate(pairs))
        if len(torque) != len(pairs) or len(torque) < 3:
            raise RigError(
                "rig constants check_torque_nm and check_pairs must be lists of equal "
                f"length >= 3, got {len(torque)} and {len(pairs)}"
            )
        object.__setattr__(self, "check_torque_nm", torque)
        object.__setattr__(self, "check_pairs", pairs)

    @classmethod
    def from_dict(cls, d: dict) -> "RigConstants":
        """Build from the parsed TOML (tables ``[rig]`` and ``[meshing]``).

        Raises
        ------
        RigError
            An unknown table or key (named in the message), or an invalid value.
        """
        kwargs = {}
        for table, value in d.items():
            if table not in _TABLES or not isinstance(value, dict):
                raise RigError(
                    f"unknown rig table [{table}]; expected tables {sorted(_TABLES)}"
                )
            unknown = set(value) - set(_TABLES[table])
            if unknown:
                raise RigError(
                    f"unknown rig constant(s) in [{table}]: {', '.join(sorted(unknown))}; "
                    f"known: {', '.join(_TABLES[table])}"
                )
            kwargs.update(value)
        return cls(**kwargs)

    def to_dict(self) -> dict:
        """Plain dict in the TOML layout (None values left out)."""
        flat = {
            k: list(v) if isinstance(v, tuple) else v
            for k, v in asdict(self).items()
            if v is not None
        }
        return {table: {k: flat[k] for k in keys if k in flat} for table, keys in _TABLES.items()}


def load_rig(path) -> RigConstants:
    """Read rig constants from a TOML file.

    Parameters
    ----------
    path : str or Path
        TOML file with ``[rig]`` and/or ``[meshing]`` tables (see module docstring).

    Returns
    -------
    RigConstants

    Raises
    ------
    RigError
        The file is missing or not valid TOML (message names the file), or a constant
        is invalid (message names the constant).
    """
    p = Path(path)
    data = read_toml(p, what="a rig file of constants (TOML)", error=RigError)
    try:
        return RigConstants.from_dict(data)
    except RigError as exc:
        raise RigError(f"rig file {p}: {exc}") from None


def output_angle_deg(rig: RigConstants, torque_nm, *, pulses=None, input_angle_deg=None):
    """Output twist of the gear from the input position, the sensor's own twist removed.

    Parameters
    ----------
    rig : RigConstants
        Needs ``transmission_ratio``; ``pulses_per_rev`` when `pulses` is given;
        ``sensor_stiffness_nm_per_rad`` if the sensor twist is to be removed.
    torque_nm : array_like
        Torque measured by the sensor, N·m.
    pulses : array_like, optional
        Input pulses N (exactly one of `pulses`, `input_angle_deg`).
    input_angle_deg : array_like, optional
        Input shaft angle, degrees.

    Returns
    -------
    ndarray
        Output angle theta_out in degrees (a new array).

    Raises
    ------
    RigError
        ``pulses_per_rev`` is missing while `pulses` are given, or neither/both of
        `pulses` and `input_angle_deg` are given.

    Notes
    -----
    theta_in = 2·pi·N/P (rad); theta_out = theta_in/i − T/K_sensor (rad), the
    stiffness paper's output-angle equation: the torque sensor is a spring in series
    with the gear, so its twist T/K_sensor is part of what the input position
    measures and is subtracted.

    Examples
    --------
    >>> rig = RigConstants(pulses_per_rev=36000, transmission_ratio=100,
    ...                    sensor_stiffness_nm_per_rad=1000 * 180 / np.pi)
    >>> output_angle_deg(rig, [0.0, 10.0], pulses=[0, 100000])  # 1000 deg in, 10 deg out
    array([0.  , 9.99])
    """
    if (pulses is None) == (input_angle_deg is None):
        raise RigError("give exactly one of pulses and input_angle_deg")
    if pulses is not None:
        input_angle_deg = pulses_to_input_deg(rig, pulses)
    theta_out = np.deg2rad(np.asarray(input_angle_deg, dtype=float)) / rig.transmission_ratio
    if rig.sensor_stiffness_nm_per_rad is not None:
        theta_out = theta_out - np.asarray(torque_nm, dtype=float) / rig.sensor_stiffness_nm_per_rad
    return np.rad2deg(theta_out)


def pulses_to_input_deg(rig: RigConstants, pulses):
    """Input shaft angle 360·N/P in degrees from input pulses N.

    Raises
    ------
    RigError
        ``pulses_per_rev`` is not set.

    Examples
    --------
    >>> pulses_to_input_deg(RigConstants(pulses_per_rev=400), [0, 100, -800])
    array([   0.,   90., -720.])
    """
    if rig.pulses_per_rev is None:
        raise RigError("rig constant pulses_per_rev is needed to convert input pulses")
    return 360.0 * np.asarray(pulses, dtype=float) / rig.pulses_per_rev
