"""From a session folder to a report: ``vision-torsion report`` and ``vision-torsion demo``.

``report_session`` processes the session first (only what is new or changed: the
session cache makes a re-run cheap), analyses ``measurements.csv`` and writes the
report next to it. ``run_demo`` renders the paper-like synthetic session (the scene
of ``synthetic/paper_session.toml``), then does the same.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from ..errors import OutputError
from ..fileio import atomic_write_text, check_replaceable, is_ours, write_csv
from ..measurements import output_folder
from ..targets import Target, load_target
from . import ReportFiles

__all__ = ["SessionReport", "report_session", "run_demo", "demo_scene"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SessionReport:
    """Where the report went and how processing went.

    Attributes
    ----------
    files : ReportFiles
        Paths of report.html, summary.json, stiffness_table.csv and the figures.
    measurements_path : pathlib.Path
        The measurements.csv the report was made from.
    n_images, n_failed : int
        Images in the manifest, and images that could not be measured.
    n_issues : int
        Figures the analysis could not compute (each with its reason in the report).
    n_pending : int
        Rows not photographed yet (a partly shot session); they are listed in the
        report and left out of the analysis.
    unlisted : tuple of str
        Image files no manifest row names.
    withheld_by_kind : dict
        Withheld figures by kind (:func:`~vision_torsion.report.analyze.withheld_by_kind`).
    angle_sign_advice : str
        Non-empty when the angle sign looks inverted: what to set.
    verdicts : tuple of Verdict or None
        The conformity verdicts against session.toml's ``[spec]`` (None without one).
    """

    files: ReportFiles
    measurements_path: Path
    n_images: int
    n_failed: int
    n_issues: int
    n_pending: int = 0
    unlisted: tuple = ()
    withheld_by_kind: dict = field(default_factory=dict)
    angle_sign_advice: str = ""
    verdicts: tuple | None = None


def _g6(x: float) -> float:
    """Six significant digits: 0.019620000000000002 is 0.01962 in a report."""
    return float(f"{x:.6g}")


def _conditions(session, n_images: int, n_failed: int) -> dict:
    rig, proto = session.config.rig, session.config.protocol
    return {
        "session folder": str(session.folder),
        "arm radius r (m)": rig.arm_radius_m,
        "gravity g (m/s²)": rig.gravity_m_per_s2,
        "mass per weight piece (kg)": rig.step_mass_kg,
        "mass standard uncertainty per piece (kg)": _g6(rig.mass_std_kg),
        "pulley friction torque std (N·m)": rig.friction_torque_std_nm,
        "torque per step, 2·m·g·r (N·m)": _g6(rig.step_torque_nm),
        "maximum torque (N·m)": _g6(proto.max_torque_nm),
        "flexspline orientations (deg)": list(proto.orientations_deg),
        "cycles per orientation": proto.cycles,
        "angle sign": session.config.angle_sign,
        "marker polarity": session.config.markers.polarity,
        "marker fit": session.config.markers.fit,
        "images": n_images,
        "images failed": n_failed,
    }


_STIFFNESS_TITLE = "Stiffness per load step (Δτ/Δθ, each loop on its own)"


def _step_table(summary: pd.DataFrame) -> pd.DataFrame:
    """One row per step of the loop, one column per phase: mean Δτ/Δθ ± u over loops."""
    from .html import fmt_value

    phases = list(dict.fromkeys(summary["phase"]))
    rows = {}
    for r in summary.itertuples(index=False):
        key = (int(r.step_from), int(r.step_to))
        row = rows.setdefault(key, {"step": f"{r.step_from}→{r.step_to}"})
        if r.n_loops:
            row[r.phase.replace("_", " ")] = (
                f"{fmt_value(r.stiffness_nm_per_rad, r.stiffness_std_nm_per_rad)} @ {r.torque_mid_nm:+.3g}"
            )
        else:
            row[r.phase.replace("_", " ")] = "flagged*"
    columns = ["step"] + [p.replace("_", " ") for p in phases]
    return pd.DataFrame([rows[k] for k in sorted(rows)], columns=columns).fillna("—")


def _stiffness_section(measurements: pd.DataFrame):
    """The stiffness section (Δτ/Δθ per load step, per loop) as (title, html).

    When the session cannot give it (no two consecutive steps measured), the
    section says why instead of failing the report.
    """
    import html

    from ..errors import VisionTorsionError
    from ..htmlpage import image_tag as _img
    from ..htmlpage import table_html as _table
    from ..stiffness.section import stiffness_section
    from .figures import svg_bytes
    from .stiffness_figures import section_figures

    try:
        section = stiffness_section(measurements)
    except VisionTorsionError as exc:
        return _STIFFNESS_TITLE, f"<p>Not computed: {html.escape(str(exc))}.</p>"
    lines = [ln[2:] for ln in section.markdown.splitlines() if ln.startswith("- ")]
    parts = [
        "<ul>" + "".join(f"<li>{html.escape(ln)}</li>" for ln in lines) + "</ul>",
        '<p class="muted">Each cell: mean over loops of Δτ/Δθ (N·m/rad) ± its standard uncertainty '
        "(scatter between loops, Type A, combined with the propagated angle and torque uncertainty), "
        "@ the mid-step torque (N·m). *flagged: the step starts or ends at zero torque (it may cross the "
        "backlash dead zone) or its angle change is not measurable; per-loop values and reasons are in "
        "<code>stiffness_steps.csv</code>.</p>",
        _table(_step_table(section.summary), left=("step",)),
    ]
    for name, fig in section_figures(section).items():
        parts.append(f"<figure>{_img(svg_bytes(fig), name.replace('_', ' '))}</figure>")
    return _STIFFNESS_TITLE, "\n".join(parts), section.steps


def _overlay_section(session):
    """Each orientation's reference image with its detected markers drawn (issue 15)."""
    from ..overlay import overlay_section

    rows = session.manifest.rows
    refs = {}
    for row in rows:  # the reference row, else the first row, as process measures against
        if row.phase == "reference":
            refs[row.orientation_deg] = row
        else:
            refs.setdefault(row.orientation_deg, row)
    images = [(f"orientation {o:g}°: {r.image}", session.manifest.image_path(r)) for o, r in refs.items()
              if r.line not in set(session.manifest.pending)]
    return overlay_section(images, settings=session.settings)


def _pending_section(waiting: pd.DataFrame, unlisted) -> tuple[str, str]:
    """A partly shot session: the rows still to photograph, and stray files."""
    import html

    parts = []
    if len(waiting):
        parts.append(
            f"<p>{len(waiting)} planned image(s) are not photographed yet; the "
            "figures above use the images that exist.</p><table><tr><th>image</th>"
            "<th>orientation (°)</th><th>cycle</th><th>phase</th><th>step</th><th>why</th></tr>"
        )
        for r in waiting.itertuples():
            parts.append(
                "<tr>"
                + "".join(
                    f"<td>{html.escape(str(v))}</td>"
                    for v in (r.image, r.orientation_deg, r.cycle, r.phase, r.step, r.message)
                )
                + "</tr>"
            )
        parts.append("</table>")
    if unlisted:
        parts.append(
            "<p>Image files that no manifest row names (not analysed):</p><ul>"
            + "".join(f"<li>{html.escape(n)}</li>" for n in unlisted)
            + "</ul>"
        )
    return "Pending images", "\n".join(parts)


def report_session(session_dir, *, out_dir=None, jobs: int | None = None, progress: bool = False) -> SessionReport:
    """Process a session (if needed), analyse it and write the report.

    Parameters
    ----------
    session_dir : str or os.PathLike
        The session folder (session.toml, manifest.csv, images).
    out_dir : str or os.PathLike, optional
        Output folder; ``SESSION_DIR/results`` by default. It receives
        measurements.csv, summary.json, stiffness_table.csv, figures/ and report.html.
    jobs : int, optional
        Images measured at once (all cores by default; see
        :func:`~vision_torsion.session.process_session`).
    progress : bool
        Show progress bars.

    Returns
    -------
    SessionReport

    Raises
    ------
    SessionError, ManifestError
        The session folder is invalid (every problem listed).
    """
    from ..measurements import read_measurements
    from ..session import load_session, process_session
    from .analyze import analyze_table

    session = load_session(session_dir, missing="pending")
    out = output_folder(session.folder, out_dir)
    # before measuring: another program's result file in the way is refused now (figures when written)
    check_replaceable(out / name for name in ("stiffness_steps.csv", "summary.json", "stiffness_table.csv",
                                              "report.html"))
    result = process_session(session.folder, out_dir=out, jobs=jobs, progress=progress)
    measurements = read_measurements(result.measurements_path)  # indexed by CSV line
    waiting = measurements[measurements["status"] == "pending"]
    measurements = measurements[measurements["status"] != "pending"]
    logger.info("analysing %d measurements", len(measurements))
    title, section_html, *steps = _stiffness_section(measurements)
    extra = [(title, section_html), _overlay_section(session)]
    if len(waiting) or result.unlisted:
        extra.append(_pending_section(waiting, result.unlisted))
    from ..fileio import output_set

    with output_set():  # the report's files are replaced together or not at all
        if steps:
            write_csv(out / "stiffness_steps.csv", steps[0])
        # the same path as `vision-torsion analyze`: the table, the session's settings, the report
        res = analyze_table(measurements, session=session.config, out_dir=out,
                            conditions=_conditions(session, result.n_images, result.n_failed), extra_sections=extra)
    files, analysis = res.files, res.analysis
    return SessionReport(
        files=files,
        measurements_path=result.measurements_path,
        n_images=result.n_images,
        n_failed=result.n_failed,
        n_issues=len(analysis.issues),
        n_pending=len(waiting),
        unlisted=result.unlisted,
        withheld_by_kind=res.withheld_by_kind,
        angle_sign_advice=res.angle_sign_advice,
        verdicts=res.verdicts,
    )


def demo_scene():
    """The demo's scene and session: the paper-like session of ``synthetic/paper_session.toml``.

    Built in code so the demo needs no file from the source tree; a test checks it
    equals the TOML file.
    """
    from ..synthetic import Scene
    from ..synthetic.scene import DiskSpec, MarkerSpec
    from ..synthetic.session import SessionSpec

    scene = Scene(
        disk=DiskSpec(center_x=700.37, center_y=500.61, background_level=200.0),
        markers=MarkerSpec(polarity="dark", level=40.0, radius_px=35.0, distance_px=300.0, positions_deg=(10.0, 190.0)),
        name="paper_session",
    )
    return scene, SessionSpec(orientation_variation=0.03, angle_sign=-1)


def run_demo(
    out_dir="vision-torsion-demo", *, seed: int = 0, jobs: int | None = None, progress: bool = False,
    force: bool = False, target=None,
) -> SessionReport:
    """Render the paper-like synthetic session, process it and write its report.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Folder for the demo: the session goes to ``OUT_DIR/session``, the results
        and report to ``OUT_DIR/session/results``. A session already rendered there
        with the same seed is reused (and only re-measured where needed); one
        rendered with another seed, or interrupted, is rendered again.
    seed : int
        Seed of the synthetic session.
    jobs : int, optional
        Images measured at once (see :func:`~vision_torsion.session.process_session`).
    progress : bool
        Show progress bars.
    force : bool
        Render the session again even when one with the same seed is there, and
        write into a folder this tool did not make a demo in.
    target : Target, str or os.PathLike, optional
        An N-marker target (a ready target's name such as ``"ring16"``, a target
        file) in place of the two markers
        (:func:`~vision_torsion.synthetic.session.write_session_folder`); a session
        rendered with another target, or none, is rendered again.

    Returns
    -------
    SessionReport

    Raises
    ------
    OutputError
        ``reason="not_ours"``: `out_dir` exists, is not empty, and holds no demo
        record of this tool's own (:data:`DEMO_STAMP`, proven by the folder's record,
        :mod:`vision_torsion.fileio`), and `force` is false. Nothing is written.
    TargetError
        `target` cannot be read.
    """
    from ..synthetic.session import write_session_folder

    session_dir = Path(out_dir) / "session"
    stamp = Path(out_dir) / DEMO_STAMP
    if not force and Path(out_dir).is_dir() and any(Path(out_dir).iterdir()) and not is_ours(stamp):
        raise OutputError(f"{out_dir}: folder exists and is not empty, and vision-torsion did not write a "
                          f"demo there (no {DEMO_STAMP} of its own); choose a new folder, or give --force "
                          "to write the demo into it (files of the same names are replaced)",
                          reason="not_ours")
    wanted = {"seed": seed}
    if target is not None:  # the layout itself, so another target of the same name is rendered anew
        target = load_target(target) if not isinstance(target, Target) else target
        wanted = json.loads(json.dumps({"seed": seed, "target": {"name": target.name, **dict(target.spec)}}))
    rendered = _demo_record(stamp) if (session_dir / "truth.csv").is_file() else None
    # truth.csv is written last: without it an earlier demo was interrupted
    if force or rendered != wanted:
        if rendered is not None and not force:
            logger.info("%s: rendered as %s; rendering it again as %s", session_dir, rendered, wanted)
        scene, spec = demo_scene()
        logger.info("rendering the synthetic session into %s", session_dir)
        write_session_folder(scene, spec, session_dir, seed=seed, progress=progress, overwrite=True,
                             header=DEMO_HEADER | {"serial": f"DEMO-{seed}", "date": _today()},
                             catalogue=DEMO_CATALOGUE, target=target)
        atomic_write_text(stamp, json.dumps(wanted) + "\n")
    else:
        logger.info("%s: reusing the session rendered earlier with seed %d (--force renders it again)",
                    session_dir, seed)
    return report_session(session_dir, jobs=jobs, progress=progress)


#: The demo folder's record of the seed its session was rendered with.
DEMO_STAMP = "demo.json"
#: The demo gear's identity (its serial is the seed, its date the day it is rendered)
#: and its type's catalogue (package data: T1/T2 and the limits of the verdict).
DEMO_HEADER = {"gear": "paper-demo-gear (synthetic)", "operator": "vision-torsion demo"}
DEMO_CATALOGUE = "paper_demo"


def _today() -> str:
    import datetime

    return datetime.date.today().isoformat()


def _demo_record(stamp: Path) -> dict | None:
    """What a demo folder's stamp records its session was rendered with (the seed,
    and the N-marker target if any), or None (no stamp, unreadable: the session is
    rendered again)."""
    try:
        record = json.loads(stamp.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) else None
