"""The measurements vocabulary: phases, column names, the torque rig, and the one reader.

Everything that names a part of a session's table lives here, once: the phases of
the protocol and the sign of their torque, the columns of ``manifest.csv`` and of
``measurements.csv``, the weight pieces per pan, the constants of the force-couple
rig that the torque model needs (:class:`TorqueRig`), and :func:`read_measurements`,
the one reader and checker of a ``measurements.csv`` table. The session
(:mod:`vision_torsion.session`), the hysteresis analysis
(:mod:`vision_torsion.analysis`) and the stiffness curve
(:mod:`vision_torsion.stiffness`) all take them from here.

Rows are numbered one way everywhere: by their **CSV line number**, the header
being line 1 and the first data row line 2 (the number a text editor or a
spreadsheet shows). :func:`read_measurements` returns its table indexed by that
number, so a message about a row, at any later stage, names the same line.

This module sits at the bottom of the layers (it imports only :mod:`.errors`),
beside :mod:`.settings`.
"""

from __future__ import annotations

import io
import math
import os
from dataclasses import MISSING, asdict, dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import MeasurementsError, RigError
from .textfiles import read_text_bytes
from .validate import check_number, number_problem

if TYPE_CHECKING:  # pandas is imported where a table is read (see _read_csv)
    import pandas as pd

__all__ = [
    "couple_torque_nm",
    "PHASES",
    "CYCLE_PHASES",
    "ZERO_TORQUE_PHASES",
    "PHASE_SIGN",
    "MANIFEST_COLUMNS",
    "MANIFEST_OPTIONAL_COLUMNS",
    "RESULT_COLUMNS",
    "TARGET_RESULT_COLUMNS",
    "MEASUREMENT_COLUMNS",
    "MAX_TABLE_MAGNITUDE",
    "NUMERIC_COLUMNS",
    "MEASUREMENTS_NAME",
    "RESULTS_DIRNAME",
    "output_folder",
    "TorqueRig",
    "pieces_per_pan",
    "read_measurements",
    "csv_line",
]

#: The phases of a session, in protocol order. Per orientation: a ``reference``
#: image at zero load, then each cycle's four phases (positive unloading +Tmax → 0,
#: negative loading 0 → −Tmax, negative unloading −Tmax → 0, positive loading
#: 0 → +Tmax), then a ``closing`` image at zero load after the last cycle's
#: unloading back to zero (the same load state as the end of cycle 1's positive
#: unloading, so drift and creep show as the difference of the two).
PHASES = ("reference", "positive_unloading", "negative_loading", "negative_unloading",
          "positive_loading", "closing")
#: The four phases of one loading cycle (one hysteresis loop), in order.
CYCLE_PHASES = PHASES[1:5]
#: Phases photographed with no weights on the pans (``mass_kg`` must be 0).
ZERO_TORQUE_PHASES = ("reference", "closing")
#: Sign of the torque in each phase.
PHASE_SIGN = {"reference": 0, "positive_unloading": 1, "negative_loading": -1,
              "negative_unloading": -1, "positive_loading": 1, "closing": 0}

#: Required columns of ``manifest.csv``, in the order ``plan`` writes them.
MANIFEST_COLUMNS = ("image", "orientation_deg", "cycle", "phase", "step", "mass_kg")
#: Optional manifest columns: a measured torque (N·m) and its 1σ overriding the weights.
MANIFEST_OPTIONAL_COLUMNS = ("torque_nm", "torque_std_nm")
#: Columns ``process`` adds after the manifest's own (replacing its torque columns).
RESULT_COLUMNS = ("torque_nm", "torque_std_nm", "torque_common_std_nm", "torque_source",
                  "angle_deg", "angle_std_deg", "status", "message")
#: Columns ``process`` adds after :data:`RESULT_COLUMNS` for a session of an N-marker
#: target (``[target]`` in session.toml): the markers the angle rests on, the motion of
#: the shaft axis since the orientation's reference image with the target's
#: eccentricity removed (px, image x right, y down) and its 1σ, and ``bump`` (1 where
#: the axis jumped with no rotation: a bumped camera or a loose fixture, else 0).
TARGET_RESULT_COLUMNS = ("markers_used", "centre_shift_x_px", "centre_shift_y_px", "centre_shift_x_std_px",
                         "centre_shift_y_std_px", "bump")
#: Columns every ``measurements.csv`` has and the analysis needs.
MEASUREMENT_COLUMNS = ("image", "orientation_deg", "cycle", "phase", "step", "mass_kg",
                       "torque_nm", "torque_std_nm", "angle_deg", "angle_std_deg",
                       "status", "message")
#: Numeric columns (read as float64; a blank cell is NaN).
NUMERIC_COLUMNS = ("orientation_deg", "cycle", "step", "mass_kg", "torque_nm",
                   "torque_std_nm", "torque_common_std_nm", "angle_deg", "angle_std_deg") + TARGET_RESULT_COLUMNS
#: Numeric columns that may not be negative (masses, standard uncertainties, counts).
_NON_NEGATIVE = ("mass_kg", "torque_std_nm", "torque_common_std_nm", "angle_std_deg", "markers_used",
                 "centre_shift_x_std_px", "centre_shift_y_std_px", "bump")
#: Largest magnitude of any number in the table: no torque (N·m), mass (kg), angle
#: or orientation (degrees), cycle or step of a gear test comes near it; a value
#: beyond it is a typing or unit slip, refused with its row before any analysis
#: (one such outlier made the analysis' normal matrix singular).
MAX_TABLE_MAGNITUDE = 1e6
#: Text columns (read as str; a blank cell is "").
_TEXT_COLUMNS = ("image", "phase", "status", "message", "torque_source")
#: File name of the table ``process`` writes.
MEASUREMENTS_NAME = "measurements.csv"
#: The folder a command writes into, inside the folder it reads, when not given -o.
RESULTS_DIRNAME = "results"


def output_folder(folder, out_dir=None) -> Path:
    """`out_dir`, or the default output folder ``folder/results`` when it is None."""
    return Path(out_dir) if out_dir is not None else Path(folder) / RESULTS_DIRNAME
_TABLE_RANGE = dict(low=-MAX_TABLE_MAGNITUDE, high=MAX_TABLE_MAGNITUDE)
#: Name of the index of a table :func:`read_measurements` returns (CSV line numbers).
_LINE = "line"
#: At most this many problems are listed in one error (then "and N more").
_MAX_LISTED = 20


def pieces_per_pan(mass_kg, step_mass_kg):
    """Number of weight pieces making up a pan load of `mass_kg`.

    A load that is not a whole number of step masses counts as the next whole number
    (the conservative choice for the mass uncertainty); any load above zero is at
    least one piece; zero, negative or non-finite loads are none.

    Parameters
    ----------
    mass_kg : float or array_like
        Mass on one pan (kg).
    step_mass_kg : float
        Mass of one weight piece (kg), > 0.

    Returns
    -------
    int or numpy.ndarray of int
        An int for a scalar `mass_kg`, else an array of its shape.

    Examples
    --------
    >>> pieces_per_pan(0.06, 0.02), pieces_per_pan(0.0, 0.02), pieces_per_pan(0.05, 0.02)
    (3, 0, 3)
    >>> pieces_per_pan([0.0, 0.02, 0.06, 0.05, float("nan")], 0.02).tolist()
    [0, 1, 3, 3, 0]
    """
    m = np.asarray(mass_kg, dtype=float)
    loaded = np.isfinite(m) & (m > 0)
    ratio = np.where(loaded, m, 0.0) / step_mass_kg
    n = np.where(loaded, np.maximum(1.0, np.ceil(ratio - 1e-6)), 0.0).astype(int)
    return int(n) if n.ndim == 0 else n


def couple_torque_nm(mass_kg, *, gravity_m_per_s2: float, arm_radius_m: float):
    """The torque of the rig's force couple, τ = 2·m·g·r (N·m): mass `mass_kg` (kg)
    on each pan of the loaded pair, local g (m/s²), arm radius r (m) where the wires
    pull. The one place this formula is written (paper's Eq. for the couple).

    Examples
    --------
    >>> round(couple_torque_nm(0.1, gravity_m_per_s2=9.81, arm_radius_m=0.05), 6)
    0.0981
    """
    return 2.0 * mass_kg * gravity_m_per_s2 * arm_radius_m


@dataclass(frozen=True, kw_only=True)
class TorqueRig:
    """The constants of the force-couple rig that the torque model needs (SI units).

    The one home of the rig's constants: session.toml's ``[rig]`` table (with
    ``[protocol] step_mass_kg``) is read into it
    (:attr:`vision_torsion.session.SessionConfig.rig`), and it goes on to the analysis
    (``analyze_session(..., rig=...)``); checked once, here.

    Attributes
    ----------
    step_mass_kg : float
        Mass of one weight piece (kg), > 0.
    mass_std_kg : float
        Standard uncertainty (1σ) of one piece's mass (kg), >= 0.
    gravity_m_per_s2 : float
        Local g (m/s²), > 0; 9.81 by default.
    arm_radius_m : float
        Radius r at which the wires pull (m), > 0.
    friction_torque_std_nm : float
        1σ of the pulley friction torque per image (N·m), >= 0.
    arm_radius_std_m : float
        1σ of r (m), >= 0.
    gravity_std_m_per_s2 : float
        1σ of g (m/s²), >= 0.
    mass_tolerance_kg : float or None
        The ± bound of one piece's mass as a session.toml gave it (kg), >= 0, kept
        to write the file back as it was; `mass_std_kg` is then
        ``mass_tolerance_kg / sqrt(3)`` (uniform within the bound, GUM 4.3.7). None
        when the 1σ was given directly. Not part of :meth:`to_dict` (the torque
        model uses `mass_std_kg`).

    Raises
    ------
    RigError
        A value that is not a finite number, a non-positive step mass, r or g, or a
        negative uncertainty (the message names the constant); a `mass_std_kg`
        that is not ``mass_tolerance_kg / sqrt(3)``.

    Examples
    --------
    >>> rig = TorqueRig(step_mass_kg=0.02, mass_std_kg=1e-4, arm_radius_m=0.05)
    >>> rig.gravity_m_per_s2, rig.friction_torque_std_nm
    (9.81, 0.0)
    """

    step_mass_kg: float
    mass_std_kg: float
    gravity_m_per_s2: float = 9.81
    arm_radius_m: float
    friction_torque_std_nm: float = 0.0
    arm_radius_std_m: float = 0.0
    gravity_std_m_per_s2: float = 0.0
    mass_tolerance_kg: float | None = None

    #: Constants that must be > 0 (the others are uncertainties, >= 0).
    _POSITIVE = ("step_mass_kg", "gravity_m_per_s2", "arm_radius_m")

    def __post_init__(self):
        for f in fields(self):
            if f.name == "mass_tolerance_kg" and self.mass_tolerance_kg is None:
                continue
            v = check_number(getattr(self, f.name), name=f"rig: {f.name}", error=RigError, low=0,
                             low_open=f.name in self._POSITIVE)
            object.__setattr__(self, f.name, v)
        tol = self.mass_tolerance_kg
        if tol is not None and not math.isclose(self.mass_std_kg, tol / math.sqrt(3.0), rel_tol=1e-9, abs_tol=0.0):
            raise RigError(f"rig: mass_std_kg {self.mass_std_kg:g} is not mass_tolerance_kg / sqrt(3) = "
                           f"{tol / math.sqrt(3.0):g} (a ± bound is taken as uniform); give one of the two")

    @classmethod
    def from_tolerance(cls, *, mass_tolerance_kg: float, **constants) -> "TorqueRig":
        """The rig with the ± bound `mass_tolerance_kg` (kg) of one piece's mass:
        ``mass_std_kg = mass_tolerance_kg / sqrt(3)`` (uniform within the bound, GUM
        4.3.7); `constants` are the other fields.

        Examples
        --------
        >>> rig = TorqueRig.from_tolerance(mass_tolerance_kg=1e-4, step_mass_kg=0.02, arm_radius_m=0.05)
        >>> round(rig.mass_std_kg * 1e6, 2)
        57.74
        """
        tol = check_number(mass_tolerance_kg, name="rig: mass_tolerance_kg", error=RigError, low=0)
        return cls(mass_std_kg=tol / math.sqrt(3.0), mass_tolerance_kg=tol, **constants)

    @classmethod
    def required(cls) -> tuple[str, ...]:
        """Names of the constants without a default."""
        return tuple(f.name for f in fields(cls) if f.default is MISSING)

    @classmethod
    def from_mapping(cls, rig) -> "TorqueRig":
        """From a mapping of the constants (unknown or missing keys are an error).

        Raises
        ------
        RigError
            Not a mapping, a missing or unknown key, or a bad value.
        """
        if not hasattr(rig, "keys"):
            raise RigError(f"rig must be a mapping of rig constants, got {type(rig).__name__}")
        names = [f.name for f in fields(cls)]
        required = list(cls.required())
        missing = [k for k in required if k not in rig]
        unknown = sorted(set(rig) - set(names))
        if missing or unknown:
            optional = [k for k in names if k not in required]
            raise RigError(f"rig: missing key(s) {missing}, unknown key(s) {unknown}; expected {required} "
                           f"and optionally {optional}")
        return cls(**{k: rig[k] for k in rig})

    @property
    def step_torque_nm(self) -> float:
        """The torque of one weight piece on each pan of the pair, 2·m·g·r (N·m)."""
        return couple_torque_nm(self.step_mass_kg, gravity_m_per_s2=self.gravity_m_per_s2,
                                arm_radius_m=self.arm_radius_m)

    def to_dict(self) -> dict:
        """The constants of the torque model as a plain dict of floats (JSON-safe;
        :meth:`from_mapping` reads it back)."""
        out = asdict(self)
        del out["mass_tolerance_kg"]
        return out


def csv_line(position: int) -> int:
    """CSV line number of the data row at 0-based `position` (header = line 1).

    >>> csv_line(0)
    2
    """
    return int(position) + 2


def _read_csv(path: Path, name: str) -> pd.DataFrame:
    import pandas as pd  # here, not at the top: `process` uses this module without pandas

    if not path.exists():
        raise MeasurementsError(f"{name}: no such file", reason="not_found")
    raw = read_text_bytes(path, what="a measurements table", error=MeasurementsError)  # size checked first
    try:
        # blank cells are missing values; text such as "NA" is not silently one
        return pd.read_csv(io.BytesIO(raw), keep_default_na=False, na_values=[""])
    except (UnicodeDecodeError, ValueError, pd.errors.ParserError) as exc:
        raise MeasurementsError(f"{name}: cannot be read as CSV ({exc})", reason="unreadable") from None


def _repeated_rows(table, needed) -> list:
    """Row problems of measured images (``status == "ok"`` when the column is there) that no analysis can
    take: a zero ``angle_std_deg`` when the caller needs it (the reference image defines the zero angle
    and may have none), and a row repeating an earlier one (the same image, or the same orientation,
    cycle, phase and step) when the caller needs those columns."""
    ok = table["status"] == "ok" if "status" in table.columns else np.ones(len(table), bool)
    problems = []
    if "angle_std_deg" in needed:
        measured = ok & (table["phase"] != "reference") if "phase" in table.columns else ok
        zero = measured & (table["angle_std_deg"] == 0)
        problems += [(line, "angle_std_deg is 0 for a measured image: every measured angle has a positive "
                      "1σ (re-measure the image, or give its uncertainty)") for line in table.index[zero]]
    keys = ("orientation_deg", "cycle", "phase", "step")
    checks = ((["image"], "the same image"), (list(keys), "the same orientation, cycle, phase and step"))
    seen = set()
    for cols, what in checks:
        if not all(c in table.columns and c in needed for c in cols):
            continue
        sub = table.loc[np.asarray(ok, bool), cols]
        sub = sub[sub["image"] != ""] if cols == ["image"] else sub
        dup = sub.duplicated(keep="first")
        first = {tuple(r): line for line, r in zip(sub.index[~dup], sub[~dup].itertuples(index=False))}
        for line, r in zip(sub.index[dup], sub[dup].itertuples(index=False)):
            if line not in seen:  # one message per repeated row
                seen.add(line)
                problems.append((line, f"repeats line {first[tuple(r)]} ({what}): each image is measured once; "
                                 "delete the repeated row"))
    return problems


def read_measurements(source, *, columns=MEASUREMENT_COLUMNS, name: str | None = None) -> pd.DataFrame:
    """Read and check a ``measurements.csv`` table: the one reader of that table.

    Parameters
    ----------
    source : str, os.PathLike or pandas.DataFrame
        The file, or a table as read from one: the frame's row at position ``i``
        is CSV line ``i + 2`` (header = line 1), whatever its index; except a table
        this function returned (its index is named ``"line"``), or rows taken from
        one, which keep their line numbers.
    columns : sequence of str
        The columns the caller needs (all of :data:`MEASUREMENT_COLUMNS` by default);
        a missing one is an error. Other columns are kept.
    name : str, optional
        What messages call the table: the file's name by default, else
        ``"measurements table"``.

    Returns
    -------
    pandas.DataFrame
        The table, **indexed by CSV line number** (header = line 1), every column
        kept in order. Of the columns present, :data:`NUMERIC_COLUMNS` are float64
        (a blank cell is NaN) and ``image, phase, status, message, torque_source``
        are str (stripped; a blank cell is "").

    Raises
    ------
    MeasurementsError
        The file is missing or not CSV; `source` is neither a path nor a DataFrame;
        a needed column is missing; or rows have problems: text that is not a number
        in a numeric column, a number that is infinite or beyond
        :data:`MAX_TABLE_MAGNITUDE` (checked here, at read time, so no analysis
        overflows), a negative mass or uncertainty, an unknown phase; and, when
        `columns` holds the columns concerned, a measured image (``status`` ok, not
        the reference) with ``angle_std_deg`` 0, or a row repeating an earlier one
        (the same image, or the same orientation, cycle, phase and step among
        measured rows). Every
        row problem is listed (the first 20, then a count), each with its CSV line
        number and column.

    Notes
    -----
    The contract on the caller's data (as photutils' input helper states its own):
    the caller's frame is **never modified**; the result is a new frame object; a
    column is copied only when it must change (converted to float64 or to
    stripped text), and the others share their data with the caller's frame. So
    do not write into the result's unconverted columns in place if the caller's
    frame must stay as it is; reassigning a column is always safe.

    Examples
    --------
    >>> import pandas as pd
    >>> t = pd.DataFrame({"phase": ["reference", "positive_loading"], "angle_deg": ["0", "x"]})
    >>> try:
    ...     read_measurements(t, columns=("phase", "angle_deg"))
    ... except MeasurementsError as exc:
    ...     print(exc)
    measurements table: 1 problem(s) (line numbers are CSV lines, the header is line 1)
      line 3: column angle_deg is not a number ('x')
    """
    import pandas as pd

    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        name = name or path.name
        frame = _read_csv(path, name)
    elif isinstance(source, pd.DataFrame):
        name = name or "measurements table"
        frame = source
    else:
        raise MeasurementsError(
            f"measurements must be a pandas DataFrame or a CSV file, got {type(source).__name__}", reason="bad_type"
        )
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise MeasurementsError(f"{name}: missing column(s): {', '.join(missing)}", reason="missing_column")
    out = frame.copy(deep=False)  # a new frame object; the columns are shared until replaced
    if frame.index.name != _LINE:  # else: already numbered by this function (perhaps a subset of rows)
        out.index = pd.RangeIndex(2, len(frame) + 2, name=_LINE)
    problems: list[tuple[int, str]] = []
    for col in NUMERIC_COLUMNS:
        if col not in out.columns:
            continue
        raw = out[col]
        if raw.dtype != np.float64:
            num = pd.to_numeric(raw, errors="coerce").astype(np.float64)
            text = raw.astype(str).str.strip()
            bad = num.isna() & raw.notna() & (text != "") & (text.str.lower() != "nan")
            problems += [(line, f"column {col} is not a number ({raw[line]!r})") for line in raw.index[bad]]
            out[col] = num
        with np.errstate(invalid="ignore"):  # NaN is a blank cell, not a huge one
            huge = np.abs(out[col].to_numpy()) > MAX_TABLE_MAGNITUDE  # inf included
        problems += [(line, f"column {col} {number_problem(float(out[col][line]), **_TABLE_RANGE)}")
                     for line in out.index[huge]]
        if col in _NON_NEGATIVE:
            neg = out[col] < 0
            problems += [(line, f"{col} is negative ({out[col][line]:g})") for line in out.index[neg]]
    for col in _TEXT_COLUMNS:
        if col in out.columns:
            out[col] = out[col].astype(object).where(out[col].notna(), "").astype(str).str.strip()
    if "phase" in out.columns:
        unknown = ~out["phase"].isin(PHASES)
        problems += [
            (line, f"unknown phase {out['phase'][line]!r}, expected one of {', '.join(PHASES)}")
            for line in out.index[unknown]
        ]
    problems += _repeated_rows(out, columns)
    if problems:
        problems.sort()
        listed = [f"line {line}: {what}" for line, what in problems[:_MAX_LISTED]]
        if len(problems) > _MAX_LISTED:
            listed.append(f"and {len(problems) - _MAX_LISTED} more")
        raise MeasurementsError(
            f"{name}: {len(problems)} problem(s) (line numbers are CSV lines, the header "
            "is line 1)\n  " + "\n  ".join(listed),
            reason="bad_row",
        )
    return out
