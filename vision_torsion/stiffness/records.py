"""Torque-angle records from either rig, validated in one place.

Two inputs give the same :class:`TorqueAngleRecord`:

* an **encoder/torque-sensor CSV** (the stiffness paper's rig): columns ``time_s``
  and ``torque_nm``, and either ``input_pulses`` or ``input_angle_deg``. The output
  twist is computed with :func:`~vision_torsion.stiffness.rig.output_angle_deg`
  (sensor twist removed), and the drive position theta_in/i is kept to tell the
  direction of motion;
* a **camera-rig** ``measurements.csv`` (columns ``image, orientation_deg, cycle,
  phase, step, mass_kg, torque_nm, torque_std_nm, angle_deg, angle_std_deg, status,
  message``): only rows with ``status == "ok"`` are used; the angle is measured
  directly, so no rig conversion applies and there is no time axis (the record is a
  series of load steps, labelled by ``phase``).

Messages name the file, the column and the row by its CSV line number (the header
is line 1), the one row-numbering rule of :mod:`vision_torsion.measurements`.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import RecordError, RigError
from ..measurements import MEASUREMENT_COLUMNS, PHASES, csv_line, read_measurements
from ..textfiles import read_text_bytes
from ..validate import MAX_MAGNITUDE, number_problem
from .rig import RigConstants, output_angle_deg, pulses_to_input_deg

__all__ = [
    "TorqueAngleRecord",
    "read_record",
    "record_from_encoder",
    "record_from_measurements",
    "MEASUREMENT_COLUMNS",
    "PHASES",
    "MIN_RECORD_POINTS",
]

# MEASUREMENT_COLUMNS and PHASES: vision_torsion.measurements' vocabulary, re-exported.
#: Fewest samples an encoder record may have: the zero-phase filter and the
#: branch split need a few hundredths of a loading cycle at least.
MIN_RECORD_POINTS = 30


def _frozen(values, dtype=float) -> np.ndarray:
    """A read-only copy, so a record never shares memory with the caller."""
    a = np.array(values, dtype=dtype, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class TorqueAngleRecord:
    """A torque-angle series of one gear, whichever rig measured it.

    Attributes
    ----------
    angle_deg : ndarray
        Output twist, degrees (positive counter-clockwise; unwrapped).
    torque_nm : ndarray
        Torque, N·m, same length.
    time_s : ndarray or None
        Sample times, s, strictly increasing (encoder rig); None for load steps.
    drive_deg : ndarray or None
        Drive position theta_in/i, degrees, whose direction of change tells loading
        from unloading (encoder rig); None when `phase` is given.
    phase : ndarray of str or None
        Phase label per sample (camera rig), one of :data:`PHASES`.
    group : ndarray of int or None
        Cycle/orientation group per sample (camera rig), so runs of one phase in
        different cycles stay apart.
    source : {"encoder", "camera"}
    name : str
        Where the record came from (file name), for messages.
    """

    angle_deg: np.ndarray
    torque_nm: np.ndarray
    time_s: np.ndarray | None = None
    drive_deg: np.ndarray | None = None
    phase: np.ndarray | None = None
    group: np.ndarray | None = None
    source: str = "encoder"
    name: str = "record"
    _len: int = field(init=False, repr=False, default=0)

    def __post_init__(self):
        for attr, dtype in (("angle_deg", float), ("torque_nm", float), ("time_s", float),
                            ("drive_deg", float), ("phase", object), ("group", int)):
            value = getattr(self, attr)
            if value is not None:
                object.__setattr__(self, attr, _frozen(value, dtype))
        n = len(self.angle_deg)
        for attr in ("torque_nm", "time_s", "drive_deg", "phase", "group"):
            value = getattr(self, attr)
            if value is not None and len(value) != n:
                raise RecordError(f"{self.name}: {attr} has {len(value)} values, angle_deg has {n}")
        object.__setattr__(self, "_len", n)

    def __len__(self) -> int:
        return self._len

    def replace(self, **changes) -> "TorqueAngleRecord":
        """A copy with some fields replaced (e.g. filtered signals)."""
        kwargs = {k: getattr(self, k) for k in
                  ("angle_deg", "torque_nm", "time_s", "drive_deg", "phase", "group", "source", "name")}
        kwargs.update(changes)
        return TorqueAngleRecord(**kwargs)


def _require_columns(frame: pd.DataFrame, columns, name: str, what: str) -> None:
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise RecordError(
            f"{name}: {what} needs column(s) {', '.join(map(repr, missing))}; "
            f"found {', '.join(map(repr, frame.columns))}"
        )


def _numeric(frame: pd.DataFrame, column: str, name: str, lines=None) -> np.ndarray:
    """Column as float; a blank or non-numeric cell is an error naming its CSV line
    (`lines`, else the row's position + 2: header = line 1) and the column."""
    values = pd.to_numeric(frame[column], errors="coerce").to_numpy(dtype=float)
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        row = bad[0]
        line = csv_line(row) if lines is None else int(lines[row])
        value = frame[column].iloc[row]
        shown = ("(blank)" if pd.isna(value) else repr(float(value)) if isinstance(value, (float, np.floating))
                 else repr(value))
        raise RecordError(
            f"{name}: column {column!r} has a missing, non-numeric or infinite value {shown} on line {line}"
        )
    huge = np.flatnonzero(np.abs(values) > MAX_MAGNITUDE)
    if huge.size:
        row = huge[0]
        line = csv_line(row) if lines is None else int(lines[row])
        raise RecordError(f"{name}: line {line}: column {column!r} "
                          f"{number_problem(float(values[row]))}", reason="bad_value")
    return values


def _check_time(time_s: np.ndarray, name: str) -> None:
    steps = np.diff(time_s)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        row = bad[0] + 1  # 0-based position of the sample that does not come after the one before
        raise RecordError(
            f"{name}: column 'time_s' must be strictly increasing; line {csv_line(row)} "
            f"(t = {time_s[row]:g} s) does not come after line {csv_line(row - 1)} "
            f"(t = {time_s[row - 1]:g} s)"
        )


def record_from_encoder(frame: pd.DataFrame, *, rig: RigConstants, name: str = "record") -> TorqueAngleRecord:
    """Record of an encoder/torque-sensor rig from its table.

    Parameters
    ----------
    frame : pandas.DataFrame
        Columns ``time_s`` (s), ``torque_nm`` (N·m) and one of ``input_pulses``
        (counts) or ``input_angle_deg`` (degrees of the input shaft).
    rig : RigConstants
        Transmission ratio, pulses per revolution and sensor stiffness.
    name : str
        Name used in messages (the file name).

    Returns
    -------
    TorqueAngleRecord
        ``angle_deg`` = theta_out (sensor twist removed), ``drive_deg`` = theta_in/i.

    Raises
    ------
    RecordError
        A column is missing or holds a non-numeric, infinite or absurdly large
        (beyond :data:`~vision_torsion.validate.MAX_MAGNITUDE`) value, fewer than
        :data:`MIN_RECORD_POINTS` rows, or ``time_s`` is not strictly increasing
        (a repeated time included). Each names the CSV line.
    RigError
        ``pulses_per_rev`` is missing for a record with ``input_pulses``.
    """
    _require_columns(frame, ("time_s", "torque_nm"), name, "an encoder record")
    kinds = [c for c in ("input_pulses", "input_angle_deg") if c in frame.columns]
    if len(kinds) != 1:
        raise RecordError(
            f"{name}: an encoder record needs exactly one of the columns 'input_pulses' "
            f"and 'input_angle_deg'; found {', '.join(map(repr, frame.columns))}"
        )
    if len(frame) < MIN_RECORD_POINTS:
        raise RecordError(
            f"{name}: too few points: {len(frame)} rows, at least {MIN_RECORD_POINTS} needed"
        )
    time_s = _numeric(frame, "time_s", name)
    _check_time(time_s, name)
    torque = _numeric(frame, "torque_nm", name)
    input_deg = _numeric(frame, kinds[0], name)
    if kinds[0] == "input_pulses":
        input_deg = pulses_to_input_deg(rig, input_deg)
    angle = output_angle_deg(rig, torque, input_angle_deg=input_deg)
    drive_deg = input_deg / rig.transmission_ratio
    return TorqueAngleRecord(angle_deg=angle, torque_nm=torque, time_s=time_s,
                             drive_deg=drive_deg, source="encoder", name=name)


def record_from_measurements(frame: pd.DataFrame, *, name: str = "measurements.csv") -> TorqueAngleRecord:
    """Record of the camera rig from a ``measurements.csv`` table.

    Parameters
    ----------
    frame : pandas.DataFrame
        The measurements table (columns :data:`MEASUREMENT_COLUMNS`; ``image``,
        ``mass_kg`` and the ``*_std`` columns are not used here).
    name : str
        Name used in messages.

    Returns
    -------
    TorqueAngleRecord
        Only ``status == "ok"`` rows, in file order, with ``phase`` and ``group``
        (one group per ``(orientation_deg, cycle)``).

    Raises
    ------
    RecordError
        A needed column is missing, a row has a bad value or an unknown phase
        (:class:`~vision_torsion.errors.MeasurementsError` from
        :func:`vision_torsion.measurements.read_measurements`), a usable row has
        no torque or angle, or no row is ``ok``. Rows are named by CSV line.
    """
    needed = ("orientation_deg", "cycle", "phase", "torque_nm", "angle_deg", "status")
    table = read_measurements(frame, columns=needed, name=name)
    ok = table[table["status"] == "ok"]
    if ok.empty:
        raise RecordError(f"{name}: no row has status 'ok' (column 'status')")
    keys = ok[["orientation_deg", "cycle"]].astype(str).agg("/".join, axis=1)
    group = pd.factorize(keys)[0]
    return TorqueAngleRecord(
        angle_deg=_numeric(ok, "angle_deg", name, ok.index), torque_nm=_numeric(ok, "torque_nm", name, ok.index),
        phase=ok["phase"].to_numpy(dtype=object), group=group, source="camera", name=name,
    )


def read_record(path, *, rig: RigConstants | None = None) -> TorqueAngleRecord:
    """Read a torque-angle record from a CSV file of either rig.

    A file with ``phase`` and ``status`` columns is a camera-rig measurements table;
    any other is an encoder/torque-sensor record.

    Parameters
    ----------
    path : str or Path
        The CSV file.
    rig : RigConstants, optional
        Needed for an encoder record (transmission ratio, ...); ignored for a camera
        record, whose angles are measured directly.

    Returns
    -------
    TorqueAngleRecord

    Raises
    ------
    RecordError
        The file is missing, not CSV, or fails validation (see
        :func:`record_from_encoder`, :func:`record_from_measurements`).
    RigError
        An encoder record is read without rig constants.
    """
    p = Path(path)
    if not p.exists():
        raise RecordError(f"record file {p} does not exist")
    raw = read_text_bytes(p, what="a torque-angle record", error=RecordError)
    try:
        # blank cells are missing; "nan" or "NA" typed in a cell is text, shown as written
        frame = pd.read_csv(io.BytesIO(raw), keep_default_na=False, na_values=[""])
    except (ValueError, pd.errors.ParserError) as exc:
        raise RecordError(f"record file {p} cannot be read as CSV: {exc}") from None
    if {"phase", "status"} <= set(frame.columns):
        return record_from_measurements(frame, name=p.name)
    if rig is None:
        raise RigError(
            f"{p.name} is an encoder record; its rig constants (transmission_ratio, "
            "pulses_per_rev, sensor_stiffness_nm_per_rad) are needed: pass --rig FILE"
        )
    return record_from_encoder(frame, rig=rig, name=p.name)
