"""The live page of ``watch``: the loop so far against the plan, in a file that reloads.

:func:`live_page` returns one self-contained HTML page (no script, no network) with
a ``<meta http-equiv="refresh">`` so a browser opened on the file shows the latest
state: progress, the next step to load, the torque–angle loop of the photographs so
far (hand-written SVG: drawing it costs well under a millisecond, a matplotlib
figure ~100 ms), the plan's torque sequence with the photographed rows marked, the
latest images with Δangle, and every warning on the image where it happened.
"""

from __future__ import annotations

import html
import math
import time
from dataclasses import dataclass

__all__ = ["LivePoint", "live_page", "LIVE_PAGE_NAME"]

#: File name of the live page in the output folder.
LIVE_PAGE_NAME = "live.html"
_W, _H, _PAD = 560, 380, 48


@dataclass(frozen=True)
class LivePoint:
    """One photographed row, as the page shows it.

    Attributes
    ----------
    number : int
        Position of the row in the manifest, 1-based.
    file : str
        The photograph's file name.
    line : int
        Manifest CSV line.
    orientation_deg : float
    label : str
        Phase and step, e.g. "negative_loading s3".
    torque_nm : float
        Planned torque of the row (N·m).
    angle_deg, delta_deg : float
        Angle (deg, NaN when not measured) and the step from the previous image.
    warnings : tuple of str
    """

    number: int
    file: str
    line: int
    orientation_deg: float
    label: str
    torque_nm: float
    angle_deg: float
    delta_deg: float
    warnings: tuple = ()


def _scale(lo, hi, a, b):
    if not hi > lo:
        lo, hi = lo - 1.0, hi + 1.0
    pad = 0.05 * (hi - lo)
    lo, hi = lo - pad, hi + pad
    return lambda v: a + (v - lo) / (hi - lo) * (b - a), lo, hi


def _axes(svg, x_lo, x_hi, y_lo, y_hi, fx, fy, xlabel, ylabel):
    svg.append(f'<rect x="{_PAD}" y="10" width="{_W - _PAD - 10}" height="{_H - _PAD - 10}" '
               'fill="#fff" stroke="#888"/>')
    for k in range(5):
        xv = x_lo + (x_hi - x_lo) * k / 4
        yv = y_lo + (y_hi - y_lo) * k / 4
        svg.append(f'<text x="{fx(xv):.1f}" y="{_H - _PAD + 16}" text-anchor="middle" '
                   f'font-size="11">{xv:.3g}</text>')
        svg.append(f'<text x="{_PAD - 4}" y="{fy(yv) + 4:.1f}" text-anchor="end" '
                   f'font-size="11">{yv:.3g}</text>')
        svg.append(f'<line x1="{_PAD}" x2="{_W - 10}" y1="{fy(yv):.1f}" y2="{fy(yv):.1f}" '
                   'stroke="#eee"/>')
    svg.append(f'<text x="{(_PAD + _W) / 2}" y="{_H - 8}" text-anchor="middle" '
               f'font-size="12">{xlabel}</text>')
    svg.append(f'<text x="12" y="{_H / 2}" text-anchor="middle" font-size="12" '
               f'transform="rotate(-90 12 {_H / 2})">{ylabel}</text>')


def _loop_svg(points, orientation, next_torque) -> str:
    """Torque against angle: this orientation's photographs joined in capture order,
    earlier orientations in grey, the next planned torque dashed."""
    done = [p for p in points if math.isfinite(p.angle_deg)]
    if not done:
        return "<p>No angle measured yet.</p>"
    angles = [p.angle_deg for p in done]
    torques = [p.torque_nm for p in done] + ([next_torque] if next_torque is not None else [])
    fx, x_lo, x_hi = _scale(min(angles), max(angles), _PAD, _W - 10)
    fy, y_lo, y_hi = _scale(min(torques), max(torques), _H - _PAD, 10)
    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{_W}" height="{_H}" role="img" '
           'aria-label="torque against angle">']
    _axes(svg, x_lo, x_hi, y_lo, y_hi, fx, fy, "angle (°)", "torque (N·m)")
    for o in dict.fromkeys(p.orientation_deg for p in done):
        mine = [p for p in done if p.orientation_deg == o]
        colour = "#1f5fbf" if o == orientation else "#bbb"
        path = " ".join(f"{fx(p.angle_deg):.1f},{fy(p.torque_nm):.1f}" for p in mine)
        svg.append(f'<polyline points="{path}" fill="none" stroke="{colour}" stroke-width="1.5"/>')
        for p in mine:
            fill = "#d62728" if p.warnings else colour
            svg.append(f'<circle cx="{fx(p.angle_deg):.1f}" cy="{fy(p.torque_nm):.1f}" r="3.5" '
                       f'fill="{fill}"><title>{html.escape(p.file)}: {p.label}</title></circle>')
    if next_torque is not None:
        y = fy(next_torque)
        svg.append(f'<line x1="{_PAD}" x2="{_W - 10}" y1="{y:.1f}" y2="{y:.1f}" stroke="#2ca02c" '
                   'stroke-dasharray="6 4"/>')
        svg.append(f'<text x="{_W - 14}" y="{y - 4:.1f}" text-anchor="end" font-size="11" '
                   'fill="#2ca02c">next planned torque</text>')
    last = done[-1]
    svg.append(f'<circle cx="{fx(last.angle_deg):.1f}" cy="{fy(last.torque_nm):.1f}" r="7" '
               'fill="none" stroke="#000" stroke-width="1.5"/>')
    svg.append("</svg>")
    return "".join(svg)


def _plan_svg(planned_torques, points) -> str:
    """The plan's torque of every row (grey) with the photographed ones marked."""
    n = len(planned_torques)
    fx, x_lo, x_hi = _scale(1, max(n, 2), _PAD, _W - 10)
    fy, y_lo, y_hi = _scale(min(planned_torques), max(planned_torques), _H - _PAD, 10)
    svg = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{_W}" height="{_H}" role="img" '
           'aria-label="planned torque of every image">']
    _axes(svg, x_lo, x_hi, y_lo, y_hi, fx, fy, "image number (manifest order)", "planned torque (N·m)")
    path = " ".join(f"{fx(i + 1):.1f},{fy(t):.1f}" for i, t in enumerate(planned_torques))
    svg.append(f'<polyline points="{path}" fill="none" stroke="#bbb" stroke-width="1"/>')
    for p in points:
        fill = "#d62728" if p.warnings else ("#1f5fbf" if math.isfinite(p.angle_deg) else "#ff7f0e")
        svg.append(f'<circle cx="{fx(p.number):.1f}" cy="{fy(p.torque_nm):.1f}" r="3" '
                   f'fill="{fill}"/>')
    svg.append("</svg>")
    return "".join(svg)


def live_page(*, title: str, points, planned_torques, next_step: str | None,
              next_torque_nm: float | None = None, messages=(), refresh_s: int = 2,
              finished: bool = False, now: float | None = None) -> str:
    """The live page's HTML.

    Parameters
    ----------
    title : str
        The session's name.
    points : sequence of LivePoint
        Photographed rows, in capture order.
    planned_torques : sequence of float
        Planned torque of every manifest row, in manifest order (N·m).
    next_step : str or None
        What to load and photograph next (None when every row has its image).
    next_torque_nm : float, optional
        Its planned torque (N·m), drawn on the loop.
    messages : sequence of str
        Other notices (files set aside, deleted, the folder gone), newest last.
    refresh_s : int
        Seconds between reloads; no reload once `finished`.
    finished : bool
        The watch has ended.
    now : float, optional
        Time shown as "updated" (seconds since the epoch).
    """
    points = list(points)
    n_rows = len(planned_torques)
    current = points[-1].orientation_deg if points else None
    next_torque = next_torque_nm if next_step is not None else None
    stamp = time.strftime("%H:%M:%S", time.localtime(now if now is not None else time.time()))
    warned = [p for p in points if p.warnings]
    head = (f'<meta http-equiv="refresh" content="{int(refresh_s)}">' if not finished else "")
    rows = []
    for p in points[-12:][::-1]:
        cls = ' class="warn"' if p.warnings else ""
        angle = f"{p.angle_deg:+.4f}" if math.isfinite(p.angle_deg) else "—"
        delta = f"{p.delta_deg:+.4f}" if math.isfinite(p.delta_deg) else "—"
        rows.append(f"<tr{cls}><td>{p.number}</td><td>{html.escape(p.file)}</td><td>{p.line}</td>"
                    f"<td>{p.orientation_deg:g}°</td><td>{html.escape(p.label)}</td>"
                    f"<td>{p.torque_nm:+.5f}</td><td>{angle}</td><td>{delta}</td>"
                    f"<td>{'<br>'.join(html.escape(w) for w in p.warnings)}</td></tr>")
    warn_items = "".join(f"<li><b>{html.escape(p.file)}</b> (line {p.line}, {html.escape(p.label)}): "
                         + "; ".join(html.escape(w) for w in p.warnings) + "</li>" for p in warned)
    notes = "".join(f"<li>{html.escape(m)}</li>" for m in list(messages)[-10:])
    state = ("finished" if finished else f"watching — reloads every {int(refresh_s)} s")
    nxt = (f'<p class="next">Next: {html.escape(str(next_step))}</p>' if next_step is not None
           else '<p class="next">Every planned image is in.</p>')
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">{head}
<title>live: {html.escape(title)}</title>
<style>
body {{ font-family: sans-serif; margin: 16px; color: #222; }}
h1 {{ font-size: 20px; margin: 0 0 4px; }}
.status {{ color: #555; margin: 0 0 8px; }}
.next {{ font-size: 18px; background: #eef7ee; border-left: 5px solid #2ca02c; padding: 6px 10px; }}
.plots {{ display: flex; flex-wrap: wrap; gap: 12px; }}
figure {{ margin: 0; max-width: {_W}px; }}
th {{ text-align: left; }}
table {{ border-collapse: collapse; font-size: 13px; margin-top: 8px; }}
td, th {{ border: 1px solid #ccc; padding: 2px 6px; text-align: right; }}
td:nth-child(2), td:nth-child(5), td:nth-child(9) {{ text-align: left; }}
tr.warn td {{ background: #fde8e8; }}
.warnings li {{ color: #a00; }}
</style></head><body>
<h1>{html.escape(title)}</h1>
<p class="status">{len(points)} of {n_rows} planned images · {len(warned)} with warnings · updated {stamp} · {state}</p>
{nxt}
<div class="plots"><figure>{_loop_svg(points, current, next_torque)}<figcaption>Torque against angle
(this orientation in blue, earlier ones grey, red: a warning, ringed: the latest image)</figcaption></figure>
<figure>{_plan_svg(list(planned_torques), points)}<figcaption>The plan: planned torque of every image
(grey), photographed ones marked</figcaption></figure></div>
<h2>Warnings</h2>
<ul class="warnings">{warn_items or "<li style='color:#2a2'>none</li>"}</ul>
<h2>Latest images</h2>
<table><tr><th>#</th><th>file</th><th>line</th><th>orientation</th><th>phase, step</th>
<th>torque (N·m)</th><th>angle (°)</th><th>Δangle (°)</th><th>warnings</th></tr>
{"".join(rows)}</table>
{f"<h2>Notices</h2><ul>{notes}</ul>" if notes else ""}
</body></html>
"""
