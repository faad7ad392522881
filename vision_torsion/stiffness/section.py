"""The stiffness section of a camera-rig session report.

A session's ``measurements.csv`` holds a few load steps per phase and one loop per
orientation and cycle, each against its own reference image (its own zero offset).
The section gives the stiffness of every load step, Δτ/Δθ, within each loop
(:func:`~.steps.step_stiffness`), compared over loops at equal step
(:func:`~.steps.summarise_steps`). Loops are never pooled into one curve, and no
smooth fit is made unless one is asked for (then one per loop, whose failures are
notes, not a failed section). The report layer draws its figures
(:func:`vision_torsion.report.stiffness_figures.section_figures`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

from ..errors import AnalysisError
from ..measurements import read_measurements
from .analysis import StiffnessResult, analyze_stiffness_curve, as_record
from .per_step import step_stiffness, summarise_steps
from .rig import RigConstants

__all__ = ["StiffnessSection", "stiffness_section"]


@dataclass(frozen=True)
class StiffnessSection:
    """Step stiffness, optional per-loop curves and a markdown summary.

    Attributes
    ----------
    steps : pandas.DataFrame
        Every step of every loop (:func:`~.steps.step_stiffness`).
    summary : pandas.DataFrame
        Per phase and step over the loops (:func:`~.steps.summarise_steps`).
    result : StiffnessResult or None
        Per-loop smooth curves, when a fit method was asked for.
    markdown : str
        A short summary.
    """

    steps: pd.DataFrame = field(repr=False)
    summary: pd.DataFrame = field(repr=False)
    result: StiffnessResult | None
    markdown: str


def _summary_text(steps: pd.DataFrame, summary: pd.DataFrame, result) -> str:
    loops = steps[["orientation_deg", "cycle"]].drop_duplicates()
    lines = ["## Stiffness per load step", "",
             f"- {len(steps)} steps in {len(loops)} loop(s); each loop on its own (own zero offset)"]
    for phase, part in summary.groupby("phase", sort=False):
        ok = part[part["n_loops"] > 0]
        if len(ok):
            lines.append(f"- {phase.replace('_', ' ')}: Δτ/Δθ from {ok['stiffness_nm_per_rad'].min():.4g} to "
                         f"{ok['stiffness_nm_per_rad'].max():.4g} N·m/rad")
    flagged = int((steps["flag"] != "").sum())
    if flagged:
        lines.append(f"- {flagged} step(s) flagged and left out of the means (reason per step in the table)")
    if result is not None:
        for c in result.curves:
            lines.append(f"- smooth fit, {c.kind}: K from {c.stiffness_nm_per_rad.min():.4g} to "
                         f"{c.stiffness_nm_per_rad.max():.4g} N·m/rad, mean of {c.n_cycles} loop(s)")
        lines.extend(f"- note: {n}" for n in result.notes)
    return "\n".join(lines) + "\n"


def stiffness_section(measurements, *, rig: RigConstants | None = None, order: int = 3,
                      method: str | None = None) -> StiffnessSection:
    """Stiffness section for a session report from its measurements table.

    Parameters
    ----------
    measurements : pandas.DataFrame or str or Path
        The session's ``measurements.csv`` (camera rig).
    rig : RigConstants, optional
        Ks (or a reference point) and z for the meshing figures of a smooth fit.
    order : int
        Polynomial order of a smooth fit (``method="polynomial"``).
    method : {None, "polynomial", "spline"}
        None (default): step stiffness only. Otherwise also a smooth fit per loop.

    Returns
    -------
    StiffnessSection

    Raises
    ------
    RecordError
        The table is invalid.
    AnalysisError
        No pair of consecutive measured steps in any phase; or, with a fit, no
        loop's loading branch could be fitted (each loop's reason given).

    Examples
    --------
    >>> from vision_torsion.synthetic.encoder import synthetic_measurements
    >>> section = stiffness_section(synthetic_measurements(steps=10))
    >>> section.result is None, len(section.steps)
    (True, 40)
    """
    frame = read_measurements(measurements, columns=("orientation_deg", "cycle", "phase", "step",
                                                     "torque_nm", "angle_deg", "status"))
    steps = step_stiffness(frame)
    if steps.empty:
        raise AnalysisError("no two consecutive load steps of one phase were measured: "
                            "no step stiffness can be computed")
    summary = summarise_steps(steps)
    result = None
    if method is not None:
        result = analyze_stiffness_curve(as_record(frame), rig=rig, order=order, method=method)
    return StiffnessSection(steps=steps, summary=summary, result=result,
                            markdown=_summary_text(steps, summary, result))
