"""The printable capture sheet: ``capture_sheet.html`` (and ``.pdf`` where Chromium is).

One A4 page header with the test's fields (gear, serial number, operator, date:
printed when given to ``plan``, blank lines to fill in otherwise), the rig, the
sign convention in words and as a picture (which pans make positive torque and
which way the marker line then turns in the camera image), then one section per
orientation, each starting on a new page, with a row per photograph: the mass on
each pan, the torque, the file name to save it under, a blank to note the camera's
own file number and a box to tick. On every printed page: the orientation and the
column names (the table head repeats), the gear and serial number at the top and
"page N of M" at the bottom (CSS page-margin boxes). The
unphotographed steps (preconditioning, the pre-load, the return to zero before a
closing image) are rows of their own, in italics.

The PDF is printed by a headless Chromium when one is installed (``chromium``,
``chromium-browser``, ``google-chrome``); without one only the HTML is written,
and a browser prints it the same way (the page carries its own print CSS).
"""

from __future__ import annotations

import html
import logging
import shutil
import subprocess
import tempfile
from pathlib import Path

from ..fileio import atomic_write_text
from ..htmlpage import page_html
from .torque import couple_torque

__all__ = ["capture_sheet_html", "sign_picture_svg", "write_capture_sheet", "find_chromium",
           "CAPTURE_SHEET_HTML", "CAPTURE_SHEET_PDF"]

logger = logging.getLogger(__name__)

CAPTURE_SHEET_HTML = "capture_sheet.html"
CAPTURE_SHEET_PDF = "capture_sheet.pdf"
_HEADER_FIELDS = (("gear", "Gear (type, ratio)"), ("serial", "Serial number"),
                  ("operator", "Operator"), ("date", "Date"))


def sign_picture_svg(angle_sign: int) -> str:
    """The sign convention as a picture: the disk as the camera sees it, the "+" and
    "−" pans, and the marker line before and after a positive torque.

    With ``angle_sign = +1`` a positive torque turns the marker line
    counter-clockwise in the camera image (the angle's own sense); with −1,
    clockwise. The "+ pans" are by definition the pair that makes positive torque.
    """
    ccw = angle_sign > 0
    turn = 22 if ccw else -22  # degrees, counter-clockwise as displayed
    import math

    cx, cy, r = 170, 150, 95

    def pt(angle_deg, radius):
        a = math.radians(angle_deg)
        return cx + radius * math.cos(a), cy - radius * math.sin(a)

    x1, y1 = pt(180 + 10, 70)
    x2, y2 = pt(10, 70)
    a1, b1 = pt(180 + 10 + turn, 70)
    a2, b2 = pt(10 + turn, 70)
    # the curved arrow of the positive rotation, outside the disk
    start, end = (60, 120) if ccw else (120, 60)
    sx, sy = pt(start, r + 18)
    ex, ey = pt(end, r + 18)
    sweep = 0 if ccw else 1
    # one pan of each pair drawn: a pan hanging from the rim pulls that side down, so
    # the + pan hangs on the left for a counter-clockwise turn, on the right otherwise
    plus_x, minus_x = (cx - r, cx + r) if ccw else (cx + r, cx - r)
    return f"""<svg xmlns="http://www.w3.org/2000/svg" width="360" height="300" viewBox="0 0 360 300" role="img"
 aria-label="sign convention">
<defs><marker id="arrow" viewBox="0 0 10 10" refX="8" refY="5" markerWidth="7" markerHeight="7"
 orient="auto-start-reverse">
<path d="M0,0 L10,5 L0,10 z" fill="#1f5fbf"/></marker></defs>
<circle cx="{cx}" cy="{cy}" r="{r}" fill="#f4f4f4" stroke="#444" stroke-width="2"/>
<line x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" stroke="#999" stroke-width="2" stroke-dasharray="6 4"/>
<circle cx="{x1:.1f}" cy="{y1:.1f}" r="9" fill="#bbb"/><circle cx="{x2:.1f}" cy="{y2:.1f}" r="9" fill="#bbb"/>
<line x1="{a1:.1f}" y1="{b1:.1f}" x2="{a2:.1f}" y2="{b2:.1f}" stroke="#000" stroke-width="2.5"/>
<circle cx="{a1:.1f}" cy="{b1:.1f}" r="9" fill="#222"/><circle cx="{a2:.1f}" cy="{b2:.1f}" r="9" fill="#222"/>
<path d="M{sx:.1f},{sy:.1f} A{r + 18},{r + 18} 0 0 {sweep} {ex:.1f},{ey:.1f}" fill="none" stroke="#1f5fbf"
 stroke-width="3" marker-end="url(#arrow)"/>
<text x="{cx}" y="22" text-anchor="middle" font-size="13" fill="#1f5fbf">positive torque turns it
 {"counter-clockwise" if ccw else "clockwise"}</text>
<line x1="{plus_x}" y1="{cy}" x2="{plus_x}" y2="{cy + 120}" stroke="#444" stroke-width="1.5"/>
<rect x="{plus_x - 24}" y="{cy + 120}" width="48" height="22" fill="#d9ead3" stroke="#444"/>
<text x="{plus_x}" y="{cy + 136}" text-anchor="middle" font-size="13" font-weight="bold">+ pan</text>
<line x1="{minus_x}" y1="{cy}" x2="{minus_x}" y2="{cy + 120}" stroke="#444" stroke-width="1.5" stroke-dasharray="3 3"/>
<rect x="{minus_x - 24}" y="{cy + 120}" width="48" height="22" fill="#f4cccc" stroke="#444"/>
<text x="{minus_x}" y="{cy + 136}" text-anchor="middle" font-size="13" font-weight="bold">− pan</text>
</svg>"""


def _css_string(text: str) -> str:
    """`text` for a CSS string in double quotes inside <style> (no markup there)."""
    out = "".join(f"\\{ord(c):x} " if c in '"\\<>' or ord(c) < 32 else c for c in text)
    return out


def _pan(pieces: int, step_kg: float) -> str:
    if pieces == 0:
        return "empty"
    return f"{pieces * step_kg * 1000:g} g ({pieces} × {step_kg * 1000:g} g)"


def capture_sheet_html(plan) -> str:
    """The capture sheet of a :class:`~vision_torsion.session.plan.SessionPlan` as HTML."""
    cfg, n = plan.config, plan.steps_per_phase
    rig = cfg.rig
    step = rig.step_mass_kg
    esc = html.escape
    fields = "".join(
        f"<tr><th>{label}</th><td>{esc(str(plan.header.get(key, '')))}</td></tr>" for key, label in _HEADER_FIELDS
    )
    below, above = plan.nearest_max_torques_nm
    snapped = (
        ""
        if plan.exact
        else f" (requested {plan.requested_max_torque_nm:g} N·m is not a whole number of steps: "
        f"the nearest achievable maxima are {below:.5f} N·m with {n} steps and "
        f"{above:.5f} N·m with {n + 1})"
    )
    ccw = cfg.angle_sign > 0
    words = (
        f"<b>Sign convention.</b> The <b>+ pans</b> are the two pans whose wires make "
        f"<b>positive torque</b>; loading them turns the disk, and the line from one marker to "
        f"the other, <b>{'counter-clockwise' if ccw else 'clockwise'}</b> as seen in the camera "
        f"image (session.toml: angle_sign = {cfg.angle_sign:+d}). Before the first loaded "
        "photograph, load one + piece and check the turn on the camera's screen: if the line "
        "turns the other way, the pans are swapped or angle_sign is wrong; fix it now."
    )
    named = [str(plan.header[k]) for k in ("gear", "serial") if plan.header.get(k)]
    ident = esc(" — " + ", ".join(named)) if named else ""
    running = _css_string("Capture sheet" + (" — " + ", ".join(named) if named else ""))
    sections = []
    current = None
    body: list[str] = []
    number = 0

    def close_section():
        if current is not None:
            sections.append(
                f"<section><h2>Orientation {esc(current)}°</h2><p>Rotate the flexspline to "
                f"{esc(current)}° relative to the circular spline. Remove all weights.</p>"
                # the head repeats on every printed page: the orientation, then the column names
                f'<table><thead><tr class="title"><th colspan="10">Orientation {esc(current)}°{ident}'
                "</th></tr><tr><th>#</th><th>cycle</th><th>phase</th><th>step</th>"
                "<th>+ pans (each)</th><th>− pans (each)</th><th>torque (N·m)</th>"
                '<th>save as</th><th class="cam">camera file no.</th><th>done</th></tr></thead><tbody>'
                + "".join(body) + "</tbody></table></section>"
            )

    for row in plan.rows:
        if row["orientation_deg"] != current:
            close_section()
            current, body = row["orientation_deg"], []
        phase = row["phase"]
        if phase == "reference" and plan.preconditioning_cycles:
            body.append(
                f'<tr class="quiet"><td></td><td></td><td colspan="5">preconditioning, no '
                f"photographs: load to +{plan.max_torque_nm:.5f} N·m and −{plan.max_torque_nm:.5f}"
                f" N·m {plan.preconditioning_cycles} time(s), then remove all weights</td>"
                "<td></td><td></td><td>☐</td></tr>"
            )
        if phase == "closing":
            body.append(
                '<tr class="quiet"><td></td><td></td><td colspan="5">unload to zero step by '
                "step, no photographs</td><td></td><td></td><td>☐</td></tr>"
            )
        pieces = round(float(row["mass_kg"]) / step)
        torque = couple_torque(float(row["mass_kg"]), phase, rig).torque_nm
        plus = _pan(pieces if phase.startswith("positive") else 0, step)
        minus = _pan(pieces if phase.startswith("negative") else 0, step)
        number += 1
        level = plan.level_label(pieces, phase) if hasattr(plan, "level_label") else ""
        level = f" <b>({esc(level)})</b>" if level else ""
        body.append(
            f"<tr><td>{number}</td><td>{row['cycle']}</td><td>{esc(phase)}</td><td>{row['step']}</td>"
            f"<td>{plus}</td><td>{minus}</td><td>{torque:+.5f}{level}</td><td><code>{esc(row['image'])}"
            "</code></td><td></td><td>☐</td></tr>"
        )
        if phase == "reference":
            body.append(
                f'<tr class="quiet"><td></td><td></td><td colspan="5">pre-load, no photographs: '
                f"add {step * 1000:g} g to each + pan {n} times → {plan.max_torque_nm:+.5f} N·m</td>"
                "<td></td><td></td><td>☐</td></tr>"
            )
    close_section()
    per_step = plan.torque_per_step_nm
    # the page style: A4, every page with the running title, the page number and the column heads
    css = f"""@page {{ size: A4; margin: 12mm 12mm 14mm;
  @top-left {{ content: "{running}"; font: 9px sans-serif; color: #555; }}
  @bottom-center {{ content: "page " counter(page) " of " counter(pages); font: 9px sans-serif; }} }}
thead {{ display: table-header-group; }}
tr {{ break-inside: avoid; }}
tr.title th {{ text-align: left; font-size: 12px; background: #eee; }}
th.cam {{ width: 26mm; }}
body {{ font-family: sans-serif; font-size: 11px; color: #111; }}
h1 {{ font-size: 20px; margin: 0 0 6px; }}
h2 {{ font-size: 15px; margin: 0 0 4px; }}
.head {{ display: flex; gap: 18px; align-items: flex-start; }}
.fields th {{ text-align: left; padding: 6px 8px 6px 0; white-space: nowrap; }}
.fields td {{ border-bottom: 1px solid #000; min-width: 220px; padding: 6px 4px; }}
table {{ border-collapse: collapse; width: 100%; }}
section table td, section table th {{ border: 1px solid #999; padding: 2px 4px; }}
section {{ break-before: page; }}
tr.quiet td {{ font-style: italic; color: #555; background: #f6f6f6; }}
td:last-child {{ text-align: center; font-size: 14px; }}
code {{ font-size: 9.5px; }}
.sign {{ border: 2px solid #1f5fbf; padding: 6px 8px; }}
.signpic {{ margin: 0; width: 360px; }}
.signpic figcaption {{ font-size: 10px; color: #555; }}
section td:nth-child(5), section td:nth-child(6) {{ white-space: nowrap; }}
"""
    body = f"""<h1>Capture sheet</h1>
<div class="head"><div>
<table class="fields">{fields}</table>
<p>Arm radius r = {rig.arm_radius_m:g} m, g = {rig.gravity_m_per_s2:g} m/s², step mass
{step * 1000:g} g per pan = {per_step:.5f} N·m per step (τ = 2·m·g·r). Maximum torque
{plan.max_torque_nm:.5f} N·m = {n} steps{snapped}. {len(plan.rows)} photographs in
{len(cfg.protocol.orientations_deg)} orientation(s), {cfg.protocol.cycles} cycle(s) each.</p>
{f"<p>{esc(plan.lost_motion_text())}</p>" if getattr(plan, "rated_torque_nm", None) is not None else ""}
<p class="sign">{words}</p>
<p>Masses are per pan: both pans of a pair always carry the same mass. Wait for the disk to
settle before each photograph. Save each under the name given, or keep the camera's own
names and run <code>vision-torsion bind</code> (or <code>watch</code> during the test).</p>
</div><figure class="signpic">{sign_picture_svg(cfg.angle_sign)}<figcaption>As seen in the camera
image. Grey: the markers at zero torque; black: after a positive torque. One pan of each pair
is drawn.</figcaption></figure></div>
{"".join(sections)}
"""
    return page_html("Capture sheet", [body], css=css, main=False)


def find_chromium() -> str | None:
    """Path of a Chromium or Chrome executable, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        path = shutil.which(name)
        if path:
            return path
    return None


def write_capture_sheet(plan, *, pdf: bool = True, timeout_s: float = 60.0) -> tuple[Path, Path | None]:
    """Write ``capture_sheet.html`` into the plan's folder, and the PDF when a
    headless Chromium is available; returns (html path, pdf path or None).

    A failing or missing converter is logged, never an error: the HTML is the sheet.
    """
    page = atomic_write_text(plan.folder / CAPTURE_SHEET_HTML, capture_sheet_html(plan))
    exe = find_chromium() if pdf else None
    if exe is None:
        if pdf:
            logger.info("no Chromium found: wrote %s only (print it from a browser)", page)
        return page, None
    target = plan.folder / CAPTURE_SHEET_PDF
    with tempfile.TemporaryDirectory() as profile:
        tmp_pdf = Path(profile) / "sheet.pdf"
        cmd = [
            exe,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            f"--user-data-dir={profile}",
            "--no-pdf-header-footer",
            f"--print-to-pdf={tmp_pdf}",
            page.resolve().as_uri(),
        ]
        try:
            subprocess.run(cmd, capture_output=True, timeout=timeout_s, check=True)
            data = tmp_pdf.read_bytes()
        except (OSError, subprocess.SubprocessError) as exc:
            logger.warning("capture sheet PDF not written (%s); print %s from a browser", exc, page)
            return page, None
    from ..fileio import atomic_write_bytes

    return page, atomic_write_bytes(target, data)
