"""One report folder read as a campaign record: identity, figures, verdict and the
hashes of the inputs it was computed from.

A report folder is what ``vision-torsion report`` or ``analyze`` writes: a
``summary.json`` of schema ``vision-torsion/analysis-summary/N`` beside
``measurements.csv`` (a session's ``results/``) or the analysed table. Nothing in
the folder is written or changed.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from ..errors import CampaignError

__all__ = [
    "FigureRecord",
    "ReportRecord",
    "read_report",
    "SUMMARY_NAME",
    "SUPPORTED_SUMMARY_SCHEMAS",
    "MAX_SUMMARY_BYTES",
]

SUMMARY_NAME = "summary.json"
#: Versions of ``vision-torsion/analysis-summary/N`` a campaign record can be made from.
SUPPORTED_SUMMARY_SCHEMAS = (2,)
#: A summary.json larger than this is refused before it is read (the demo's is 0.17 MB).
MAX_SUMMARY_BYTES = 64 * 2**20
_SCHEMA = re.compile(r"^vision-torsion/analysis-summary/(\d+)$")
_INPUT_NAMES = ("measurements.csv",)
_SESSION_INPUTS = ("session.toml", "manifest.csv")


@dataclass(frozen=True)
class FigureRecord:
    """One figure of a report: the mean over its loops with its uncertainty.

    ``value`` is None when the report withheld the figure; ``u95`` is the expanded
    uncertainty with ``coverage_factor``; ``flagged`` says the report marked it (its
    reason in ``flag``); ``verdict`` is the report's conformity decision for it
    (:data:`vision_torsion.analysis.conformity.DECISIONS`), if it was judged.
    """

    figure: str
    unit: str
    n: int
    value: float | None
    std: float | None
    u95: float | None
    coverage_factor: float | None
    flagged: bool
    withheld: bool
    flag: str
    verdict: str | None


@dataclass(frozen=True)
class ReportRecord:
    """What the campaign database keeps of one report.

    ``identity`` names the test (model, serial, test date, session folder name): a
    report of the same identity with other content is a new version of it.
    ``content_sha256`` is the hash of summary.json and of every input's hash: the
    same report added twice has the same one. ``verdict`` is the report's overall
    conformity verdict (``pass``, ``fail``, ``not_decided``; None without a
    ``[spec]``) and ``limits`` its catalogue limit per figure, ``(kind, value)``.
    """

    source: str
    model: str
    serial: str
    operator: str
    test_date: str
    date_source: str
    test_hours: float | None
    software_version: str
    summary_schema: str
    verdict: str | None
    limits: dict
    inputs: dict
    content_sha256: str
    summary_bytes: bytes
    figures: tuple[FigureRecord, ...]

    @property
    def identity(self) -> str:
        return "\x1f".join((self.model, self.serial, self.test_date, Path(self.source).parent.name))


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _number(value) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def _text(mapping, *keys) -> str:
    if not isinstance(mapping, dict):
        return ""
    for key in keys:
        value = mapping.get(key)
        if isinstance(value, (str, int, float)) and not isinstance(value, bool) and str(value).strip():
            return str(value).strip()
    return ""


def _verdicts(summary: dict) -> tuple[str | None, dict, dict]:
    """The report's overall verdict, its decision per figure and its limit per figure
    (``(kind, value)``), from summary.json's ``conformity`` (None, {}, {}: no [spec])."""
    from ..analysis.conformity import Limit, Verdict, overall

    conformity = summary.get("conformity")
    entries = conformity.get("verdicts") if isinstance(conformity, dict) else None
    if not isinstance(entries, list):
        return None, {}, {}
    verdicts, decisions, limits = [], {}, {}
    for entry in entries:
        if not isinstance(entry, dict):
            continue
        figure, kind, limit, decision = (entry.get(k) for k in ("figure", "limit_kind", "limit", "decision"))
        if not (isinstance(figure, str) and isinstance(decision, str) and kind in ("min", "max")
                and _number(limit) is not None):
            continue
        decisions[figure] = decision
        limits[figure] = (kind, float(limit))
        verdicts.append(Verdict(Limit(figure, kind, float(limit)), _number(entry.get("value")),
                                _number(entry.get("u95")), _number(entry.get("coverage_factor")), decision,
                                str(entry.get("reason") or "")))
    return (overall(verdicts) if verdicts else None), decisions, limits


def _figures(summary: dict, where: Path, verdicts: dict) -> tuple[FigureRecord, ...]:
    table = summary.get("summary")
    if not isinstance(table, dict):
        raise CampaignError(f"{where}: no 'summary' table of figures", reason="not_a_report")
    out = []
    for name, entry in table.items():
        if not isinstance(entry, dict):
            raise CampaignError(f"{where}: figure {name!r} is not a table", reason="not_a_report")
        value = _number(entry.get("mean"))
        out.append(FigureRecord(
            figure=str(name),
            unit=str(entry.get("unit") or ""),
            n=int(_number(entry.get("n")) or 0),
            value=value,
            std=_number(entry.get("mean_std")),
            u95=_number(entry.get("mean_u95")),
            coverage_factor=_number(entry.get("coverage_factor")),
            flagged=bool(entry.get("flagged")) or bool(entry.get("flag")),
            withheld=value is None,
            flag=str(entry.get("flag") or ""),
            verdict=verdicts.get(name),
        ))
    return tuple(out)


def _load_summary(folder: Path) -> tuple[bytes, dict]:
    path = folder / SUMMARY_NAME
    if not folder.is_dir():
        raise CampaignError(f"{folder}: not a folder (a report folder holds {SUMMARY_NAME})", reason="not_a_report")
    if not path.is_file():
        raise CampaignError(f"{folder}: not a vision-torsion report (no {SUMMARY_NAME})", reason="not_a_report")
    size = path.stat().st_size
    if size > MAX_SUMMARY_BYTES:
        raise CampaignError(f"{path}: {size} bytes, more than a report's summary can be "
                            f"({MAX_SUMMARY_BYTES} bytes)", reason="not_a_report")
    data = path.read_bytes()
    try:
        summary = json.loads(data.decode("utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise CampaignError(f"{path}: not UTF-8 text (byte {exc.start})", reason="not_a_report") from None
    except json.JSONDecodeError as exc:
        raise CampaignError(f"{path}: not JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})",
                            reason="not_a_report") from None
    except RecursionError:
        raise CampaignError(f"{path}: nested too deeply to be a report's summary", reason="not_a_report") from None
    if not isinstance(summary, dict):
        raise CampaignError(f"{path}: not a report's summary (a JSON object is expected)", reason="not_a_report")
    schema = summary.get("schema")
    match = _SCHEMA.match(schema) if isinstance(schema, str) else None
    if match is None:
        raise CampaignError(f"{path}: not a vision-torsion analysis summary (schema {schema!r})",
                            reason="not_a_report")
    if int(match.group(1)) not in SUPPORTED_SUMMARY_SCHEMAS:
        known = ", ".join(map(str, SUPPORTED_SUMMARY_SCHEMAS))
        raise CampaignError(f"{path}: a report of summary schema version {match.group(1)}; this vision-torsion "
                            f"reads version {known} (re-run `vision-torsion report` or upgrade)",
                            reason="schema_version")
    return data, summary


def _inputs(folder: Path, summary: dict, summary_bytes: bytes) -> dict:
    """sha256 of summary.json and of each input found: measurements.csv beside it,
    session.toml and manifest.csv of the session folder (None where absent)."""
    inputs = {SUMMARY_NAME: hashlib.sha256(summary_bytes).hexdigest()}
    for name in _INPUT_NAMES:
        path = folder / name
        inputs[name] = _sha256(path) if path.is_file() else None
    conditions = summary.get("conditions") if isinstance(summary.get("conditions"), dict) else {}
    session = conditions.get("session folder")
    session_dir = Path(session) if isinstance(session, str) and session else folder.parent
    for name in _SESSION_INPUTS:
        path = session_dir / name
        inputs[name] = _sha256(path) if path.is_file() else None
    return inputs


def _test_date(summary: dict, folder: Path) -> tuple[str, str]:
    """(ISO date of the test, where it came from)."""
    value = _text(summary.get("identity"), "date")
    if value:
        return value, "[test] date"
    stamp = datetime.fromtimestamp((folder / SUMMARY_NAME).stat().st_mtime, tz=timezone.utc)
    return stamp.date().isoformat(), "date of summary.json (no test date in the report)"


def read_report(folder, *, test_hours: float | None = None) -> ReportRecord:
    """Read a report folder into a :class:`ReportRecord`.

    Parameters
    ----------
    folder : str or Path
        A report folder (holding ``summary.json``).
    test_hours : float, optional
        Hours of running before this test (a life test); overrides ``[test]
        test_hours`` of the report.

    Raises
    ------
    CampaignError
        ``reason="not_a_report"``: not a folder, no summary.json, not JSON, not a
        vision-torsion summary, no figure table; ``reason="schema_version"``: a
        summary schema this version does not read. The message names the file.
    """
    folder = Path(folder).resolve()
    data, summary = _load_summary(folder)
    overall, per_figure, limits = _verdicts(summary)
    figures = _figures(summary, folder / SUMMARY_NAME, per_figure)
    identity = summary.get("identity") if isinstance(summary.get("identity"), dict) else {}
    gear, test = summary.get("gear"), summary.get("test")
    if test_hours is None:
        test_hours = _number(test.get("test_hours")) if isinstance(test, dict) else None
    test_date, date_source = _test_date(summary, folder)
    inputs = _inputs(folder, summary, data)
    content = hashlib.sha256(json.dumps({"inputs": inputs, "test_hours": test_hours},
                                        sort_keys=True).encode("ascii")).hexdigest()
    software = summary.get("software")
    return ReportRecord(
        source=str(folder),
        model=_text(identity, "gear") or _text(gear, "model", "name"),
        serial=_text(identity, "serial") or _text(gear, "serial"),
        operator=_text(identity, "operator") or _text(test, "operator"),
        test_date=test_date,
        date_source=date_source,
        test_hours=test_hours,
        software_version=_text(software, "version") if isinstance(software, dict) else _text(summary, "software"),
        summary_schema=str(summary["schema"]),
        verdict=overall,
        limits=limits,
        inputs=inputs,
        content_sha256=content,
        summary_bytes=data,
        figures=figures,
    )
