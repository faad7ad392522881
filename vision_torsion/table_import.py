"""Torque–angle tables from anywhere, turned into the measurements table.

``measurements.csv`` (:mod:`.measurements`) is the table every analysis reads. A
table from another rig or a spreadsheet differs from it in ways this module
undoes, and says what it did (:attr:`ImportedTable.notes`):

- **separator and decimal mark**: comma, semicolon or tab, told from the header
  line (the separator that splits it into the most fields, the tab before the
  semicolon before the comma); with a semicolon or tab, a decimal comma in the
  numbers (``0,125``) is read as a decimal point.
- **column names**: the measurements' own names are taken as they are; otherwise a
  column map (``{"torque": "Torque [N m]", "angle": "Angle [arcmin]"}``, the
  ``--columns`` option) or, without one, a header whose name before its unit is a
  known word (torque, moment; angle, rotation, twist, theta) names the column, and
  ``angle_std``, ``u(angle)``, ``sigma angle`` (the same for torque) its uncertainty.
- **units** from the header: ``Torque [N m]``, ``Torque (mN·m)``, ``Angle [arcmin]``,
  ``angle_rad``; torque in N·m or mN·m, angles in deg, arcmin, arcsec, rad or
  mrad, converted to N·m and degrees. A torque or angle column without a unit is
  refused (a radian read as a degree is a factor 57): write the unit in the header
  or give it (``units={"angle": "arcmin"}``). An uncertainty column without a unit
  is in the unit of its value's column.
- **optional columns**: ``status`` (``ok``), ``message`` (blank), ``image`` (the
  CSV line, ``line 12``), ``orientation_deg`` (0), uncertainties from the
  instrument's 1σ (``angle_std_deg``, ``torque_std_nm`` arguments) when the table
  has none.
- **a plain torque/angle record** (no ``phase`` column): phases and cycles are
  found from the torque's reversals. A row at zero torque before any load is the
  ``reference``; the first sweep from zero to an extreme (the virgin curve) and a
  last sweep that does not complete a loop are left out (counted in the notes);
  every sweep from one extreme to the other gives its two phases (from +Tmax:
  positive unloading to zero, then negative loading; from −Tmax: negative
  unloading, then positive loading), and two sweeps make one cycle. The loop
  direction (which extreme the record reached first, and the sign of ∮τ dθ) is in
  the notes.

Rows keep their CSV line numbers (header = line 1) through the import, so a later
message about a row names the line of the user's file.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import MeasurementsError
from .measurements import MEASUREMENT_COLUMNS
from .textfiles import CSV_DELIMITERS, read_text

__all__ = ["ImportedTable", "RecordPhases", "import_table", "parse_column_map", "phases_from_torque", "ANGLE_UNITS",
           "TORQUE_UNITS", "REVERSAL_FRACTION"]

#: Angle units read from headers: name -> degrees per unit.
ANGLE_UNITS = {"deg": 1.0, "°": 1.0, "degree": 1.0, "degrees": 1.0, "arcmin": 1 / 60, "'": 1 / 60,
               "arcsec": 1 / 3600, '"': 1 / 3600, "rad": 180 / math.pi, "mrad": 0.18 / math.pi}
#: Torque units read from headers: name (spaces, dots and ·/* removed, lower case) -> N·m per unit.
TORQUE_UNITS = {"nm": 1.0, "mnm": 1e-3}
#: Words a header's name (before its unit) may be, per quantity, when no column map is given.
_WORDS = {"torque": ("torque", "moment", "tau", "t"), "angle": ("angle", "rotation", "twist", "theta", "phi")}
#: Keys of a column map: the quantity, and the measurements column it fills.
_MAP_KEYS = {"torque": "torque_nm", "angle": "angle_deg", "torque_std": "torque_std_nm",
             "angle_std": "angle_std_deg", "orientation": "orientation_deg", "cycle": "cycle", "phase": "phase",
             "step": "step", "image": "image", "status": "status", "message": "message", "mass": "mass_kg"}
#: Keys of a unit map: the quantities that carry a unit.
_UNIT_KEYS = ("torque", "angle", "torque_std", "angle_std")
_LINE = "line"
_SEP_NAMES = {",": "comma", ";": "semicolon", "\t": "tab"}
_NUMBER_WITH_COMMA = re.compile(r"^\s*[+-]?\d*,\d+(?:[eE][+-]?\d+)?\s*$")


@dataclass(frozen=True)
class ImportedTable:
    """A table turned into the measurements' columns.

    Attributes
    ----------
    frame : pandas.DataFrame
        The table with :data:`~vision_torsion.measurements.MEASUREMENT_COLUMNS`
        (torque in N·m, angles in degrees), indexed by CSV line (``line``; a sample
        at a phase boundary of a plain record is in both phases, under one line),
        checked row by row by :func:`~vision_torsion.measurements.read_measurements`.
    delimiter : str
        The separator found.
    decimal_comma : bool
        Numbers were written with a decimal comma.
    notes : tuple of str
        What the import did, in words (units converted, columns filled, phases found,
        rows left out, the loop direction).
    """

    frame: object
    delimiter: str
    decimal_comma: bool
    notes: tuple = ()


def parse_column_map(text: str, *, what: str = "--columns") -> dict:
    """``"torque=Torque [N m],angle=Angle [arcmin]"`` -> ``{"torque": "Torque [N m]", ...}``.

    With ``what="--units"`` the keys are the quantities with a unit (``torque``,
    ``angle``, ``torque_std``, ``angle_std``) and the values units.

    Raises
    ------
    MeasurementsError
        An entry without ``=``, an unknown key, or a key given twice (reason
        ``bad_option``); the message starts with `what`.

    Examples
    --------
    >>> parse_column_map("torque=Torque [N m], angle=Angle [arcmin]")
    {'torque': 'Torque [N m]', 'angle': 'Angle [arcmin]'}
    """
    keys = _UNIT_KEYS if what == "--units" else tuple(_MAP_KEYS)
    out = {}
    for part in (p for p in text.split(",") if p.strip()):
        key, sep, value = part.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise MeasurementsError(f"{what}: {part.strip()!r} is not KEY=VALUE (e.g. "
                                    f"{'angle=arcmin' if what == '--units' else 'torque=Torque [N m]'})",
                                    reason="bad_option")
        if key not in keys:
            raise MeasurementsError(f"{what}: unknown key {key!r}; expected one of {', '.join(keys)}",
                                    reason="bad_option")
        if key in out:
            raise MeasurementsError(f"{what}: {key!r} given twice", reason="bad_option")
        out[key] = value
    return out


def _delimiter(header: str) -> str:
    counts = {sep: len(header.split(sep)) for sep in CSV_DELIMITERS}
    best = max(counts.values())
    for sep in ("\t", ";", ","):  # a semicolon file may have commas in its numbers, not the reverse
        if counts[sep] == best:
            return sep
    return ","  # pragma: no cover - one of the three always has the maximum


def _split_name_unit(header: str) -> tuple[str, str | None]:
    """``"Torque [N m]"`` -> ``("torque", "N m")``; ``"angle_rad"`` -> ``("angle", "rad")``."""
    h = header.strip()
    if re.match(r"^u\s*\([^()]*\)$", h, flags=re.IGNORECASE):  # "u(angle)": an uncertainty's name, no unit
        return h.lower().replace(" ", ""), None
    m = re.match(r"^(.*?)\s*[\[(]\s*(.*?)\s*[\])]\s*$", h)
    if m:
        return m.group(1).strip().lower(), m.group(2)
    m = re.match(r"^(.*?)[_ ]+(deg|arcmin|arcsec|rad|mrad|nm|mnm)$", h, flags=re.IGNORECASE)
    if m:
        return m.group(1).strip().lower(), m.group(2)
    return h.lower(), None


def _factor(quantity: str, unit: str | None, *, column: str, name: str) -> tuple[float, str]:
    """(scale to N·m or degrees, unit as read) of a torque or angle column."""
    if unit is None:
        raise MeasurementsError(
            f"{name}: column {column!r} has no unit; write it in the header ({column} [deg], {column} [N m]) or "
            f"give it (--units {quantity}=UNIT)", reason="no_unit")
    if quantity == "torque":
        key = re.sub(r"[\s.·*⋅]", "", unit).lower()
        table = TORQUE_UNITS
    else:
        key = unit.strip().lower()
        table = ANGLE_UNITS
    if key not in table:
        allowed = "N·m, mN·m" if quantity == "torque" else "deg, arcmin, arcsec, rad, mrad"
        raise MeasurementsError(f"{name}: column {column!r}: unit {unit!r} not known for {quantity}; expected "
                                f"one of {allowed}", reason="bad_unit")
    return table[key], unit


#: How a header names the uncertainty of a quantity ("angle_std", "u(angle)", ...).
_STD_FORMS = ("{}_std", "{} std", "u({})", "u {}", "sigma {}", "σ{}", "σ {}")


def _detect(key, words, header, found, name) -> None:
    """Claim the one header whose name (before its unit) is one of `words` for `key`."""
    target = _MAP_KEYS[key]
    if target in found:
        return
    hits = [h for h in header if h not in found.values() and _split_name_unit(h)[0] in words]
    if len(hits) > 1:
        raise MeasurementsError(f"{name}: columns {', '.join(map(repr, hits))} could each be the "
                                f"{key.replace('_std', ' uncertainty')}; name one (--columns {key}=HEADER)",
                                reason="ambiguous_column")
    if hits:
        found[target] = hits[0]


def _find_columns(header: list[str], column_map: dict, *, name: str) -> dict:
    """Measurements column -> the file's header it comes from."""
    found = {}
    for key, head in column_map.items():
        if head not in header:
            raise MeasurementsError(f"{name}: --columns {key}={head!r}: no such column; the header has "
                                    f"{', '.join(map(repr, header))}", reason="missing_column")
        found[_MAP_KEYS[key]] = head
    for col in MEASUREMENT_COLUMNS + ("torque_common_std_nm",):
        if col in header and col not in found and col not in found.values():
            found[col] = col
    for quantity, words in _WORDS.items():  # the uncertainties too: "angle_std", "u(angle)", "sigma torque"
        _detect(quantity, words, header, found, name)
        _detect(f"{quantity}_std", tuple(f.format(w) for w in words for f in _STD_FORMS), header, found, name)
    missing = [q for q in ("torque", "angle") if _MAP_KEYS[q] not in found]
    if missing:
        raise MeasurementsError(
            f"{name}: no {' and no '.join(missing)} column found among {', '.join(map(repr, header))} (after "
            f"reading the header with its separator); name it: --columns "
            + ",".join(f"{q}=HEADER" for q in missing), reason="missing_column")
    return found


#: A reversal of the torque counts when it retreats this fraction of the record's
#: range from its last extreme (noise on a continuously logged torque does not).
REVERSAL_FRACTION = 0.05


def _turning_points(tau: np.ndarray) -> list[int]:
    """Indices where the torque reverses (first and last sample included)."""
    n = len(tau)
    delta = REVERSAL_FRACTION * float(np.ptp(tau)) if n else 0.0
    turns, direction, ext = [0], 0, 0
    for i in range(1, n):
        if direction == 0:
            if abs(tau[i] - tau[0]) > delta:
                direction, ext = (1 if tau[i] > tau[0] else -1), i
        elif direction * (tau[i] - tau[ext]) >= 0:
            ext = i
        elif abs(tau[ext] - tau[i]) > delta:
            turns.append(ext)
            direction, ext = -direction, i
    if turns[-1] != n - 1:
        turns.append(n - 1)
    return turns


@dataclass(frozen=True)
class RecordPhases:
    """Phases of a torque record found from its reversals (:func:`phases_from_torque`).

    Attributes
    ----------
    rows : tuple of (int, str, int)
        ``(sample index, phase, cycle)`` in acquisition order; a sample at a phase
        boundary (an extreme, or zero torque inside a sweep) is in both phases.
        The reference has cycle 0.
    left_out : int
        Samples in no loop (the first loading from zero, a last incomplete sweep).
    first : {"positive", "negative", ""}
        The extreme the first full sweep starts from ("" without one).
    """

    rows: tuple
    left_out: int
    first: str


def phases_from_torque(torque) -> RecordPhases:
    """Phase and cycle of every sample of a torque record, from its reversals.

    Parameters
    ----------
    torque : array_like
        The torque of each sample in acquisition order (N·m, or any unit).

    Returns
    -------
    RecordPhases

    Notes
    -----
    A reversal counts once the torque has retreated :data:`REVERSAL_FRACTION` of the
    record's range from its extreme. A *full* sweep runs from beyond half the
    positive maximum to beyond half the negative minimum, or back. A sweep down is
    split at zero torque into ``positive_unloading`` (τ ≥ 0) and
    ``negative_loading`` (τ < 0), a sweep up into ``negative_unloading`` and
    ``positive_loading``; two adjacent full sweeps are one cycle. Each sample is in
    one phase only, as each photograph of a planned session is: a turning point ends
    the sweep that reaches it, and the zero-torque sample ends the unloading (the
    analysis starts each phase at the last sample of the one before). A sample at
    zero torque before any load is the ``reference``.

    Examples
    --------
    >>> r = phases_from_torque([0, 1, 2, 1, 0, -1, -2, -1, 0, 1, 2, 1])
    >>> [(i, phase) for i, phase, cycle in r.rows if i in (0, 3, 4, 7, 10)]  # doctest: +NORMALIZE_WHITESPACE
    [(0, 'reference'), (3, 'positive_unloading'), (4, 'positive_unloading'), (7, 'negative_unloading'),
     (10, 'positive_loading')]
    >>> r.left_out, r.first  # sample 1 (the first loading) and 11 (a last, incomplete sweep)
    (2, 'positive')
    """
    tau = np.asarray(torque, dtype=float)
    n = len(tau)
    if n == 0 or not np.all(np.isfinite(tau)):
        return RecordPhases(rows=(), left_out=n, first="")
    top, bottom = float(tau.max()), float(tau.min())
    turns = _turning_points(tau)
    sweeps = list(zip(turns[:-1], turns[1:]))

    def full(a, b):
        return (top > 0 > bottom) and ((tau[a] > top / 2 and tau[b] < bottom / 2)
                                       or (tau[a] < bottom / 2 and tau[b] > top / 2))

    zero = 1e-9 * max(abs(top), abs(bottom))
    rows = []
    used = np.zeros(n, bool)
    if abs(tau[0]) <= zero:
        rows.append((0, "reference", 0))
        used[0] = True
    first, cycle, k = "", 0, 0
    while k + 1 < len(sweeps):
        if not (full(*sweeps[k]) and full(*sweeps[k + 1])):
            k += 1
            continue
        cycle += 1
        for a, b in sweeps[k:k + 2]:
            down = tau[a] > 0
            first = first or ("positive" if down else "negative")
            names = ("positive_unloading", "negative_loading") if down else ("negative_unloading", "positive_loading")
            at_zero = False  # the sweep's first zero-torque sample ends the unloading, a later one starts the loading
            for i in range(a, b + 1):
                if used[i]:  # each sample once: a turning point ends its sweep, as a plan's phases do
                    continue
                v = tau[i] if down else -tau[i]
                second = v < -zero or (v <= zero and at_zero)
                at_zero = at_zero or v <= zero
                rows.append((i, names[1] if second else names[0], cycle))
                used[i] = True
        k += 2
    return RecordPhases(rows=tuple(rows), left_out=int((~used).sum()), first=first)


def _given_uncertainties(out, notes, *, angle_std_deg, torque_std_nm, name) -> None:
    """The 1σ columns the table lacks, from the values given (refused when none is)."""
    for col, value, word in (("angle_std_deg", angle_std_deg, "angle_std"),
                             ("torque_std_nm", torque_std_nm, "torque_std")):
        if col in out.columns:
            continue
        if value is None:
            raise MeasurementsError(
                f"{name}: no {col} column and no 1σ given: map the column (--columns {word}=HEADER) or give "
                f"the instrument's standard uncertainty (--{word.replace('_', '-')} "
                f"{'DEG' if word.startswith('angle') else 'NM'})", reason="no_uncertainty")
        out[col] = float(value)
        notes.append(f"{col} = {value:g} for every row (given)")


def _fill_defaults(out, notes) -> None:
    """The optional columns the table lacks (orientation 0, no mass, status ok, the
    line as the image's name), said in `notes`."""
    defaults = {"orientation_deg": 0.0, "mass_kg": np.nan, "status": "ok", "message": ""}
    filled = [c for c in defaults if c not in out.columns]
    for col in filled:
        out[col] = defaults[col]
    if "image" not in out.columns:
        out["image"] = [f"line {ln}" for ln in out.index]
        filled.append("image")
    if filled:
        notes.append(f"not in the table, filled: {', '.join(filled)}")


def import_table(path, *, column_map=None, units=None, angle_std_deg=None, torque_std_nm=None, name=None):
    """Read a torque–angle table in any of the forms the module docstring lists.

    Parameters
    ----------
    path : str or os.PathLike
        The CSV (or TSV) file, UTF-8 with or without a byte-order mark.
    column_map : dict, optional
        Quantity -> header (:func:`parse_column_map`).
    units : dict, optional
        Quantity (``torque``, ``angle``, ``torque_std``, ``angle_std``) -> unit,
        for headers that do not carry one (overrides the header's).
    angle_std_deg, torque_std_nm : float, optional
        1σ of every angle (deg) and torque (N·m), for a table without those columns.
    name : str, optional
        What messages call the file (its path by default).

    Returns
    -------
    ImportedTable

    Raises
    ------
    MeasurementsError
        ``not_found``/``unreadable``/``not_utf8`` (the file), ``missing_column``
        (no torque or angle column, a mapped header that is not there: the header's
        columns are listed as read), ``ambiguous_column``, ``no_unit``,
        ``bad_unit``, ``no_uncertainty`` (no uncertainty column and no 1σ given),
        ``no_loop`` (a record whose torque never runs from one extreme to the other
        and back).
    """
    import pandas as pd

    from .measurements import read_measurements

    p = Path(path)
    name = name or str(p)
    text = read_text(p, what="a torque-angle table", error=MeasurementsError, name=name)
    lines = text.splitlines()
    if not lines or not lines[0].strip():
        raise MeasurementsError(f"{name}: empty, or no header on line 1", reason="unreadable")
    sep = _delimiter(lines[0])
    header = [h.strip() for h in lines[0].split(sep)]
    body = [line for line in lines[1:] if line.strip()]
    decimal_comma = sep != "," and any(_NUMBER_WITH_COMMA.match(cell) for line in body[:200]
                                       for cell in line.split(sep))
    rows = [[cell.strip() for cell in line.split(sep)] for line in lines[1:]]
    line_numbers = [i + 2 for i, line in enumerate(lines[1:]) if line.strip()]
    rows = [r for r, line in zip(rows, lines[1:]) if line.strip()]
    bad = [(ln, len(r)) for ln, r in zip(line_numbers, rows) if len(r) != len(header)]
    if bad:
        ln, k = bad[0]
        raise MeasurementsError(f"{name}: line {ln}: {k} field(s), the header has {len(header)} "
                                f"(separator {_SEP_NAMES[sep]}); {len(bad)} such line(s)", reason="unreadable")
    if (sep == "," and not decimal_comma and not column_map and not units
            and set(MEASUREMENT_COLUMNS) <= set(header)):  # a measurements.csv: its own reader, as it is
        return ImportedTable(frame=read_measurements(p, name=name), delimiter=sep, decimal_comma=False)
    table = pd.DataFrame(rows, columns=header, index=pd.Index(line_numbers, name=_LINE), dtype=object)
    notes = []
    if sep != "," or decimal_comma:
        notes.append(f"separator {_SEP_NAMES[sep]}" + (", decimal comma" if decimal_comma else ""))
    found = _find_columns(header, dict(column_map or {}), name=name)
    units = dict(units or {})
    out = pd.DataFrame(index=table.index)

    def numbers(head):
        col = table[head].astype(str)
        return _to_float(col.str.replace(",", ".", regex=False) if decimal_comma else col, head, name)

    for col, head in found.items():
        if col in ("torque_nm", "angle_deg", "torque_std_nm", "angle_std_deg", "torque_common_std_nm"):
            quantity = "torque" if col.startswith("torque") else "angle"
            key = {"torque_nm": "torque", "angle_deg": "angle", "torque_std_nm": "torque_std",
                   "angle_std_deg": "angle_std", "torque_common_std_nm": "torque_std"}[col]
            if head == col:
                unit = "N m" if quantity == "torque" else "deg"
            else:
                unit = units.get(key) or _split_name_unit(head)[1]
                if unit is None and key != quantity:  # an uncertainty in the value's unit
                    unit = units.get(quantity) or _split_name_unit(found.get(_MAP_KEYS[quantity], ""))[1]
            scale, unit = _factor(quantity, unit, column=head, name=name)
            out[col] = numbers(head) * scale
            if head != col:
                notes.append(f"{col} from {head!r}" + ("" if scale == 1.0 else f" ({unit} → "
                             f"{'N·m' if quantity == 'torque' else 'deg'})"))
        elif col in ("orientation_deg", "cycle", "step", "mass_kg"):
            out[col] = numbers(head)
        else:
            out[col] = table[head].astype(str)
    _given_uncertainties(out, notes, angle_std_deg=angle_std_deg, torque_std_nm=torque_std_nm, name=name)
    if "phase" not in out.columns:
        out = _phases(out, notes, name)
    else:
        notes += _direction_notes(out)
    _fill_defaults(out, notes)
    extra = [c for c in out.columns if c not in MEASUREMENT_COLUMNS]
    frame = read_measurements(out.loc[:, list(MEASUREMENT_COLUMNS) + extra], name=name)
    return ImportedTable(frame=frame, delimiter=sep, decimal_comma=decimal_comma, notes=tuple(notes))


def _to_float(col, head, name):
    import pandas as pd

    num = pd.to_numeric(col, errors="coerce").astype(float)
    bad = num.isna() & (col.str.strip() != "") & (col.str.strip().str.lower() != "nan")
    if bad.any():
        ln = bad.index[bad.to_numpy()][0]
        raise MeasurementsError(f"{name}: line {ln}: column {head!r} is not a number ({col[ln]!r}); "
                                f"{int(bad.sum())} such cell(s)", reason="bad_row")
    return num


def _phases(out, notes, name):
    """The plain record's phases, cycles and steps from its torque reversals."""
    import pandas as pd

    if "cycle" in out.columns or "step" in out.columns:
        raise MeasurementsError(f"{name}: a cycle or step column without a phase column; give all three or "
                                "none (phases are then found from the torque)", reason="missing_column")
    groups = out.groupby("orientation_deg", sort=False) if "orientation_deg" in out.columns else [(None, out)]
    parts, n_left, n_cycles = [], 0, 0
    for orient, sub in groups:
        found = phases_from_torque(sub["torque_nm"].to_numpy(float))
        where = "" if orient is None else f"orientation {orient:g}°: "
        if not any(ph != "reference" for _, ph, _ in found.rows):
            raise MeasurementsError(
                f"{name}: {where}no phase column, and the torque never runs from one extreme to the other and "
                "back, so no loop can be found from its reversals", reason="no_loop")
        frame = sub.iloc[[i for i, _, _ in found.rows]].copy()
        frame["phase"] = [ph for _, ph, _ in found.rows]
        frame["cycle"] = [float(c) for _, _, c in found.rows]
        frame["step"] = frame.groupby(["cycle", "phase"], sort=False).cumcount().astype(float)
        parts.append(frame)
        n_left += found.left_out
        n_cycles = max(n_cycles, int(frame["cycle"].max()))
        area = _signed_area(frame[frame["phase"] != "reference"])
        notes.append(f"{where}the record runs to {'+' if found.first == 'positive' else '−'}Tmax first; ∮τ dθ "
                     + ("> 0" if area > 0 else "≤ 0 (the loop runs the other way round: the angle's sign or the "
                        "columns may be swapped)"))
    notes.insert(-len(parts), f"no phase column: phases and {n_cycles} cycle(s) per orientation found from the "
                 "torque reversals" + (f"; {n_left} row(s) outside a complete loop left out (the first loading "
                                       "from zero, a last incomplete sweep)" if n_left else ""))
    return pd.concat(parts)


def _direction_notes(out) -> list[str]:
    """A note for each orientation whose labelled loops run the other way round:
    ∮τ dθ ≤ 0 over the loop phases in protocol order (cycle, phase, step)."""
    from .measurements import CYCLE_PHASES

    order = {p: i for i, p in enumerate(CYCLE_PHASES)}
    loops = out[out["phase"].astype(str).isin(order)].copy()
    if loops.empty:
        return []
    loops["_order"] = loops["phase"].map(order)
    keys = [k for k in ("orientation_deg", "cycle") if k in loops.columns]
    notes = []
    for key, sub in (loops.groupby(keys, sort=True) if keys else [((), loops)]):
        sub = sub.sort_values(["_order", "step"] if "step" in sub.columns else ["_order"], kind="stable")
        if _signed_area(sub) <= 0:
            where = ", ".join(f"{k} {v:g}" for k, v in zip(keys, key if isinstance(key, tuple) else (key,)))
            notes.append(f"{where or 'the table'}: ∮τ dθ ≤ 0 over its phases in protocol order: the loop runs the "
                         "other way round (phases labelled against the torque's path, or the columns swapped)")
    return notes


def _signed_area(sub) -> float:
    """∮τ dθ over the loops' rows in acquisition order (trapezoids), N·m·deg:
    positive for a loop run the way a dissipating gear runs it (the angle lags the
    torque)."""
    tau = sub["torque_nm"].to_numpy(float)
    theta = sub["angle_deg"].to_numpy(float)
    ok = np.isfinite(tau) & np.isfinite(theta)
    tau, theta = tau[ok], theta[ok]
    if len(tau) < 3:
        return 0.0
    return float(np.sum(0.5 * (tau[1:] + tau[:-1]) * np.diff(theta)))
