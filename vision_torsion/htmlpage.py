"""The display layer's building blocks: a whole self-contained page, the report
style, values rounded to their uncertainty, tables and embedded figures.

Every HTML page the package writes is built from these: the session and campaign
reports (:data:`PAGE_CSS`), the live page of ``watch`` and the capture sheet of
``plan`` (each with its own style). Inline CSS, images as base64 data URIs, no
scripts, no network; text is escaped here. The pages are written by several layers
(``plan`` and ``watch`` in the session layer, ``report`` above it), so this home is
in the foundation. :data:`PAGE_CSS` prints on A4 (``@page``/``@media print``):
figures and table rows are never split, long tables repeat their header row.
"""

from __future__ import annotations

import base64
import html
import math

import pandas as pd

__all__ = ["PAGE_CSS", "fmt_value", "image_tag", "table_html", "page_html", "unit_words"]

# the unit codes of summary.json's figures, as a reader writes them
_UNIT_WORDS = {"nm_per_rad": "N·m/rad", "nm": "N·m", "j": "J", "deg": "deg", "per_nm": "1/(N·m)", "1": ""}

PAGE_CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:0;color:#1d2430;background:#f6f7f9}
main{max-width:1180px;margin:0 auto;padding:24px 28px 60px;background:#fff}
h1{font-size:26px;margin:0 0 4px}
h2{font-size:19px;margin:34px 0 10px;border-bottom:2px solid #d8dde6;padding-bottom:4px}
h3{font-size:15px;margin:18px 0 6px}p,li{line-height:1.45;font-size:14px}.muted{color:#5b6575;font-size:13px}
table{border-collapse:collapse;font-size:12.5px;margin:8px 0 14px}
th,td{border:1px solid #d8dde6;padding:4px 7px;text-align:right}
th{background:#eef1f6;text-align:center}td.l,th.l{text-align:left}tr:nth-child(even) td{background:#fafbfc}
.grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(360px,1fr));gap:12px}
figure{margin:6px 0}figure img{max-width:100%;border:1px solid #e3e6eb}figcaption{font-size:12.5px;color:#5b6575}
.ok{color:#1a7f37;font-weight:600}.bad{color:#b42318;font-weight:600}
.note{background:#fff8e6;border-left:4px solid #f0b429;padding:8px 12px;font-size:13px}
.scroll{max-height:420px;overflow:auto;border:1px solid #e3e6eb}
.who{border-collapse:collapse;font-size:15px;margin:6px 0 4px;width:auto!important}
.who th,.who td{border:0;padding:2px 14px 2px 0;text-align:left;background:none!important}
.who th{color:#5b6575;font-weight:600}
.pass{color:#1a7f37;font-weight:700}.fail{color:#b42318;font-weight:700}.undecided{color:#9a6700;font-weight:700}
.meta{display:flex;flex-wrap:wrap;gap:4px 22px;margin:8px 0 4px;font-size:13px}.meta b{color:#5b6575;font-weight:600}
td{overflow-wrap:break-word}
@page{size:A4;margin:12mm 11mm 14mm}
@media print{
body{background:#fff;font-size:11px}main{max-width:none;padding:0}
h1{font-size:20px}h2{font-size:15px;margin:16px 0 6px;break-after:avoid}h3{break-after:avoid}
p,li{font-size:11px}.muted,figcaption{font-size:10px}
table{font-size:9px;width:100%;table-layout:auto}th,td{padding:2px 3px}
thead{display:table-header-group}tr,figure,img{break-inside:avoid}
.scroll{max-height:none;overflow:visible;border:0}
.grid{grid-template-columns:repeat(2,1fr);gap:6px}
figure img{max-width:100%;max-height:125mm;width:auto;object-fit:contain}
}
"""


def fmt_value(value, std=None, digits=2) -> str:
    """``value ± std`` with the value rounded to the std's precision (2 significant digits)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    if std is None or not math.isfinite(std) or std <= 0:
        return f"{value:.4g}"
    decimals = max(0, digits - 1 - int(math.floor(math.log10(std))))
    if decimals > 10:
        return f"{value:.6g} ± {std:.{digits}g}"
    return f"{value:.{decimals}f} ± {std:.{decimals}f}"


def image_tag(data: bytes, alt: str, *, mime: str = "image/svg+xml") -> str:
    """An ``<img>`` holding ``data`` (SVG by default) with its ``alt`` text escaped."""
    return f'<img alt="{html.escape(alt)}" src="data:{mime};base64,{base64.b64encode(data).decode("ascii")}">'


def table_html(frame: pd.DataFrame, left=()) -> str:
    """A table of ``frame``: text escaped, floats to 4 significant digits, missing or
    non-finite values as "—"; the columns named in ``left`` left-aligned."""
    if frame is None or len(frame) == 0:
        return '<p class="muted">None.</p>'
    head = "".join(f'<th class="{"l" if c in left else ""}">{html.escape(str(c))}</th>' for c in frame.columns)
    body = []
    for row in frame.itertuples(index=False):
        cells = []
        for c, v in zip(frame.columns, row):
            text = (
                v
                if isinstance(v, str)
                else (
                    "—"
                    if v is None or (isinstance(v, float) and not math.isfinite(v))
                    else f"{v:.4g}"
                    if isinstance(v, float)
                    else str(v)
                )
            )
            cells.append(f'<td class="{"l" if c in left else ""}">{html.escape(str(text))}</td>')
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def page_html(title: str, parts, *, css: str = PAGE_CSS, head: str = "", main: bool = True) -> str:
    """A whole page: ``title`` (escaped), the style ``css``, trusted ``head`` markup
    (a refresh, ...) and the body's HTML ``parts`` in order (inside ``<main>``
    unless ``main`` is false)."""
    body = "\n".join(parts)
    if main:
        body = f"<main>{body}</main>"
    return (
        f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">{head}'
        f"<title>{html.escape(title)}</title><style>{css}</style></head><body>{body}</body></html>\n"
    )


def unit_words(unit) -> str:
    """A figure's unit code (``"nm_per_rad"``) as a reader writes it (``"N·m/rad"``);
    an unknown code as it is."""
    return _UNIT_WORDS.get(str(unit), str(unit))
