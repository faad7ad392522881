"""The live page of ``watch``: the loop so far against the plan, in a file that reloads.

:func:`live_page` returns one self-contained HTML page (no network) that a browser
opened on the file keeps up to date: a few lines of script load the small stamp file
``live-stamp.js`` beside it every 0.25 s (a ``<script>`` element, which a page
opened from a ``file://`` address may load where ``fetch`` may not) and reload the
page only when the stamp differs from the one the page was written with (so it does
not flicker while nothing changes, and a browser restores the scroll position on a
reload); without scripts, a ``<meta http-equiv="refresh">`` reloads it every second.
:func:`stamp_script` is the stamp's text; the writer writes the page first, then its
stamp. The page shows the latest state: progress, the next step to load, the
torque–angle loop of the photographs so far (hand-written SVG: drawing it costs well
under a millisecond, a matplotlib figure ~100 ms), the plan's torque sequence with
the photographed rows marked, the latest images with Δangle, every warning on the
image where it happened, whether each loop closes (and the drift at the closing
image), and, once the watch has ended, a link to the report.

Axes carry round ticks (1, 2, 2.5 or 5 × 10ⁿ). Photographs are joined only where
the torque moved by at most one planned step between them: the pre-load from the
reference to +Tmax and the unloading before a closing image are not photographed,
and a line across them would look like a loading path.
"""

from __future__ import annotations

import html
import math
import time
from dataclasses import dataclass

from ..htmlpage import page_html

__all__ = ["LivePoint", "live_page", "nice_ticks", "loop_closure", "LIVE_PAGE_NAME", "LIVE_STAMP_NAME",
           "stamp_script"]

#: File name of the live page in the output folder.
LIVE_PAGE_NAME = "live.html"
#: File name of the live page's stamp beside it (:func:`stamp_script`).
LIVE_STAMP_NAME = "live-stamp.js"
#: Milliseconds between the page's looks at its stamp.
_STAMP_POLL_MS = 250
_W, _H, _PAD = 560, 380, 48
_LIVE_CSS = """
body {{ font-family: sans-serif; margin: 16px; color: #222; }}
h1 {{ font-size: 20px; margin: 0 0 4px; }}
.status {{ color: #555; margin: 0 0 8px; }}
.next {{ font-size: 18px; background: #eef7ee; border-left: 5px solid #2ca02c; padding: 6px 10px; }}
.plots {{ display: flex; flex-wrap: wrap; gap: 12px; }}
figure {{ margin: 0; max-width: {w}px; }}
th {{ text-align: left; }}
table {{ border-collapse: collapse; font-size: 13px; margin-top: 8px; }}
td, th {{ border: 1px solid #ccc; padding: 2px 6px; text-align: right; }}
td:nth-child(2), td:nth-child(5), td:nth-child(9) {{ text-align: left; }}
tr.warn td {{ background: #fde8e8; }}
.warnings li {{ color: #a00; }}
li.ok {{ color: #1a7f37; }} li.bad {{ color: #a00; font-weight: 600; }}
""".format(w=_W)


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
    phase : str
        The row's phase ("" when not given: then read from `label`, "<phase> s<step>").
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
    phase: str = ""

    @property
    def phase_name(self) -> str:
        """The phase: `phase`, else the first word of `label`."""
        return self.phase or (self.label.split(" ")[0] if self.label else "")


def nice_ticks(lo: float, hi: float, *, minimum: int = 4) -> list[float]:
    """Round tick values inside [lo, hi]: the widest spacing of 1, 2, 2.5 or 5 × 10ⁿ
    that still gives at least `minimum` ticks.

    Examples
    --------
    >>> nice_ticks(-6.88, 13.8)
    [-5.0, 0.0, 5.0, 10.0]
    >>> nice_ticks(-0.36, 0.36)
    [-0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3]
    """
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return [lo] if math.isfinite(lo) else []
    top = 10.0 ** math.ceil(math.log10(hi - lo))
    for step in (top * m / d for d in (1, 10, 100, 1000) for m in (1.0, 0.5, 0.25, 0.2)):
        first, last = math.ceil(lo / step - 1e-9), math.floor(hi / step + 1e-9)
        if last - first + 1 >= minimum:
            return [round(k * step, 12) + 0.0 for k in range(first, last + 1)]
    return [lo, hi]  # pragma: no cover - a spacing of range/1000 always gives enough


def loop_closure(points) -> list[tuple[str, float]]:
    """How far each loop of one orientation's photographs fails to close (deg).

    For each loop: the angle at its last ``positive_loading`` image (+Tmax) minus
    the angle at the ``positive_unloading`` image that began it (the same +Tmax);
    for a ``closing`` image, its angle minus that of the first loop's last
    ``positive_unloading`` image (the same unloaded state). Drift and creep show as
    these differences. Returns ``[(what, difference_deg), ...]`` in capture order;
    a loop still being shot (its loading not yet back at its first torque) is not
    listed.

    Examples
    --------
    >>> pts = [LivePoint(i, "", i, 0.0, f"{ph} s0", 0.0, a, 0.0) for i, (ph, a) in enumerate(
    ...     [("positive_unloading", 10.0), ("positive_unloading", 9.0), ("negative_loading", 5.0),
    ...      ("negative_unloading", 4.0), ("positive_loading", 10.25), ("closing", 9.5)])]
    >>> loop_closure(pts)
    [('loop 1', 0.25), ('closing − loop 1 unloaded', 0.5)]
    """
    out = []
    loops = []

    def close(start, end):
        loops.append(end.angle_deg - start.angle_deg)
        out.append((f"loop {len(loops)}", loops[-1]))

    start = unloaded = last_loading = None
    previous = ""
    for p in points:
        if not math.isfinite(p.angle_deg):
            continue
        ph = p.phase_name
        if ph == "positive_unloading" and previous != "positive_unloading":
            if start is not None and last_loading is not None:
                close(start, last_loading)
            start, last_loading = p, None
        if ph == "positive_unloading" and not loops:
            unloaded = p  # the first loop's unloading, down to zero
        if ph == "positive_loading":
            last_loading = p
        if ph == "closing":
            if start is not None and last_loading is not None:
                close(start, last_loading)
                start = last_loading = None
            if unloaded is not None:
                out.append(("closing − loop 1 unloaded", p.angle_deg - unloaded.angle_deg))
        previous = ph
    # the last loop, once its loading is back at the torque it began at
    if start is not None and last_loading is not None \
            and abs(last_loading.torque_nm - start.torque_nm) <= 1e-9 * max(abs(start.torque_nm), 1e-12):
        close(start, last_loading)
    return out


def _scale(lo, hi, a, b):
    if not hi > lo:
        lo, hi = lo - 1.0, hi + 1.0
    pad = 0.05 * (hi - lo)
    lo, hi = lo - pad, hi + pad
    return lambda v: a + (v - lo) / (hi - lo) * (b - a), lo, hi


def _axes(svg, x_lo, x_hi, y_lo, y_hi, fx, fy, xlabel, ylabel):
    svg.append(f'<rect x="{_PAD}" y="10" width="{_W - _PAD - 10}" height="{_H - _PAD - 10}" '
               'fill="#fff" stroke="#888"/>')
    for xv in nice_ticks(x_lo, x_hi):
        svg.append(f'<text x="{fx(xv):.1f}" y="{_H - _PAD + 16}" text-anchor="middle" '
                   f'font-size="11">{xv:g}</text>')
        svg.append(f'<line x1="{fx(xv):.1f}" x2="{fx(xv):.1f}" y1="10" y2="{_H - _PAD}" stroke="#f2f2f2"/>')
    for yv in nice_ticks(y_lo, y_hi):
        svg.append(f'<text x="{_PAD - 4}" y="{fy(yv) + 4:.1f}" text-anchor="end" '
                   f'font-size="11">{yv:g}</text>')
        svg.append(f'<line x1="{_PAD}" x2="{_W - 10}" y1="{fy(yv):.1f}" y2="{fy(yv):.1f}" '
                   'stroke="#eee"/>')
    svg.append(f'<text x="{(_PAD + _W) / 2}" y="{_H - 8}" text-anchor="middle" '
               f'font-size="12">{xlabel}</text>')
    svg.append(f'<text x="12" y="{_H / 2}" text-anchor="middle" font-size="12" '
               f'transform="rotate(-90 12 {_H / 2})">{ylabel}</text>')


def _runs(points, max_step_nm):
    """`points` cut where the torque jumps by more than one planned step (an
    unphotographed pre-load or unloading): each run is a path that was loaded."""
    runs, run = [], []
    for p in points:
        if run and abs(p.torque_nm - run[-1].torque_nm) > max_step_nm:
            runs.append(run)
            run = []
        run.append(p)
    return runs + ([run] if run else [])


def _largest_step(planned_torques) -> float:
    """1.5 × the planned torque step (the median of the plan's steps, N·m): the
    largest jump a loaded path makes between two photographs."""
    floor = 1e-6 * max((abs(t) for t in planned_torques), default=0.0)  # 0.0 then -0.0 is no step
    steps = [abs(b - a) for a, b in zip(planned_torques, planned_torques[1:]) if abs(b - a) > floor]
    return 1.5 * sorted(steps)[len(steps) // 2] if steps else math.inf  # the median step


def _loop_svg(points, orientation, next_torque, max_step_nm=math.inf) -> str:
    """Torque against angle: this orientation's photographs joined in capture order
    where the torque was loaded step by step, earlier orientations in grey, the next
    planned torque dashed."""
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
        for run in _runs(mine, max_step_nm):
            path = " ".join(f"{fx(p.angle_deg):.1f},{fy(p.torque_nm):.1f}" for p in run)
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


def _closure_html(points, orientation) -> str:
    """Does each loop of the current orientation close? The differences of
    :func:`loop_closure`, judged against 1 % of the orientation's angle span."""
    mine = [p for p in points if p.orientation_deg == orientation and math.isfinite(p.angle_deg)]
    found = loop_closure(mine)
    if not found:
        return ('<p class="status">Loop closure and drift: shown once a loop of this orientation is complete.</p>')
    span = max(p.angle_deg for p in mine) - min(p.angle_deg for p in mine)
    limit = 0.01 * span
    items = []
    for what, diff in found:
        ok = abs(diff) <= limit
        items.append(f'<li class="{"ok" if ok else "bad"}">{html.escape(what)}: {diff:+.4f}° '
                     + ("(closes)" if ok else "(open by more than 1 % of the angle span: drift, creep or a "
                        "moved target?)") + "</li>")
    return (f"<h2>Loop closure and drift ({orientation:g}°)</h2><ul>{''.join(items)}</ul>"
            f'<p class="status">Same load state, photographed twice: the difference of the angles; '
            f"1 % of the angle span = {limit:.4f}°.</p>")


def stamp_script(version: str) -> str:
    """The text of ``live-stamp.js`` for the page written with `version` (letters,
    digits, ``-`` and ``_`` only: it is put in a script)."""
    if not version or not all(c.isascii() and (c.isalnum() or c in "-_") for c in version):
        raise ValueError(f"version must be letters, digits, '-' or '_', got {version!r}")
    return f'liveStamp("{version}");\n'


def _reloader(version: str) -> str:
    """The page's script: load the stamp every _STAMP_POLL_MS, reload when it changed."""
    stamp_script(version)  # checks it
    return ('<script>(function () {\n'
            f'  var mine = "{version}", busy = false;\n'
            '  window.liveStamp = function (s) { if (s !== mine) { location.reload(); } };\n'
            '  setInterval(function () {\n'
            '    if (busy) { return; }\n'
            '    busy = true;\n'
            '    var e = document.createElement("script");\n'
            f'    e.src = "{LIVE_STAMP_NAME}?" + Date.now();\n'
            '    e.onload = e.onerror = function () { e.remove(); busy = false; };\n'
            '    document.head.appendChild(e);\n'
            f'  }}, {_STAMP_POLL_MS});\n'
            '})();</script>')


def live_page(*, title: str, points, planned_torques, next_step: str | None,
              next_torque_nm: float | None = None, messages=(), refresh_s: int = 1,
              finished: bool = False, now: float | None = None, report_href: str = "report.html",
              version: str | None = None) -> str:
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
        Seconds between reloads in a browser without scripts; no reload once
        `finished`.
    finished : bool
        The watch has ended.
    now : float, optional
        Time shown as "updated" (seconds since the epoch).
    report_href : str
        Where the report will be, relative to the page (``watch`` writes it next to
        the page when it ends): linked once `finished`.
    version : str, optional
        The page's stamp (:func:`stamp_script`): with it, and not `finished`, the
        page reloads as soon as ``live-stamp.js`` beside it holds another; the
        meta refresh is then only for a browser without scripts.

    Raises
    ------
    ValueError
        `version` holds a character other than a letter, a digit, ``-`` or ``_``.
    """
    points = list(points)
    n_rows = len(planned_torques)
    current = points[-1].orientation_deg if points else None
    next_torque = next_torque_nm if next_step is not None else None
    stamp = time.strftime("%H:%M:%S", time.localtime(now if now is not None else time.time()))
    warned = [p for p in points if p.warnings]
    refresh = f'<meta http-equiv="refresh" content="{int(refresh_s)}">'
    head = ("" if finished else refresh if version is None
            else f"<noscript>{refresh}</noscript>{_reloader(version)}")
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
    state = ("finished" if finished else f"watching — reloads every {int(refresh_s)} s" if version is None
             else "watching — updates as each photograph comes in")
    closure = _closure_html(points, current)
    report = (f'<p class="next">Finished. The report: <a href="{html.escape(report_href)}">'
              f"{html.escape(report_href)}</a> (written next to this page as the watch ends; if it is missing, "
              "run <code>vision-torsion report</code> on the session folder).</p>" if finished else "")
    nxt = (f'<p class="next">Next: {html.escape(str(next_step))}</p>' if next_step is not None
           else '<p class="next">Every planned image is in.</p>')
    body = f"""<h1>{html.escape(title)}</h1>
<p class="status">{len(points)} of {n_rows} planned images · {len(warned)} with warnings · updated {stamp} · {state}</p>
{report}{nxt}
<div class="plots"><figure>{_loop_svg(points, current, next_torque, _largest_step(list(planned_torques)))}
<figcaption>Torque against angle (this orientation in blue, earlier ones grey, red: a warning, ringed: the latest
image; photographs joined where the torque was loaded step by step)</figcaption></figure>
<figure>{_plan_svg(list(planned_torques), points)}<figcaption>The plan: planned torque of every image
(grey), photographed ones marked</figcaption></figure></div>
{closure}
<h2>Warnings</h2>
<ul class="warnings">{warn_items or "<li style='color:#2a2'>none</li>"}</ul>
<h2>Latest images</h2>
<table><tr><th>#</th><th>file</th><th>line</th><th>orientation</th><th>phase, step</th>
<th>torque (N·m)</th><th>angle (°)</th><th>Δangle (°)</th><th>warnings</th></tr>
{"".join(rows)}</table>
{f"<h2>Notices</h2><ul>{notes}</ul>" if notes else ""}
"""
    return page_html(f"live: {title}", [body], css=_LIVE_CSS, head=head, main=False)
