"""Text inputs as users have them: UTF-8 with or without a byte-order mark, and CSV
files separated by commas, semicolons or tabs.

One home for what every text reader of the toolkit needs (the session manifest,
an accuracy check's reference table): a file in another encoding is refused with
the line and column of the first byte that is not UTF-8, and a CSV's separator is
told from its header line, which must name known columns.
"""

from __future__ import annotations

__all__ = ["decode_utf8", "csv_delimiter", "CSV_DELIMITERS"]

#: Field separators accepted: the comma, the semicolon spreadsheets write where the
#: decimal mark is a comma, and the tab of "tab-separated" exports.
CSV_DELIMITERS = (",", ";", "\t")


def decode_utf8(raw: bytes, *, name, error: type[Exception], what: str = "the file") -> str:
    """`raw` as UTF-8 text, a leading byte-order mark dropped.

    Parameters
    ----------
    raw : bytes
        The file's contents.
    name : str or path
        The file, for the message.
    error : exception class
        Raised (with the message) when `raw` is not UTF-8.
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
                    f"{column}); save {what} as UTF-8 (in a spreadsheet: \"CSV UTF-8\")") from None


def csv_delimiter(header_line: str, required) -> str:
    """The separator of a CSV whose first line is `header_line`: the comma, or a
    semicolon or tab when the header splits into the `required` column names by it
    and not by commas (else the comma, and the caller reports missing columns)."""
    for sep in CSV_DELIMITERS:
        if set(required) <= {c.strip() for c in header_line.split(sep)}:
            return sep
    return ","
