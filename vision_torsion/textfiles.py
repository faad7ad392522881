"""Text inputs as users have them, read with the project's errors.

One home for what every text reader of the toolkit needs:

- :func:`read_toml`: every TOML file vision-torsion reads (session.toml, scenes,
  accuracy specs, plane corrections, rig constants) goes through it, so each fails
  the same way: the caller's :class:`~vision_torsion.errors.VisionTorsionError`
  subclass, a message naming the file and what was expected, and a ``reason`` code
  (``not_found``, ``unreadable``, ``not_utf8``, ``bad_toml``, ``too_large``) for
  code to branch on. Limits are checked before parsing or after it, never by a
  crash: a file over :data:`MAX_TEXT_BYTES`, tables or arrays nested deeper than
  :data:`MAX_TOML_DEPTH`, and integers beyond TOML's 64 bits are refused by name.
  On Python < 3.11 the standard library has no ``tomllib``; the ``tomli`` package
  (the same parser, a dependency on those versions) stands in.
- :func:`decode_utf8`: UTF-8 with or without a byte-order mark; a file in another
  encoding is refused with the line and column of the first byte that is not UTF-8.
- :func:`csv_delimiter`: CSV files separated by commas, semicolons or tabs (the
  session manifest, an accuracy check's reference table), told from the header line,
  which must name known columns.
"""

from __future__ import annotations

import os
import stat
import sys
from pathlib import Path

from .errors import VisionTorsionError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

__all__ = ["read_toml", "read_text", "parse_toml", "TOMLDecodeError", "decode_utf8", "csv_delimiter",
           "CSV_DELIMITERS", "read_text_bytes", "MAX_TEXT_BYTES", "MAX_TOML_DEPTH", "nonblocking_opener"]

#: The TOML parser's error (``tomllib.TOMLDecodeError`` or ``tomli.TOMLDecodeError``).
TOMLDecodeError = tomllib.TOMLDecodeError

#: Field separators accepted: the comma, the semicolon spreadsheets write where the
#: decimal mark is a comma, and the tab of "tab-separated" exports.
CSV_DELIMITERS = (",", ";", "\t")
#: Largest text input read (bytes): a session's manifest of 100 000 rows is ~10 MB.
MAX_TEXT_BYTES = 256 * 1024 * 1024
#: Deepest nesting of tables and arrays in a TOML file; the toolkit's own files
#: nest 2 deep.
MAX_TOML_DEPTH = 32
# TOML integers are 64-bit signed (TOML 1.0, "Integer")
_TOML_INT_RANGE = (-(2**63), 2**63 - 1)


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


def nonblocking_opener(path, flags: int) -> int:
    """An ``opener`` for :func:`open` that does not wait for a named pipe's writer
    (``O_NONBLOCK``, where the system has it); a regular file reads as it would
    without it, and the caller refuses what :func:`os.fstat` says is no file."""
    return os.open(path, flags | getattr(os, "O_NONBLOCK", 0))


def read_text_bytes(path, *, what: str, error: type[VisionTorsionError] = VisionTorsionError,
                    limit: int = MAX_TEXT_BYTES, name=None) -> bytes:
    """The bytes of a text input, its size checked before it is read.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    what : str
        What the file should be, for the messages.
    error : VisionTorsionError subclass
        The error to raise.
    limit : int
        Largest size accepted (bytes).
    name : str, optional
        What the messages call the file (the path by default).

    Raises
    ------
    error
        Reason ``not_found`` (no such file, a broken or looping symbolic link),
        ``unreadable`` (a folder, no permission, an I/O error; a named pipe or a
        device, which is refused without waiting for a writer or reading an endless
        stream) or ``too_large``
        (``PATH: 3000000000 bytes, more than the 268435456 a text input may have``).
    """
    p = Path(path)
    name = p if name is None else name
    try:
        with open(p, "rb", opener=nonblocking_opener) as fh:
            st = os.fstat(fh.fileno())
            if not (stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)):
                raise error(f"{name}: not a regular file (a named pipe or a device); expected {what}",
                            reason="unreadable")
            size = st.st_size
            if size > limit:
                raise error(f"{name}: {size} bytes, more than the {limit} {what} may have",
                            reason="too_large")
            return fh.read(size + 1)  # as the size says (asking for `limit` would allocate that much)
    except FileNotFoundError:
        raise error(f"{name}: no such file; expected {what}", reason="not_found") from None
    except VisionTorsionError:
        raise
    except OSError as exc:
        raise error(f"{name}: cannot be read ({exc.strerror or exc})", reason="unreadable") from None


def parse_toml(text: str, *, source, error: type[VisionTorsionError] = VisionTorsionError) -> dict:
    """Parse TOML text; invalid TOML raises `error` naming `source` (reason ``bad_toml``).

    Besides the parser's syntax errors, refused with reason ``bad_toml``: tables or
    arrays nested deeper than :data:`MAX_TOML_DEPTH`, and integers outside TOML's
    64-bit range (the message names the key).

    >>> parse_toml('a = 1', source="inline")
    {'a': 1}
    >>> parse_toml('a = [[[1]]]', source="inline")["a"]
    [[[1]]]
    """
    try:
        doc = tomllib.loads(text)
    except TOMLDecodeError as exc:
        raise error(f"{source}: not valid TOML ({exc})", reason="bad_toml") from None
    except RecursionError:
        raise error(f"{source}: not valid TOML (tables or arrays nested deeper than "
                    f"{MAX_TOML_DEPTH} levels)", reason="bad_toml") from None
    except ValueError:  # an integer of more digits than Python converts (over 4300)
        raise error(f"{source}: not valid TOML (an integer of thousands of digits; TOML integers "
                    f"are 64-bit, {_TOML_INT_RANGE[0]} to {_TOML_INT_RANGE[1]})", reason="bad_toml") from None
    _check_toml_limits(doc, source=source, error=error)
    return doc


def _check_toml_limits(doc: dict, *, source, error) -> None:
    """Nesting depth and integer range of a parsed document, walked without recursion."""
    stack = [(doc, "", 1)]
    while stack:
        node, key, depth = stack.pop()
        if depth > MAX_TOML_DEPTH:
            raise error(f"{source}: not valid TOML for vision-torsion ({key or 'the document'} is "
                        f"nested {depth} levels deep, more than {MAX_TOML_DEPTH})", reason="bad_toml")
        items = node.items() if isinstance(node, dict) else enumerate(node)
        for k, v in items:
            name = f"{key}.{k}" if isinstance(k, str) and key else (k if isinstance(k, str) else f"{key}[{k}]")
            if isinstance(v, (dict, list)):
                stack.append((v, name, depth + 1))
            elif isinstance(v, int) and not isinstance(v, bool) and not (
                    _TOML_INT_RANGE[0] <= v <= _TOML_INT_RANGE[1]):
                raise error(f"{source}: {name} is an integer beyond TOML's 64 bits "
                            f"({_TOML_INT_RANGE[0]} to {_TOML_INT_RANGE[1]})", reason="bad_toml")


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
        mark is dropped, see :func:`decode_utf8`), ``too_large`` (over
        :data:`MAX_TEXT_BYTES`, checked before reading) or ``bad_toml`` (a syntax
        error, with the parser's line and column; nesting or an integer beyond the
        limits, see :func:`parse_toml`). The message starts with the path.

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
    """A UTF-8 text file's contents (a byte-order mark dropped), its size checked
    before it is read (:func:`read_text_bytes`).

    Raises
    ------
    error
        ``NAME: no such file; expected WHAT`` (reason ``not_found``), ``NAME: cannot
        be read (why)`` (``unreadable``), too large (``too_large``), or not UTF-8
        (``not_utf8``, :func:`decode_utf8`); NAME is `name`, the path by default.
    """
    name = path if name is None else name
    return decode_utf8(read_text_bytes(path, what=what, error=error, name=name), name=name, error=error, what=what)
