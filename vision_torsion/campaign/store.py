"""The campaign database: every report of every tested gear, immutable, in one SQLite file.

One record per report (gear identity, test metadata, software version, every figure
with its uncertainty, coverage factor, flags and verdict, the sha256 of the inputs,
and the summary.json itself, compressed). Records are never changed or deleted
(triggers refuse it); re-adding a report whose content is already there is a no-op;
a report of the same identity (model, serial, test date, session) with other content
is stored as its next version.

Each report is added in its own ``BEGIN IMMEDIATE`` transaction: concurrent adders
wait for each other (``busy_timeout``) and lose nothing, and a process killed during
an add leaves the database as it was before that report (SQLite's write-ahead log:
an uncommitted transaction is never seen).

The schema is versioned by ``PRAGMA user_version`` and marked as a vision-torsion
campaign by ``PRAGMA application_id``; an older schema is migrated on opening for
writing, a newer one is refused by name.
"""

from __future__ import annotations

import json
import logging
import os
import sqlite3
import time
import zlib
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from ..errors import CampaignError
from .folder_record import FigureRecord, ReportRecord

__all__ = ["CampaignDB", "AddResult", "SCHEMA_VERSION", "APPLICATION_ID"]

log = logging.getLogger(__name__)

#: 'VTCA' — marks the SQLite file as a vision-torsion campaign database.
APPLICATION_ID = 0x56544341
SCHEMA_VERSION = 1
_BUSY_TIMEOUT_MS = 60_000

_SCHEMA_V1 = """
CREATE TABLE reports(
    id INTEGER PRIMARY KEY,
    content_sha256 TEXT NOT NULL UNIQUE,
    identity TEXT NOT NULL,
    version INTEGER NOT NULL,
    model TEXT NOT NULL,
    serial TEXT NOT NULL,
    operator TEXT NOT NULL,
    test_date TEXT NOT NULL,
    date_source TEXT NOT NULL,
    test_hours REAL,
    added_utc TEXT NOT NULL,
    software_version TEXT NOT NULL,
    added_by_version TEXT NOT NULL,
    summary_schema TEXT NOT NULL,
    source TEXT NOT NULL,
    verdict TEXT,
    inputs TEXT NOT NULL,
    summary_zlib BLOB NOT NULL,
    UNIQUE(identity, version)
);
CREATE TABLE figures(
    report_id INTEGER NOT NULL REFERENCES reports(id),
    figure TEXT NOT NULL,
    unit TEXT NOT NULL,
    n INTEGER NOT NULL,
    value REAL,
    std REAL,
    u95 REAL,
    coverage_factor REAL,
    flagged INTEGER NOT NULL,
    withheld INTEGER NOT NULL,
    flag TEXT NOT NULL,
    verdict TEXT,
    limit_kind TEXT,
    limit_value REAL,
    PRIMARY KEY(report_id, figure)
) WITHOUT ROWID;
CREATE INDEX figures_by_name ON figures(figure, report_id);
CREATE INDEX reports_by_serial ON reports(serial, test_date);
CREATE TRIGGER reports_immutable BEFORE UPDATE ON reports
    BEGIN SELECT RAISE(ABORT, 'campaign records are immutable'); END;
CREATE TRIGGER reports_kept BEFORE DELETE ON reports
    BEGIN SELECT RAISE(ABORT, 'campaign records are immutable'); END;
CREATE TRIGGER figures_immutable BEFORE UPDATE ON figures
    BEGIN SELECT RAISE(ABORT, 'campaign records are immutable'); END;
CREATE TRIGGER figures_kept BEFORE DELETE ON figures
    BEGIN SELECT RAISE(ABORT, 'campaign records are immutable'); END;
"""

# schema version -> the SQL that takes a database from it to the next version
_MIGRATIONS = {0: _SCHEMA_V1}

_REPORT_COLUMNS = ("id", "identity", "version", "model", "serial", "operator", "test_date", "date_source",
                   "test_hours", "added_utc", "software_version", "added_by_version", "summary_schema", "source",
                   "verdict", "content_sha256")


@dataclass(frozen=True)
class AddResult:
    """What adding one report did: ``status`` is ``"added"`` (a new record, its
    ``version`` 1 or the next of its identity) or ``"present"`` (the same content is
    already record ``report_id``: nothing written)."""

    source: str
    status: str
    report_id: int
    version: int


_SQLITE_HEADER = b"SQLite format 3\x00"
# SQLite result-code names (Python >= 3.11 gives them as ``sqlite_errorname``) -> (reason code, words)
_SQLITE_CODES = {
    "SQLITE_NOTADB": ("not_a_campaign", "not a campaign database (not an SQLite file)"),
    "SQLITE_READONLY": ("read_only", "read-only: the database cannot be written"),
    "SQLITE_BUSY": ("busy", f"busy: another process held it for more than {_BUSY_TIMEOUT_MS // 1000} s"),
    "SQLITE_CORRUPT": ("damaged", "damaged (the database disk image is malformed)"),
    "SQLITE_FULL": ("disk_full", "the disk is full"),
    "SQLITE_IOERR": ("io_error", "the disk could not be read or written"),
}


def _sqlite_reason(exc: sqlite3.Error) -> tuple[str, str]:
    """(reason code, words) of an SQLite error, from its result code where Python
    gives it (3.11+); otherwise a generic code with SQLite's own words."""
    name = getattr(exc, "sqlite_errorname", "") or ""
    for prefix, (code, words) in _SQLITE_CODES.items():
        if name.startswith(prefix):
            return code, words
    return "database_error", f"{type(exc).__name__}: {exc}"


class CampaignDB:
    """A campaign database file, opened for reading or for adding reports.

    Parameters
    ----------
    path : str or Path
        The database file. For writing it is created when missing (its folder must
        exist); for reading it must exist.
    write : bool, keyword-only
        Open for adding reports (checks that the file and its folder are writable,
        creates or migrates the schema).

    Raises
    ------
    CampaignError
        The file is missing (reading), is not an SQLite file or is another
        application's database (``reason="not_a_campaign"``), has a newer schema
        (``"schema_version"``), cannot be written (``"read_only"``); each message
        names the file.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with CampaignDB(pathlib.Path(tempfile.mkdtemp()) / "c.db", write=True) as db:
    ...     db.count()
    0
    """

    def __init__(self, path, *, write: bool = False):
        self.path = Path(path)
        self.write = write
        if write:
            self._check_writable()
        elif not self.path.is_file():
            raise CampaignError(f"{self.path}: no such campaign database", reason="not_found")
        uri = self.path.resolve().as_uri() + ("" if write else "?mode=ro")
        self._check_header()
        try:
            self._conn = sqlite3.connect(uri, uri=True, timeout=_BUSY_TIMEOUT_MS / 1000, isolation_level=None)
        except sqlite3.Error as exc:
            raise self._error(exc) from None
        try:
            self._conn.execute(f"PRAGMA busy_timeout = {_BUSY_TIMEOUT_MS}")
            self._prepare()
        except sqlite3.Error as exc:
            self._conn.close()
            raise self._error(exc) from None
        except CampaignError:
            self._conn.close()
            raise

    # -- opening ---------------------------------------------------------------
    def _check_writable(self) -> None:
        folder = self.path.parent if str(self.path.parent) else Path(".")
        if self.path.is_dir():
            raise CampaignError(f"{self.path}: a folder, not a campaign database file", reason="not_a_campaign")
        if not folder.is_dir():
            raise CampaignError(f"{self.path}: its folder {folder} does not exist", reason="not_found")
        # the write-ahead log and its index are files beside the database
        if not os.access(folder, os.W_OK | os.X_OK):
            raise CampaignError(f"{self.path}: read-only: its folder {folder} cannot be written "
                                "(the database needs a journal file beside it)", reason="read_only")
        if self.path.exists() and not os.access(self.path, os.W_OK):
            raise CampaignError(f"{self.path}: read-only: the database cannot be written", reason="read_only")

    def _check_header(self) -> None:
        """An existing non-empty file must start as every SQLite database does."""
        try:
            with open(self.path, "rb") as fh:
                head = fh.read(len(_SQLITE_HEADER))
        except FileNotFoundError:
            return
        except OSError as exc:
            raise CampaignError(f"{self.path}: cannot be read ({exc.strerror})", reason="unreadable") from None
        if head and head != _SQLITE_HEADER:
            raise CampaignError(f"{self.path}: not a campaign database (not an SQLite file)",
                                reason="not_a_campaign")

    def _error(self, exc: sqlite3.Error) -> CampaignError:
        code, words = _sqlite_reason(exc)
        return CampaignError(f"{self.path}: {words}", reason=code)

    def _prepare(self) -> None:
        conn = self._conn
        # one statement, one snapshot: another process may be creating the schema meanwhile
        # (fetchall: the statement finished, no read lock kept into the journal-mode switch)
        ((app_id, version, tables),) = conn.execute(
            "SELECT (SELECT application_id FROM pragma_application_id), (SELECT user_version FROM pragma_user_version),"
            " (SELECT count(*) FROM sqlite_master)").fetchall()
        if app_id != APPLICATION_ID and (app_id != 0 or tables):
            raise CampaignError(f"{self.path}: not a campaign database (an SQLite file of another application)",
                                reason="not_a_campaign")
        if version > SCHEMA_VERSION:
            raise CampaignError(f"{self.path}: a campaign database of schema version {version}, made by a newer "
                                f"vision-torsion; this one reads up to version {SCHEMA_VERSION}",
                                reason="schema_version")
        if self.write:
            # WAL: readers never wait for an adder, and a commit costs no fsync of its own
            # (synchronous NORMAL: a killed process loses nothing committed; a power cut
            # may lose the last commits but never leaves the file inconsistent)
            self._use_wal()
            conn.execute("PRAGMA synchronous = NORMAL")
        if version == SCHEMA_VERSION:
            return
        if not self.write:
            if app_id == 0 and not tables:
                raise CampaignError(f"{self.path}: an empty file, not a campaign database", reason="not_a_campaign")
            raise CampaignError(f"{self.path}: a campaign database of schema version {version}; open it for "
                                f"writing (campaign add) to migrate it to version {SCHEMA_VERSION}",
                                reason="schema_version")
        self._migrate(version)

    def _use_wal(self) -> None:
        """Switch the file to WAL once. The switch needs the file to itself and SQLite
        answers it "busy" at once, without waiting, while another process holds it
        (several adders creating one database together): waited for here instead."""
        deadline = time.monotonic() + _BUSY_TIMEOUT_MS / 1000
        while True:
            ((mode,),) = self._conn.execute("PRAGMA journal_mode").fetchall()
            if str(mode).lower() == "wal":
                return
            try:
                self._conn.execute("PRAGMA journal_mode = WAL").fetchall()
            except sqlite3.OperationalError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.02)

    def _migrate(self, version: int) -> None:
        conn = self._conn
        conn.execute("BEGIN IMMEDIATE")
        try:
            # another process may have migrated it while this one waited for the lock
            current = conn.execute("PRAGMA user_version").fetchone()[0]
            while current < SCHEMA_VERSION:
                for statement in _MIGRATIONS[current].split(";\n"):
                    if statement.strip():
                        conn.execute(statement)
                current += 1
                conn.execute(f"PRAGMA user_version = {current}")
            conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
            conn.execute("COMMIT")
        except BaseException:
            conn.execute("ROLLBACK")
            raise
        if version:
            log.info("%s: migrated from schema version %d to %d", self.path, version, SCHEMA_VERSION)

    def close(self) -> None:
        self._conn.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -- adding ----------------------------------------------------------------
    def add(self, record: ReportRecord) -> AddResult:
        """Add one report in one transaction (see the module docstring).

        Raises
        ------
        CampaignError
            The database cannot be written (read-only, disk full, busy for more than
            a minute); nothing of this report is then stored.
        """
        from .. import __version__

        conn = self._conn
        try:
            conn.execute("BEGIN IMMEDIATE")
            try:
                row = conn.execute("SELECT id, version FROM reports WHERE content_sha256 = ?",
                                   (record.content_sha256,)).fetchone()
                if row is not None:
                    conn.execute("ROLLBACK")
                    return AddResult(record.source, "present", row[0], row[1])
                version = conn.execute("SELECT coalesce(max(version), 0) + 1 FROM reports WHERE identity = ?",
                                       (record.identity,)).fetchone()[0]
                cursor = conn.execute(
                    "INSERT INTO reports(content_sha256, identity, version, model, serial, operator, test_date, "
                    "date_source, test_hours, added_utc, software_version, added_by_version, summary_schema, "
                    "source, verdict, inputs, summary_zlib) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                    (record.content_sha256, record.identity, version, record.model, record.serial, record.operator,
                     record.test_date, record.date_source, record.test_hours,
                     datetime.now(timezone.utc).isoformat(timespec="seconds"), record.software_version,
                     __version__, record.summary_schema, record.source, record.verdict,
                     json.dumps(record.inputs, sort_keys=True), zlib.compress(record.summary_bytes, 1)),
                )
                report_id = cursor.lastrowid
                conn.executemany(
                    "INSERT INTO figures VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)",
                    [(report_id, f.figure, f.unit, f.n, f.value, f.std, f.u95, f.coverage_factor, int(f.flagged),
                      int(f.withheld), f.flag, f.verdict, *record.limits.get(f.figure, (None, None)))
                     for f in record.figures],
                )
                conn.execute("COMMIT")
            except BaseException:
                if conn.in_transaction:
                    conn.execute("ROLLBACK")
                raise
        except sqlite3.Error as exc:
            raise self._error(exc) from None
        return AddResult(record.source, "added", report_id, version)

    # -- reading ---------------------------------------------------------------
    def _query(self, sql: str, params=()) -> list:
        """The rows of a query; an SQLite error (a damaged file, a table not as this
        schema has it) is a CampaignError naming the file, never an internal error."""
        try:
            return self._conn.execute(sql, params).fetchall()
        except sqlite3.Error as exc:
            raise self._error(exc) from None

    def count(self) -> int:
        """Number of records (every version counted)."""
        return self._query("SELECT count(*) FROM reports")[0][0]

    def reports(self, *, serial=None, model=None, since=None, latest_only: bool = False):
        """Records as a DataFrame (one row each, oldest test first), filtered by
        serial(s), model and test date (``since``, ISO date, inclusive);
        ``latest_only`` keeps each identity's newest version."""
        import pandas as pd

        where, params = [], []
        if serial:
            serials = [serial] if isinstance(serial, str) else list(serial)
            where.append(f"serial IN ({','.join('?' * len(serials))})")
            params += serials
        if model:
            where.append("model = ?")
            params.append(model)
        if since:
            where.append("test_date >= ?")
            params.append(str(since))
        if latest_only:
            where.append("version = (SELECT max(version) FROM reports r2 WHERE r2.identity = reports.identity)")
        sql = f"SELECT {', '.join(_REPORT_COLUMNS)} FROM reports"
        if where:
            sql += " WHERE " + " AND ".join(where)
        sql += " ORDER BY test_date, id"
        return pd.DataFrame(self._query(sql, params), columns=list(_REPORT_COLUMNS))

    def figures(self, report_ids=None, *, figure=None):
        """Figures as a long DataFrame (``report_id, figure, unit, n, value, std, u95,
        coverage_factor, flagged, withheld, flag, verdict, limit_kind, limit_value``)."""
        import pandas as pd

        columns = [f.name for f in FigureRecord.__dataclass_fields__.values()] + ["limit_kind", "limit_value"]
        where, params = [], []
        if report_ids is not None:
            ids = [int(i) for i in report_ids]
            if not ids:
                return pd.DataFrame(columns=["report_id", *columns])
            where.append(f"report_id IN ({','.join('?' * len(ids))})")
            params += ids
        if figure is not None:
            names = [figure] if isinstance(figure, str) else list(figure)
            where.append(f"figure IN ({','.join('?' * len(names))})")
            params += names
        sql = f"SELECT report_id, {', '.join(columns)} FROM figures"
        if where:
            sql += " WHERE " + " AND ".join(where)
        frame = pd.DataFrame(self._query(sql, params), columns=["report_id", *columns])
        frame["flagged"] = frame["flagged"].astype(bool)
        frame["withheld"] = frame["withheld"].astype(bool)
        return frame

    def summary_of(self, report_id: int) -> dict:
        """The stored summary.json of a record, as it was added."""
        rows = self._query("SELECT summary_zlib FROM reports WHERE id = ?", (int(report_id),))
        row = rows[0] if rows else None
        if row is None:
            raise CampaignError(f"{self.path}: no record {report_id}", reason="not_found")
        return json.loads(zlib.decompress(row[0]).decode("utf-8-sig"))

    def integrity(self) -> str:
        """SQLite's own check of the file: ``"ok"`` or what is wrong."""
        return "; ".join(r[0] for r in self._query("PRAGMA integrity_check"))
