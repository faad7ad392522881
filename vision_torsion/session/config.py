"""The ``session.toml`` schema: rig constants, marker settings, protocol, angle sign.

All validation of a session.toml lives here (:func:`config_from_dict`); each message
names the key (``rig.arm_radius_m``) and says what was expected, and every problem of
the file is listed in one :class:`~vision_torsion.errors.SessionError`.

Mass tolerance
--------------
``rig.mass_tolerance_kg`` is the **± bound** on the mass of one weight piece (a
tolerance class or "within ±0.1 g" as in the paper). Without more knowledge the
error is taken as uniformly distributed within the bound, so its standard
uncertainty is ``mass_tolerance_kg / sqrt(3)`` (GUM 4.3.7). Give ``rig.mass_std_kg``
instead when a calibration certificate states a 1σ value; giving both is an error.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import tomli_w

from ..errors import SessionError, TargetError, VisionTorsionError
from ..fileio import atomic_write_text
from ..measurements import TorqueRig
from ..resources import CATALOGUES, named_file
from ..settings import MeasureSettings
from ..targets import Target, load_target, target_from_dict
from ..textfiles import read_toml
from ..validate import number_problem

__all__ = [
    "ProtocolConfig",
    "GearConfig",
    "TestConfig",
    "SpecConfig",
    "SessionConfig",
    "load_config",
    "load_catalogue",
    "write_config",
    "config_from_dict",
    "config_to_dict",
    "DEFAULT_ORIENTATIONS_DEG",
    "CONFIG_NAME",
]

#: File name of the session description inside a session folder.
CONFIG_NAME = "session.toml"
#: The six flexspline orientations of the paper's protocol (degrees).
DEFAULT_ORIENTATIONS_DEG = (0.0, 60.0, 120.0, 180.0, 240.0, 300.0)
_FORMAT_VERSION = 1


@dataclass(frozen=True)
class ProtocolConfig:
    """The planned protocol (what :func:`~vision_torsion.session.plan.plan_session` wrote).

    Attributes
    ----------
    orientations_deg : tuple of float
        Flexspline orientations relative to the circular spline (degrees).
    max_torque_nm : float
        Largest torque magnitude of a cycle (N·m), a whole number of step masses.
    cycles : int
        Cycles of the four phases per orientation.

    The mass of one weight piece, written in ``[protocol]`` as ``step_mass_kg``, is
    a rig constant in memory: :attr:`SessionConfig.rig` ``.step_mass_kg``.
    """

    orientations_deg: tuple[float, ...]
    max_torque_nm: float
    cycles: int = 1


@dataclass(frozen=True)
class GearConfig:
    """The ``[gear]`` table: what is tested, from its catalogue (all optional).

    Attributes
    ----------
    name, serial : str or None
        Free text: the gear (type, size) and its serial number.
    ratio : float or None
        Transmission ratio i (input turns per output turn): stiffnesses are also given
        on the output side, ``K_out = i²·K_in`` (with its caveat in the report).
    rated_torque_nm : float or None
        Rated torque T_R (N·m): lost motion at ±3 % and ±4 % of it.
    t1_nm, t2_nm : float or None
        Catalogue break torques T1 < T2 (N·m): K1, K2, K3 fitted with them fixed.
    """

    name: str | None = None
    serial: str | None = None
    ratio: float | None = None
    rated_torque_nm: float | None = None
    t1_nm: float | None = None
    t2_nm: float | None = None


@dataclass(frozen=True)
class TestConfig:
    """The ``[test]`` table: who, when, how the figures are taken (all optional).

    Attributes
    ----------
    operator, notes : str or None
        Free text shown in the report.
    date : str or None
        The test date as written (``2026-11-27``; a TOML date is kept in ISO form),
        shown in the report and used in the exported report's file name.
    temperature_c : float or None
        Ambient temperature (°C).
    lost_motion_fractions : tuple of float or None
        Fractions of T_R for lost motion (default 0.03 and 0.04).
    secant_interval_nm : tuple of float or None
        Secant stiffness interval (N·m), default 50–100 % of the maximum torque.
    fit_breaks : bool
        Without catalogue T1/T2, fit the break torques (default true).
    """

    operator: str | None = None
    temperature_c: float | None = None
    notes: str | None = None
    date: str | None = None
    lost_motion_fractions: tuple | None = None
    secant_interval_nm: tuple | None = None
    fit_breaks: bool = True


@dataclass(frozen=True)
class SpecConfig:
    """The ``[spec]`` table: catalogue limits the gear is judged against (all optional).

    Stiffness minima are in N·m/rad at the catalogue's break torques (``[gear]``
    ``t1_nm``/``t2_nm``); the angle maxima are in arcmin, as catalogues give them
    (lost motion at the ``[test]`` fractions of ``[gear] rated_torque_nm``;
    hysteresis loss, the loop width at zero torque). The decision rule is in
    :mod:`vision_torsion.analysis.conformity`.

    Attributes
    ----------
    k1_min_nm_per_rad, k2_min_nm_per_rad, k3_min_nm_per_rad : float or None
    lost_motion_max_arcmin, hysteresis_loss_max_arcmin : float or None
    """

    k1_min_nm_per_rad: float | None = None
    k2_min_nm_per_rad: float | None = None
    k3_min_nm_per_rad: float | None = None
    lost_motion_max_arcmin: float | None = None
    hysteresis_loss_max_arcmin: float | None = None

    def __bool__(self) -> bool:
        return any(v is not None for v in vars(self).values())


@dataclass(frozen=True)
class SessionConfig:
    """Everything ``session.toml`` says.

    Attributes
    ----------
    rig : TorqueRig
        The rig constants: the ``[rig]`` table, with ``[protocol] step_mass_kg`` as
        its step mass (:class:`~vision_torsion.measurements.TorqueRig`, the one home
        of the rig's constants and of the step torque 2·m·g·r).
    markers : MeasureSettings
        How markers are found; ``correction`` (if any) is stored as written, relative
        to the session folder.
    protocol : ProtocolConfig
    angle_sign : int
        +1 or -1: the factor applied to measured angles (CCW positive as displayed)
        so that positive torque gives a positive angle.
    target : Target or None
        The N-marker target on the disk (``[target]``: a layout table, see
        :mod:`vision_torsion.targets`, or ``name = "ring16"`` for a ready one);
        None for the two-marker target of ``[markers]``.
    """

    rig: TorqueRig
    protocol: ProtocolConfig
    markers: MeasureSettings = field(default_factory=MeasureSettings)
    angle_sign: int = 1
    gear: GearConfig = field(default_factory=GearConfig)
    test: TestConfig = field(default_factory=TestConfig)
    spec: SpecConfig = field(default_factory=SpecConfig)
    target: Target | None = None


# -- validation ---------------------------------------------------------------------


class _Problems:
    """Collects every problem of a file so they are reported together."""

    def __init__(self):
        self.items: list[str] = []

    def add(self, key: str, what: str) -> None:
        self.items.append(f"{key}: {what}")

    def raise_if_any(self, source: str) -> None:
        if self.items:
            lines = "\n  ".join(self.items)
            raise SessionError(f"{source}: {len(self.items)} problem(s)\n  {lines}")


_UNITS = (("_m_per_s2", "m/s²"), ("_nm", "N·m"), ("_kg", "kg"), ("_m", "m"), ("_deg", "degrees"), ("_c", "°C"))


def _number(table, key, problems, prefix, *, required, default=None, positive=False, nonnegative=False):
    name = f"{prefix}.{key}"
    if key not in table:
        if required:
            problems.add(name, "missing; expected a number")
        return default
    unit = next((u for suffix, u in _UNITS if key.endswith(suffix)), "")
    why = number_problem(table[key], low=0 if positive or nonnegative else None, low_open=positive, unit=unit)
    if why is not None:
        problems.add(name, why)
        return default
    return float(table[key])


def _table(data, key, problems, *, required):
    value = data.get(key)
    if value is None:
        if required:
            problems.add(key, "missing table")
        return {}
    if not isinstance(value, dict):
        problems.add(key, f"expected a table, got {type(value).__name__}")
        return {}
    return value


def _unknown(table, known, prefix, problems):
    for key in sorted(set(table) - set(known)):
        problems.add(f"{prefix}.{key}" if prefix else key, "unknown key")


_RIG_KEYS = (
    "arm_radius_m",
    "gravity_m_per_s2",
    "mass_tolerance_kg",
    "mass_std_kg",
    "friction_torque_std_nm",
    "arm_radius_std_m",
    "gravity_std_m_per_s2",
)
_PROTOCOL_KEYS = ("orientations_deg", "max_torque_nm", "step_mass_kg", "cycles")


def _rig_from(table, step_mass_kg, problems) -> TorqueRig | None:
    _unknown(table, _RIG_KEYS, "rig", problems)
    kw = dict(
        arm_radius_m=_number(table, "arm_radius_m", problems, "rig", required=True, positive=True),
        gravity_m_per_s2=_number(
            table, "gravity_m_per_s2", problems, "rig", required=False, default=9.81, positive=True
        ),
    )
    for key in ("friction_torque_std_nm", "arm_radius_std_m", "gravity_std_m_per_s2"):
        kw[key] = _number(table, key, problems, "rig", required=False, default=0.0, nonnegative=True)
    tol = _number(table, "mass_tolerance_kg", problems, "rig", required=False, nonnegative=True)
    std = _number(table, "mass_std_kg", problems, "rig", required=False, nonnegative=True)
    if "mass_tolerance_kg" in table and "mass_std_kg" in table:
        problems.add("rig.mass_std_kg", "give either mass_tolerance_kg (± bound) or mass_std_kg (1σ), not both")
    elif "mass_tolerance_kg" not in table and "mass_std_kg" not in table:
        problems.add(
            "rig.mass_tolerance_kg",
            "missing; expected the ± tolerance of one weight piece in kg (or rig.mass_std_kg, a 1σ value)",
        )
    if None in kw.values() or step_mass_kg is None or (tol is None and std is None) or problems.items:
        return None
    if tol is not None:
        return TorqueRig.from_tolerance(mass_tolerance_kg=tol, step_mass_kg=step_mass_kg, **kw)
    return TorqueRig(step_mass_kg=step_mass_kg, mass_std_kg=std, **kw)


def _protocol_from(table, problems) -> tuple[ProtocolConfig | None, float | None]:
    """The ``[protocol]`` table, and its ``step_mass_kg`` (a rig constant in memory)."""
    _unknown(table, _PROTOCOL_KEYS, "protocol", problems)
    max_torque = _number(table, "max_torque_nm", problems, "protocol", required=True, positive=True)
    step = _number(table, "step_mass_kg", problems, "protocol", required=True, positive=True)
    cycles = table.get("cycles", 1)
    why = number_problem(cycles, low=1, whole=True)
    if why is not None:
        problems.add("protocol.cycles", why)
        cycles = None
    else:
        cycles = int(cycles)
    orient = table.get("orientations_deg")
    if orient is None:
        problems.add("protocol.orientations_deg", "missing; expected a list of angles in degrees")
    elif (
        not isinstance(orient, list)
        or not orient
        or any(number_problem(v) is not None for v in orient)
    ):
        problems.add("protocol.orientations_deg", f"expected a non-empty list of numbers (degrees), got {orient!r}")
        orient = None
    elif len(set(orient)) != len(orient):
        problems.add("protocol.orientations_deg", f"repeated orientation in {orient!r}")
        orient = None
    if None in (max_torque, cycles, orient):
        return None, step
    return ProtocolConfig(orientations_deg=tuple(float(v) for v in orient), max_torque_nm=max_torque,
                          cycles=cycles), step


_GEAR_KEYS = ("name", "serial", "ratio", "rated_torque_nm", "t1_nm", "t2_nm")
_TEST_KEYS = ("operator", "date", "temperature_c", "notes", "lost_motion_fractions", "secant_interval_nm",
              "fit_breaks")
_SPEC_KEYS = ("k1_min_nm_per_rad", "k2_min_nm_per_rad", "k3_min_nm_per_rad", "lost_motion_max_arcmin",
              "hysteresis_loss_max_arcmin")


def _text(table, key, problems, prefix):
    if key not in table:
        return None
    v = table[key]
    if not isinstance(v, str):
        problems.add(f"{prefix}.{key}", f"expected text, got {v!r}")
        return None
    return v


def _numbers(table, key, problems, prefix, *, length=None, check=None, what=""):
    if key not in table:
        return None
    v = table[key]
    if (
        not isinstance(v, list)
        or not v
        or (length is not None and len(v) != length)
        or any(number_problem(x) is not None for x in v)
        or (check is not None and not check([float(x) for x in v]))
    ):
        problems.add(f"{prefix}.{key}", f"expected {what}, got {v!r}")
        return None
    return tuple(float(x) for x in v)


def _gear_from(table, problems) -> GearConfig:
    _unknown(table, _GEAR_KEYS, "gear", problems)
    kw = {k: _text(table, k, problems, "gear") for k in ("name", "serial")}
    for k in ("ratio", "rated_torque_nm", "t1_nm", "t2_nm"):
        kw[k] = _number(table, k, problems, "gear", required=False, positive=True)
    if ("t1_nm" in table) != ("t2_nm" in table):
        problems.add(
            "gear.t2_nm" if "t1_nm" in table else "gear.t1_nm",
            "give both catalogue break torques t1_nm and t2_nm, or neither",
        )
    elif kw["t1_nm"] is not None and kw["t2_nm"] is not None and not kw["t1_nm"] < kw["t2_nm"]:
        problems.add("gear.t2_nm", f"expected t1_nm < t2_nm, got {kw['t1_nm']!r} and {kw['t2_nm']!r}")
    return GearConfig(**kw)


def _test_from(table, problems) -> TestConfig:
    _unknown(table, _TEST_KEYS, "test", problems)
    kw = {k: _text(table, k, problems, "test") for k in ("operator", "notes")}
    date = table.get("date")
    if date is not None and not isinstance(date, str) and hasattr(date, "isoformat"):
        kw["date"] = date.isoformat()  # a TOML date (2026-11-27 without quotes)
    else:
        kw["date"] = _text(table, "date", problems, "test")
    kw["temperature_c"] = _number(table, "temperature_c", problems, "test", required=False)
    kw["lost_motion_fractions"] = _numbers(
        table,
        "lost_motion_fractions",
        problems,
        "test",
        check=lambda v: all(0 < x < 1 for x in v),
        what="a list of fractions in (0, 1), e.g. [0.03, 0.04]",
    )
    kw["secant_interval_nm"] = _numbers(
        table,
        "secant_interval_nm",
        problems,
        "test",
        length=2,
        check=lambda v: 0 <= v[0] < v[1],
        what="[lower, upper] in N·m, 0 <= lower < upper",
    )
    fb = table.get("fit_breaks", True)
    if not isinstance(fb, bool):
        problems.add("test.fit_breaks", f"expected true or false, got {fb!r}")
        fb = True
    kw["fit_breaks"] = fb
    return TestConfig(**kw)


#: What a catalogue limit refers to, from the [gear] table: K1-K3 are taken at the
#: catalogue's break torques, lost motion at fractions of the rated torque.
_SPEC_NEEDS = {
    "k1_min_nm_per_rad": ("t1_nm", "t2_nm"),
    "k2_min_nm_per_rad": ("t1_nm", "t2_nm"),
    "k3_min_nm_per_rad": ("t1_nm", "t2_nm"),
    "lost_motion_max_arcmin": ("rated_torque_nm",),
    "hysteresis_loss_max_arcmin": (),
}


def _spec_from(table, gear: GearConfig, problems) -> SpecConfig:
    _unknown(table, _SPEC_KEYS, "spec", problems)
    kw = {k: _number(table, k, problems, "spec", required=False, positive=True) for k in _SPEC_KEYS}
    for key, needs in _SPEC_NEEDS.items():
        missing = [f"gear.{g}" for g in needs if getattr(gear, g) is None]
        if key in table and missing:
            problems.add(f"spec.{key}", f"needs {' and '.join(missing)}: the catalogue value refers to it")
    return SpecConfig(**kw)


def _markers_from(table, problems) -> MeasureSettings | None:
    try:
        return MeasureSettings.from_dict(table)
    except (VisionTorsionError, TypeError, ValueError) as exc:
        problems.add("markers", str(exc))
        return None


def _target_from(table, problems) -> Target | None:
    if not table:
        return None
    try:
        if set(table) == {"name"}:  # a ready target by name
            return load_target(str(table["name"]))
        return target_from_dict(table)
    except TargetError as exc:
        problems.add("target", str(exc))
        return None


def config_from_dict(data: dict, *, source: str = CONFIG_NAME) -> SessionConfig:
    """Validate a parsed session.toml and build the :class:`SessionConfig`.

    Parameters
    ----------
    data : dict
        The parsed TOML document.
    source : str
        What to call the file in messages.

    Raises
    ------
    SessionError
        Listing every problem, each naming its key (``rig.arm_radius_m``) and what
        was expected.
    """
    problems = _Problems()
    _unknown(data, ("format_version", "angle_sign", "rig", "markers", "protocol", "gear", "test", "spec", "target"),
             "",
             problems)
    version = data.get("format_version", _FORMAT_VERSION)
    if version != _FORMAT_VERSION:
        problems.add("format_version", f"expected {_FORMAT_VERSION}, got {version!r}")
    sign = data.get("angle_sign", 1)
    if isinstance(sign, bool) or sign not in (1, -1):
        problems.add("angle_sign", f"expected 1 or -1, got {sign!r}")
    protocol, step_mass_kg = _protocol_from(_table(data, "protocol", problems, required=True), problems)
    rig = _rig_from(_table(data, "rig", problems, required=True), step_mass_kg, problems)
    markers = _markers_from(_table(data, "markers", problems, required=False), problems)
    gear = _gear_from(_table(data, "gear", problems, required=False), problems)
    test = _test_from(_table(data, "test", problems, required=False), problems)
    spec = _spec_from(_table(data, "spec", problems, required=False), gear, problems)
    target = _target_from(_table(data, "target", problems, required=False), problems)
    problems.raise_if_any(source)
    return SessionConfig(rig=rig, protocol=protocol, markers=markers, angle_sign=int(sign), gear=gear, test=test,
                         spec=spec, target=target)


def load_config(path) -> SessionConfig:
    """Read and validate a ``session.toml``.

    Raises
    ------
    SessionError
        The file is missing, is not valid TOML, or has invalid keys (all listed).
    """
    p = Path(path)
    data = read_toml(p, what=f"the session description (a session folder needs {CONFIG_NAME})", error=SessionError)
    return config_from_dict(data, source=str(p))


def load_catalogue(path) -> tuple[GearConfig, SpecConfig]:
    """Read a gear type's catalogue file: its ``[gear]`` and ``[spec]`` tables, with
    the keys and checks of session.toml (the same file serves every serial number of
    the type; ``plan --catalogue`` copies it into session.toml, ``analyze
    --catalogue`` uses it directly). `path` is a file, or the name of a ready
    catalogue shipped with the package (``paper_demo``: the demo's gear type).

    Raises
    ------
    SessionError
        The file is missing or not TOML, has another table, or invalid keys (all
        listed, named ``gear.t1_nm``, ``spec.k1_min_nm_per_rad``, ...).
    """
    p = named_file(path, CATALOGUES, error=SessionError, what="gear catalogue")
    data = read_toml(p, what="a catalogue file ([gear] and [spec] tables)", error=SessionError)
    problems = _Problems()
    _unknown(data, ("gear", "spec"), "", problems)
    gear = _gear_from(_table(data, "gear", problems, required=False), problems)
    spec = _spec_from(_table(data, "spec", problems, required=False), gear, problems)
    problems.raise_if_any(str(p))
    return gear, spec


def config_to_dict(config: SessionConfig) -> dict:
    """The TOML document for `config` (inverse of :func:`config_from_dict`)."""
    rig = config.rig  # step_mass_kg is written in [protocol]
    rig_d = {"arm_radius_m": rig.arm_radius_m, "gravity_m_per_s2": rig.gravity_m_per_s2}
    if rig.mass_tolerance_kg is not None:
        rig_d["mass_tolerance_kg"] = rig.mass_tolerance_kg
    else:
        rig_d["mass_std_kg"] = rig.mass_std_kg
    for key in ("friction_torque_std_nm", "arm_radius_std_m", "gravity_std_m_per_s2"):
        rig_d[key] = getattr(rig, key)
    markers = {k: v for k, v in config.markers.to_dict().items() if v is not None}
    p = config.protocol
    out = {
        "format_version": _FORMAT_VERSION,
        "angle_sign": config.angle_sign,
        "rig": rig_d,
        "markers": markers,
        "protocol": {
            "orientations_deg": list(p.orientations_deg),
            "max_torque_nm": p.max_torque_nm,
            "step_mass_kg": rig.step_mass_kg,
            "cycles": p.cycles,
        },
    }
    gear = {k: getattr(config.gear, k) for k in _GEAR_KEYS if getattr(config.gear, k) is not None}
    if gear:
        out["gear"] = gear
    test = {}
    for k in _TEST_KEYS:
        v = getattr(config.test, k)
        if k == "fit_breaks":
            if v is False:
                test[k] = False
        elif v is not None:
            test[k] = list(v) if isinstance(v, tuple) else v
    if test:
        out["test"] = test
    spec = {k: getattr(config.spec, k) for k in _SPEC_KEYS if getattr(config.spec, k) is not None}
    if spec:
        out["spec"] = spec
    if config.target is not None:
        out["target"] = {"name": config.target.name, **{k: v for k, v in config.target.spec if v is not None}}
    return out


def write_config(path, config: SessionConfig, *, header: str = "") -> Path:
    """Write `config` as TOML atomically; `header` lines are prepended as comments."""
    comment = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines())
    return atomic_write_text(path, comment + tomli_w.dumps(config_to_dict(config)))
