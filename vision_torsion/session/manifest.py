"""``manifest.csv``: one row per image of a session, and its validation.

This module is the single place where a manifest is checked. :func:`load_manifest`
reads the whole file and checks every row, and every image file the rows name,
before anything is measured; all problems are listed in one
:class:`~vision_torsion.errors.ManifestError`, each prefixed with its **CSV line
number** (the header is line 1, the first data row line 2), which is the number a
spreadsheet or text editor shows.

The file is UTF-8 (a byte-order mark is accepted; other encodings are refused
with the line of the first byte that is not UTF-8). Fields are separated by commas,
or by semicolons or tabs as spreadsheets export them (told from the header line;
with semicolons, numbers may use a decimal comma).

Columns: ``image,orientation_deg,cycle,phase,step,mass_kg`` are required, in any
order; ``torque_nm`` and ``torque_std_nm`` are optional (a measured torque that
overrides the weights, with its 1σ uncertainty); other columns are kept and passed
through to ``measurements.csv`` unchanged.
"""

from __future__ import annotations

import csv
import io
import math
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from ..errors import ManifestError
from ..images import IMAGE_SUFFIXES
from ..measurements import MANIFEST_COLUMNS, MANIFEST_OPTIONAL_COLUMNS, PHASES, ZERO_TORQUE_PHASES
from ..textfiles import csv_delimiter, decode_utf8, read_text_bytes
from ..validate import number_problem
from .binding import BINDING_NAME, load_binding

__all__ = ["ManifestRow", "Manifest", "load_manifest", "manifest_text", "MANIFEST_NAME",
           "REQUIRED_COLUMNS", "OPTIONAL_COLUMNS", "MAX_MANIFEST_ROWS"]

MANIFEST_NAME = "manifest.csv"
REQUIRED_COLUMNS = MANIFEST_COLUMNS
OPTIONAL_COLUMNS = MANIFEST_OPTIONAL_COLUMNS


@dataclass(frozen=True)
class ManifestRow:
    """One validated manifest row.

    Attributes
    ----------
    line : int
        CSV line number of the row (header = line 1).
    image : str
        Path of the image relative to the session folder, with ``/`` separators.
    orientation_deg : float
    cycle : int
        1, 2, ...
    phase : str
        One of :data:`~vision_torsion.measurements.PHASES`.
    step : int
        Step within the phase (>= 0), increasing down the file.
    mass_kg : float or None
        Mass on each pan of the loaded pair (kg); None only when `torque_nm` is given.
    torque_nm, torque_std_nm : float or None
        A measured torque and its 1σ uncertainty (N·m) overriding the weights.
    fields : tuple of (str, str)
        Every column of the row as written, in file order (passed through).
    """

    line: int
    image: str
    orientation_deg: float
    cycle: int
    phase: str
    step: int
    mass_kg: float | None
    torque_nm: float | None
    torque_std_nm: float | None
    fields: tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class Manifest:
    """A validated manifest: the columns as written and the rows in file order.

    Attributes
    ----------
    path : pathlib.Path
    columns : tuple of str
    rows : tuple of ManifestRow
    sources : dict of str to pathlib.Path
        Images bound to a camera's files (``binding.json``, :mod:`.binding`):
        manifest image path -> the camera file that is its photograph.
    pending : tuple of int
        CSV lines whose image does not exist yet (a partly shot session, loaded
        with ``missing="pending"``).
    """

    path: Path
    columns: tuple[str, ...]
    rows: tuple[ManifestRow, ...]
    sources: dict = field(default_factory=dict)
    pending: tuple[int, ...] = ()

    @property
    def session_dir(self) -> Path:
        """The folder the image paths are relative to."""
        return self.path.parent

    def image_path(self, row: ManifestRow) -> Path:
        """Absolute path of `row`'s image (the bound camera file, if any)."""
        source = self.sources.get(row.image)
        return source if source is not None else self.session_dir / row.image


def _number(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _whole(text: str) -> int | None:
    value = _number(text)
    if value is None or not value.is_integer():
        return None
    return int(value)


class _RowChecker:
    """Parses rows, collecting "line N: problem" messages."""

    def __init__(self, session_dir: Path, *, binding=None, missing: str = "error"):
        self.session_dir = session_dir
        self.root = session_dir.resolve()
        self.problems: list[str] = []
        self.binding = binding
        self.missing = missing
        self.pending: list[int] = []
        self._real_folders: dict[str, str] = {}

    def add(self, line: int, what: str) -> None:
        self.problems.append(f"line {line}: {what}")

    def image(self, line: int, text: str) -> str | None:
        if not text:
            self.add(line, "image is empty; expected a path relative to the session folder")
            return None
        posix = PurePosixPath(text)
        if posix.is_absolute() or Path(text).is_absolute() or (len(text) > 1 and text[1] == ":"):
            self.add(line, f"image {text!r} is an absolute path; expected a path relative "
                           "to the session folder")
            return None
        norm = os.path.normpath(text).replace(os.sep, "/")
        if norm == ".." or norm.startswith("../"):
            self.add(line, f"image {text!r} leaves the session folder ('..')")
            return None
        if posix.suffix.lower() not in IMAGE_SUFFIXES:
            self.add(line, f"image {text!r} is not an image file name; expected one of "
                           f"{', '.join(IMAGE_SUFFIXES)}")
            return None
        return norm

    def _real_folder(self, folder: str) -> str:
        """``os.path.realpath`` of a folder, each folder once: a manifest names
        thousands of images in a few folders, and resolving each path in full cost
        ~0.2 ms."""
        if folder not in self._real_folders:
            self._real_folders[folder] = os.path.realpath(folder)
        return self._real_folders[folder]

    def image_file(self, line: int, rel: str) -> None:
        source = self.binding.source(rel) if self.binding is not None else None
        if source is not None:
            # the user named the camera folder (bind); a link out of it is refused
            path, root, shown = str(source), str(self.binding.camera_dir.resolve()), f"{rel!r} (bound to {source})"
            where = f"the camera folder {self.binding.camera_dir}"
        else:
            path, root = os.path.join(self.session_dir, rel), str(self.root)
            shown, where = repr(rel), "the session folder"
        # os calls, not pathlib: this runs for every row of every manifest load
        try:
            st = os.lstat(path)
        except (FileNotFoundError, NotADirectoryError):
            st = None
        except OSError as exc:
            self.add(line, f"image {shown} cannot be read ({exc.strerror or exc})")
            return
        if st is not None and stat.S_ISLNK(st.st_mode):
            real = os.path.realpath(path)
            try:
                st = os.stat(path)
            except FileNotFoundError:  # a broken link: no such file
                st = None
            except OSError as exc:  # a link to itself or in a loop: never a photograph
                self.add(line, f"image {shown} is a symbolic link that cannot be followed "
                               f"({exc.strerror or exc})")
                return
        else:
            real = os.path.join(self._real_folder(os.path.dirname(path)), os.path.basename(path))
        if real != root and not real.startswith(os.path.join(root, "")):
            self.add(line, f"image {shown} leaves {where} (through a symbolic link)")
            return
        if st is None:
            if self.missing == "pending":
                self.pending.append(line)
            else:
                self.add(line, f"image {shown}: no such file")
        elif not stat.S_ISREG(st.st_mode):
            self.add(line, f"image {shown} is not a regular file")
        else:
            try:
                with open(path, "rb") as fh:
                    fh.read(1)
            except OSError as exc:
                self.add(line, f"image {shown} cannot be read ({exc.strerror or exc})")

    def number(self, line, column, text, *, expected, blank_ok=False, nonnegative=False):
        if text == "" and blank_ok:
            return None
        value = _number(text)
        if value is None:
            self.add(line, f"{column} {text!r} is not a number; expected {expected}")
        elif nonnegative and value < 0:
            self.add(line, f"{column} {text!r} is negative; expected {expected}")
            return None
        elif (why := number_problem(value)) is not None:
            self.add(line, f"{column} {why}; expected {expected}")
            return None
        return value

    def whole(self, line, column, text, *, minimum):
        value = _whole(text)
        if value is None or value < minimum:
            self.add(line, f"{column} {text!r} is not a whole number >= {minimum}")
            return None
        return value


def _parse_row(check: _RowChecker, line: int, rec: dict[str, str], has: set[str],
               check_files: bool):
    image = check.image(line, rec["image"])
    if image is not None and check_files:
        check.image_file(line, image)
    orient = check.number(line, "orientation_deg", rec["orientation_deg"],
                          expected="an angle in degrees")
    cycle = check.whole(line, "cycle", rec["cycle"], minimum=1)
    step = check.whole(line, "step", rec["step"], minimum=0)
    phase = rec["phase"]
    if phase not in PHASES:
        check.add(line, f"phase {phase!r} is unknown; expected one of {', '.join(PHASES)}")
        phase = None
    torque = std = None
    if "torque_nm" in has:
        torque = check.number(line, "torque_nm", rec["torque_nm"], blank_ok=True,
                              expected="a measured torque in N·m (or blank)")
    if "torque_std_nm" in has:
        std = check.number(line, "torque_std_nm", rec["torque_std_nm"], blank_ok=True,
                           nonnegative=True, expected="a 1σ uncertainty >= 0 in N·m")
    if torque is not None and std is None and rec.get("torque_std_nm", "") == "":
        check.add(line, "torque_nm is given without torque_std_nm; expected its 1σ "
                        "uncertainty in N·m")
    mass = check.number(line, "mass_kg", rec["mass_kg"], nonnegative=True,
                        blank_ok=torque is not None,
                        expected="the mass on each pan in kg (>= 0)")
    if phase in ZERO_TORQUE_PHASES and mass:
        check.add(line, f"mass_kg {rec['mass_kg']!r} on a {phase} row; a {phase} "
                        "image is taken at zero load (mass_kg 0)")
    elif phase in _LOADING_PHASES and step and mass == 0 and torque is None:
        check.add(line, f"mass_kg {rec['mass_kg']!r} on step {step} of a {phase} row; a loading "
                        "step has weights on its pans (mass_kg > 0; only an unloading phase ends "
                        "at 0)")
    if None in (image, orient, cycle, step, phase) or (mass is None and torque is None):
        return None
    return dict(image=image, orientation_deg=orient, cycle=cycle, phase=phase, step=step,
                mass_kg=mass, torque_nm=torque, torque_std_nm=std)


def _check_sequence(check: _RowChecker, rows: list[ManifestRow]) -> None:
    """Duplicates, step order and reference count: checks across rows."""
    by_image: dict[str, int] = {}
    by_key: dict[tuple, int] = {}
    last_step: dict[tuple, tuple[int, int]] = {}
    reference: dict[float, int] = {}
    unloaded: dict[tuple, ManifestRow] = {}  # an unloading phase's first row at zero mass
    for row in rows:
        where = (f"orientation {row.orientation_deg:g}, cycle {row.cycle}, {row.phase}")
        key = (row.orientation_deg, row.cycle, row.phase, row.step)
        if row.image in by_image:
            check.add(row.line, f"duplicate row: image {row.image!r} is already listed on "
                                f"line {by_image[row.image]}")
        elif key in by_key:
            check.add(row.line, f"duplicate row: {where}, step {row.step} is already on "
                                f"line {by_key[key]}")
        by_image.setdefault(row.image, row.line)
        by_key.setdefault(key, row.line)
        group = key[:3]
        if group in last_step and row.step < last_step[group][0]:
            prev_step, prev_line = last_step[group]
            check.add(row.line, f"steps out of order: {where}, step {row.step} comes after "
                                f"step {prev_step} (line {prev_line}); steps must increase "
                                "down the file")
        last_step[group] = (row.step, row.line)
        if row.phase.endswith("_unloading") and row.torque_nm is None:
            zero = unloaded.get(group)
            if zero is not None and row.mass_kg:
                check.add(zero.line, f"mass_kg 0 on step {zero.step} of a {row.phase} row, yet step "
                                     f"{row.step} (line {row.line}) still has {row.mass_kg:g} kg on each "
                                     "pan; an unloading phase reaches 0 only at its last step")
                del unloaded[group]
            elif row.mass_kg == 0:
                unloaded.setdefault(group, row)
        if row.phase == "reference":
            if row.orientation_deg in reference:
                check.add(row.line, f"second reference row of orientation "
                                    f"{row.orientation_deg:g} (the first is on line "
                                    f"{reference[row.orientation_deg]}); an orientation has "
                                    "one reference image")
            reference.setdefault(row.orientation_deg, row.line)


#: Most rows a manifest may have, counted as it is read (a plan writes at most this many).
MAX_MANIFEST_ROWS = 100_000
#: Phases whose steps 1, 2, ... add weights: none of them is at zero mass.
_LOADING_PHASES = ("negative_loading", "positive_loading")
_NUMERIC_COLUMNS = ("orientation_deg", "cycle", "step", "mass_kg", "torque_nm", "torque_std_nm")


def _read_records(path: Path):
    if not path.exists():
        raise ManifestError(f"{path}: no such file (a session folder needs "
                            f"{MANIFEST_NAME})")
    raw = read_text_bytes(path, what="a manifest", error=ManifestError)
    text = decode_utf8(raw, name=path, error=ManifestError, what="the manifest")
    sep = csv_delimiter(text.split("\n", 1)[0], REQUIRED_COLUMNS)
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=sep)
    header = next(reader, None)
    if not header:
        raise ManifestError(f"{path}: empty file; expected the header line "
                            f"{','.join(REQUIRED_COLUMNS)}")
    columns = tuple(h.strip() for h in header)
    missing = [c for c in REQUIRED_COLUMNS if c not in columns]
    repeated = sorted({c for c in columns if columns.count(c) > 1})
    if missing or repeated:
        what = (f"missing column(s) {', '.join(missing)}" if missing
                else f"repeated column(s) {', '.join(repeated)}")
        raise ManifestError(f"{path}: line 1: {what}; expected the header "
                            f"{','.join(REQUIRED_COLUMNS)}[,torque_nm,torque_std_nm]")
    records = []
    while True:
        start = reader.line_num + 1
        try:
            fields = next(reader, None)
        except csv.Error as exc:  # a field over csv.field_size_limit(): an unclosed quote
            raise ManifestError(f"{path}: line {start}: cannot be read as CSV ({exc}); a field "
                                "that long is usually a quote (\") opened and never closed",
                                reason="bad_csv") from None
        if fields is None:
            break
        if any(f.strip() for f in fields):
            if len(records) == MAX_MANIFEST_ROWS:  # before the work (and memory) of checking them
                raise ManifestError(f"{path}: line {start}: more than {MAX_MANIFEST_ROWS} rows, the most "
                                    "a session may have (as many as a plan may write)", reason="too_large")
            records.append((reader.line_num, fields))
    if sep == ";":  # decimal commas go with semicolons: 0,02 is 0.02
        numeric = [i for i, c in enumerate(columns) if c in _NUMERIC_COLUMNS]
        for _, fields in records:
            for i in numeric:
                if i < len(fields) and fields[i].count(",") == 1 and "." not in fields[i]:
                    fields[i] = fields[i].replace(",", ".")
    return columns, records


def load_manifest(path, *, check_files: bool = True, missing: str = "error") -> Manifest:
    """Read and validate a ``manifest.csv`` and the image files it names.

    Parameters
    ----------
    path : str or os.PathLike
        The manifest; image paths are relative to its folder (the session folder).
    check_files : bool
        Also check that every image exists inside the session folder and can be
        opened (True for processing; False to check only the table).
    missing : {"error", "pending"}
        What an image that does not exist is: a problem (the default), or a row
        not photographed yet, listed in :attr:`Manifest.pending` (a partly shot
        session; used by ``process``).

    Images bound to a camera's files by ``binding.json`` (:mod:`.binding`) in the
    manifest's folder are read from the camera folder it names.

    Returns
    -------
    Manifest

    Raises
    ------
    ManifestError
        The file is missing, empty or lacks a required column; or rows have
        problems: wrong number of fields, empty/absolute/escaping (``..`` or a
        symbolic link leading outside) image paths, names that are not images,
        missing or unreadable files, unknown phases, non-numeric or negative masses,
        non-whole cycles or steps, a reference row with a mass, a torque_nm without
        torque_std_nm, duplicate images or duplicate (orientation, cycle, phase,
        step), steps out of order within a phase, a second reference row of an
        orientation, or no rows at all. Every problem is listed, one line each,
        with its CSV line number.
    SessionError
        binding.json is unusable, or (with `check_files`) the camera folder it
        binds rows to is not there (:meth:`~.binding.Binding.check_camera_dir`).
    """
    if missing not in ("error", "pending"):
        raise ValueError(f"missing must be 'error' or 'pending', got {missing!r}")
    path = Path(path)
    columns, records = _read_records(path)
    binding = load_binding(path.parent)  # SessionError when binding.json is unusable
    if check_files and binding is not None:
        binding.check_camera_dir(path.parent / BINDING_NAME)
    check = _RowChecker(path.parent, binding=binding, missing=missing)
    has = set(columns)
    rows: list[ManifestRow] = []
    for line, fields in records:
        if len(fields) != len(columns):
            check.add(line, f"{len(fields)} fields; expected {len(columns)} (one per "
                            "header column)")
            continue
        values = [f.strip() for f in fields]
        rec = dict(zip(columns, values))
        parsed = _parse_row(check, line, rec, has, check_files)
        if parsed is None:
            continue
        rows.append(ManifestRow(line=line, fields=tuple(zip(columns, values)), **parsed))
    if not records:
        check.problems.append("no image rows below the header")
    _check_sequence(check, rows)
    if check.problems:
        listing = "\n  ".join(check.problems)
        raise ManifestError(f"{path}: {len(check.problems)} problem(s) (line numbers are "
                            f"CSV lines, the header is line 1)\n  {listing}")
    sources = {} if binding is None else {row.image: binding.source(row.image) for row in rows
                                          if row.image in binding.images}
    return Manifest(path=path, columns=columns, rows=tuple(rows), sources=sources,
                    pending=tuple(check.pending))


def manifest_text(columns, rows) -> str:
    """CSV text of `rows` (dicts or sequences) under `columns`, ``\\n`` line endings."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([row[c] for c in columns] if isinstance(row, dict) else row)
    return buf.getvalue()
