"""The stiffness section of a camera-rig session report.

A session's ``measurements.csv`` holds a few load steps per phase; this turns them
into the stiffness curve of the loading phases, when there are enough steps.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import AnalysisError
from .analysis import StiffnessResult, analyze_stiffness_curve, as_record
from .branches import LOADING_KINDS
from .plots import plot_meshing, plot_stiffness, plot_torque_angle
from .rig import RigConstants

__all__ = ["StiffnessSection", "stiffness_section"]


@dataclass(frozen=True)
class StiffnessSection:
    """Stiffness result, figures and a markdown summary for a session report.

    Attributes
    ----------
    result : StiffnessResult
    figures : dict of str to matplotlib.figure.Figure
        ``torque_angle``, ``stiffness`` and (with Ks) ``meshing_pairs``.
    markdown : str
        A short summary paragraph.
    """

    result: StiffnessResult
    figures: dict = field(repr=False)
    markdown: str


def _summary(result: StiffnessResult) -> str:
    lines = ["## Stiffness curve", ""]
    for c in result.curves:
        lines.append(f"- {c.kind}: K from {c.stiffness_nm_per_rad.min():.4g} to "
                     f"{c.stiffness_nm_per_rad.max():.4g} N·m/rad over "
                     f"{c.torque_nm[0]:.3g} to {c.torque_nm[-1]:.3g} N·m")
    if result.backlash is not None:
        b = result.backlash
        lines.append(f"- dead zone: {b.width_deg:.4g}° ± {b.width_std_deg:.2g}° wide, "
                     f"centred at {b.centre_deg:.4g}°")
    if result.meshing is not None:
        lines.append(f"- effective meshing pairs: max {result.meshing.max_pairs:.1f} at "
                     f"{result.meshing.torque_at_max_nm:.3g} N·m")
    lines.extend(f"- note: {n}" for n in result.notes)
    return "\n".join(lines) + "\n"


def stiffness_section(measurements, *, rig: RigConstants | None = None, order: int = 3,
                      method: str = "polynomial") -> StiffnessSection:
    """Stiffness section for a session report from its measurements table.

    Parameters
    ----------
    measurements : pandas.DataFrame or str or Path
        The session's ``measurements.csv`` (camera rig).
    rig : RigConstants, optional
        Ks (or a reference point) and z for the meshing figures.
    order : int
        Polynomial order of the loading-branch fits (a session has few steps).
    method : {"polynomial", "spline"}

    Returns
    -------
    StiffnessSection

    Raises
    ------
    AnalysisError
        A loading phase has fewer usable steps (``status == "ok"``, non-zero
        torque) than the fit needs (order + 3), naming the phase and the count.
    RecordError
        The table is invalid.

    Examples
    --------
    >>> from vision_torsion.stiffness.synthetic import synthetic_measurements
    >>> section = stiffness_section(synthetic_measurements(steps=10))
    >>> sorted(section.figures)
    ['stiffness', 'torque_angle']
    >>> stiffness_section(synthetic_measurements(steps=4))
    Traceback (most recent call last):
    ...
    vision_torsion.errors.AnalysisError: the session has 4 usable positive_loading steps (status ok, torque not zero); the stiffness section needs at least 6 per loading phase (polynomial order 3 + 3)
    """
    record = as_record(measurements)
    needed = order + 3
    for kind in LOADING_KINDS:
        usable = int(np.sum((record.phase == kind) & (record.torque_nm != 0)))
        if usable < needed:
            raise AnalysisError(
                f"the session has {usable} usable {kind} steps (status ok, torque not zero); "
                f"the stiffness section needs at least {needed} per loading phase "
                f"(polynomial order {order} + 3)"
            )
    result = analyze_stiffness_curve(record, rig=rig, order=order, method=method)
    figures = {"torque_angle": plot_torque_angle(result), "stiffness": plot_stiffness(result)}
    if result.meshing is not None:
        figures["meshing_pairs"] = plot_meshing(result)
    return StiffnessSection(result=result, figures=figures, markdown=_summary(result))
