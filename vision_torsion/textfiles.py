"""Text inputs as users have them, read with the project's errors.

One home for what every text reader of the toolkit needs:

- :func:`read_toml`: every TOML file vision-torsion reads (session.toml, scenes,
  accuracy specs, plane corrections, rig constants) goes through it, so each fails
  the same way: the caller's :class:`~vision_torsion.errors.VisionTorsionError`
  subclass, a message naming the file and what was expected, and a ``reason`` code
  (``not_found``, ``unreadable``, ``not_utf8``, ``bad_toml``) for code to branch on.
  On Python < 3.11 the standard library has no ``tomllib``; the ``tomli`` package
  (the same parser, a dependency on those versions) stands in.
- :func:`decode_utf8`: UTF-8 with or without a byte-order mark; a file in another
  encoding is refused with the line and column of the first byte that is not UTF-8.
- :func:`csv_delimiter`: CSV files separated by commas, semicolons or tabs (the
  session manifest, an accuracy check's reference table), told from the header line,
  which must name known columns.
"""

from __future__ import annotations

import sys
from pathlib import Path

from .errors import VisionTorsionError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = ["read_toml", "read_text", "parse_toml", "TOMLDecodeError", "decode_utf8", "csv_delimiter",
           "CSV_DELIMITERS"]

#: The TOML parser's error (``tomllib.TOMLDecodeError`` or ``tomli.TOMLDecodeError``).
TOMLDecodeError = tomllib.TOMLDecodeError

#: Field separators accepted: the comma, the semicolon spreadsheets write where the
#: decimal mark is a comma, and the tab of "tab-separated" exports.
CSV_DELIMITERS = (",", ";", "\t")


def decode_utf8(raw: bytes, *, name, error: type[VisionTorsionError], what: str = "the file") -> str:
    """`raw` as UTF-8 text, a leading byte-order mark dropped.

    Parameters
    ----------
    raw : bytes
        The file's contents.
    name : str or path
        The file, for the message.
    error : VisionTorsionError subclass
        Raised (with the message, reason ``not_utf8``) when `raw` is not UTF-8.
    what : str
        What to tell the user to save as UTF-8.

    Raises
    ------
    error
        ``NAME: line L: not UTF-8 text (byte 0xNN at column C); save ... as UTF-8``.
    """
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        column = exc.start - (raw.rfind(b"\n", 0, exc.start) + 1) + 1
        raise error(f"{name}: line {line}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at column "
                    f"{column}); save {what} as UTF-8 (in a spreadsheet: \"CSV UTF-8\")",
                    reason="not_utf8") from None


def csv_delimiter(header_line: str, required) -> str:
    """The separator of a CSV whose first line is `header_line`: the comma, or a
    semicolon or tab when the header splits into the `required` column names by it
    and not by commas (else the comma, and the caller reports missing columns)."""
    for sep in CSV_DELIMITERS:
        if set(required) <= {c.strip() for c in header_line.split(sep)}:
            return sep
    return ","


def parse_toml(text: str, *, source, error: type[VisionTorsionError] = VisionTorsionError) -> dict:
    """Parse TOML text; invalid TOML raises `error` naming `source` (reason ``bad_toml``).

    >>> parse_toml('a = 1', source="inline")
    {'a': 1}
    """
    try:
        return tomllib.loads(text)
    except TOMLDecodeError as exc:
        raise error(f"{source}: not valid TOML ({exc})", reason="bad_toml") from None


def read_toml(path, *, what: str, error: type[VisionTorsionError] = VisionTorsionError) -> dict:
    """Read and parse a TOML file.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    what : str
        What the file should be, for the messages (``"a session description"``).
    error : VisionTorsionError subclass
        The error to raise, the one the caller documents (``SessionError``,
        ``SceneError``, ...).

    Returns
    -------
    dict
        The parsed document.

    Raises
    ------
    error
        With ``reason`` ``not_found`` (no such file), ``unreadable`` (a folder, no
        permission, an I/O error), ``not_utf8`` (TOML is UTF-8 text; a byte-order
        mark is dropped, see :func:`decode_utf8`) or ``bad_toml`` (a syntax error,
        with the parser's line and column). The message starts with the path.

    Examples
    --------
    >>> from vision_torsion.errors import SessionError
    >>> read_toml("/nonexistent/session.toml", what="a session description", error=SessionError)
    Traceback (most recent call last):
    ...
    vision_torsion.errors.SessionError: /nonexistent/session.toml: no such file; expected a session description
    """
    p = Path(path)
    return parse_toml(read_text(p, what=what, error=error), source=p, error=error)


def read_text(path, *, what: str, error: type[VisionTorsionError] = VisionTorsionError, name=None) -> str:
    """A UTF-8 text file's contents (a byte-order mark dropped).

    Raises
    ------
    error
        ``NAME: no such file; expected WHAT`` (reason ``not_found``), ``NAME: cannot
        be read (why)`` (``unreadable``), or not UTF-8 (``not_utf8``,
        :func:`decode_utf8`); NAME is `name`, the path by default.
    """
    name = path if name is None else name
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        raise error(f"{name}: no such file; expected {what}", reason="not_found") from None
    except OSError as exc:
        raise error(f"{name}: cannot be read ({exc.strerror or exc})", reason="unreadable") from None
    return decode_utf8(data, name=name, error=error, what=what)
