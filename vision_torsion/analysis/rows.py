"""The figure rows of one loop and the issues that go with them: what every figure family returns.

A figure family (:mod:`.phase_figures`, :mod:`.loop_figures`, :mod:`.catalogue_figures`,
:mod:`.model_figures`) adds its figures of one loop to a :class:`FigureRows` — a value
with its uncertainty parts, its flag, the coverage factor of its ``u95`` — or fails
them with the reason; :mod:`.session_analysis` joins the families' rows into
:data:`FIGURE_COLUMNS` and their issues into one list.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special  # stdtrit is scipy.stats.t.ppf, without importing scipy.stats

from .loops import Loop
from .uncertainty import COVERAGE_FACTOR

__all__ = ["ISSUE_KINDS", "Issue", "FIGURE_COLUMNS", "SOURCE_KINDS", "TORQUE_NOT_MODELLED", "CREEP_FLAG",
           "LEVEL_TOL_NM", "FigureRows", "coverage_factor"]

#: Torque levels closer than this (N·m) are the same level.
LEVEL_TOL_NM = 1e-9

#: Kinds of torque-error source (:func:`.uncertainty.torque_sources`) kept apart in the budget.
SOURCE_KINDS = ("weights", "g_r", "friction", "level")
#: Columns of :attr:`SessionAnalysis.figures`.
FIGURE_COLUMNS = [
    "orientation_deg",
    "cycle",
    "figure",
    "unit",
    "value",
    "std",
    "std_angle",
    "std_torque",
    "u95",
    "method",
    "flag",
    *[f"std_{k}" for k in SOURCE_KINDS],
    "std_lack_of_fit",
    "std_sampling",
    "reduced_chi2",
    "coverage_factor",
]


#: The flag of every figure of a table analysed without its torque-error model (``torque_model_declared=False``).
TORQUE_NOT_MODELLED = (
    "torque uncertainty not modelled: no rig (weight-piece tolerance, pieces per step, g, r) was given, so each "
    "torque level's error was taken as its own and the pieces' accumulation step by step is missing from u95"
)


def coverage_factor(std: float, parts_dof) -> float:
    """``k`` of ``u95 = k·std``: 2, or Student's ``t_0.975`` at the Welch–Satterthwaite ν when larger.

    ``parts_dof`` lists ``(std_i, ν_i)`` of the independently estimated parts (a Monte
    Carlo std from D draws has ν = D − 1); ``ν_eff = std⁴ / Σ std_i⁴/ν_i``.
    """
    den = sum(u**4 / nu for u, nu in parts_dof if np.isfinite(u) and u > 0 and nu and np.isfinite(nu))
    if not (np.isfinite(std) and std > 0 and den > 0):
        return COVERAGE_FACTOR
    return max(COVERAGE_FACTOR, float(special.stdtrit(std**4 / den, 0.975)))


#: The flag of every figure of an orientation with a creep/closure finding.
CREEP_FLAG = "flagged: creep or drift in this orientation (see checks)"


#: What an :class:`Issue` tells the reader (see there).
ISSUE_KINDS = ("rejected", "not_applicable", "not_computable", "flagged")


@dataclass(frozen=True)
class Issue:
    """A figure that is withheld or flagged for an orientation/cycle, and why.

    ``orientation_deg``/``cycle`` are None for session-wide issues; ``figure`` is a
    figure name or ``"*"`` for all figures of that loop. ``kind`` (one of
    :data:`ISSUE_KINDS`) says what a reader is told: ``"rejected"`` — computable, but
    withheld because it does not fit its data (and given another way, e.g. a switching
    phase as its stiffness below and above the switch and its secant);
    ``"not_applicable"`` — the data call for another form (K3/T2 when one break
    describes the curve: two segments); ``"flagged"`` — shown with a flag;
    ``"not_computable"`` — the data cannot give it (missing phase, gap, failed fit).
    """

    orientation_deg: float | None
    cycle: int | None
    figure: str
    reason: str
    kind: str = "not_computable"

    def __str__(self) -> str:
        where = (
            "session" if self.orientation_deg is None else f"orientation {self.orientation_deg:g}°, cycle {self.cycle}"
        )
        return f"{where}: {self.figure}: {self.reason}"


class FigureRows:
    """The figure rows (:data:`FIGURE_COLUMNS`) and the issues of one loop, as a figure family adds them.

    ``rows`` are dicts in the order added; ``issues`` are the :class:`Issue` of a flagged or failed figure
    (and any other a family appends), in the order they arose.
    """

    def __init__(self, loop: Loop):
        self.loop, self.issues, self.rows = loop, [], []

    def add(
        self,
        figure,
        unit,
        value,
        std_angle=np.nan,
        std_torque=np.nan,
        method="",
        *,
        parts=None,
        check=None,
        flag="",
        draws=None,
        sampling=0.0,
        interval=np.nan,
    ):
        """One figure; ``check`` (a rejected :class:`.fitcheck.LackOfFit`) flags it and inflates its u.

        ``draws``: the angle part and each torque part were estimated from this many
        Monte Carlo draws (their ν = draws − 1 sets the coverage factor).
        ``sampling``: half-width of the bound on the sampling of the continuous loop by
        the measured levels (:mod:`.loop_figures`): its 1σ (``half/√3``,
        rectangular) is in ``std``, and ``u95`` is at least ``k·std_rest + half`` (a
        bias known only to lie within the bound is added linearly to the rest's
        interval: on a kinked loop the truth sits at the bound's edge).
        ``interval``: half-width of the figure's 95 % interval read from the draws of
        its own distribution (a bootstrap's, :func:`.catalogue.break_bootstrap`):
        ``u95`` is at least it (times any inflation), where that distribution has
        heavier tails than the normal one ``k·std`` assumes; ``coverage_factor`` is
        then ``u95/std``.
        """
        infl, red = 1.0, np.nan
        if check is not None and check.testable:
            red = check.reduced_chi2
            if check.rejected:
                infl = check.inflation
                flag = "; ".join(
                    x for x in (flag, f"flagged, uncertainty ×{infl:.3g} (√χ²_red): {check.describe()}") if x
                )
        std0 = float(np.hypot(std_angle, std_torque))
        std_rest = std0 * infl
        std = float(np.hypot(std_rest, sampling / math.sqrt(3.0)))
        row = {
            "orientation_deg": self.loop.orientation_deg,
            "cycle": self.loop.cycle,
            "figure": figure,
            "unit": unit,
            "value": float(value),
            "std": std,
            "std_angle": float(std_angle) * infl,
            "std_torque": float(std_torque) * infl,
            "u95": COVERAGE_FACTOR * std,
            "method": method,
            "flag": flag,
            "std_lack_of_fit": std0 * math.sqrt(max(infl**2 - 1.0, 0.0)) if np.isfinite(std0) else np.nan,
            "std_sampling": float(sampling) / math.sqrt(3.0),
            "reduced_chi2": red,
            "coverage_factor": COVERAGE_FACTOR,
        }
        if draws:
            k = coverage_factor(std0, [(std_angle, draws - 1)] + [(u, draws - 1) for u in (parts or {}).values()])
            row.update(coverage_factor=k, u95=k * std)
        if infl > 1.0 and check.dof > 0:
            # u·√χ²_red: the noise scale is estimated from the residuals, with the test's dof (a Type A
            # estimate): Student's t at that dof (GUM G.3), never below 2
            k = max(COVERAGE_FACTOR, float(special.stdtrit(check.dof, 0.975)))
            row.update(coverage_factor=k, u95=k * std)
        if sampling > 0 and np.isfinite(std) and std > 0:
            u95 = max(row["u95"], row["coverage_factor"] * std_rest + sampling)
            row.update(u95=u95, coverage_factor=u95 / std)
        if np.isfinite(interval) and interval * infl > row["u95"] and np.isfinite(std) and std > 0:
            row.update(u95=interval * infl, coverage_factor=interval * infl / std)
        for k in SOURCE_KINDS:
            row[f"std_{k}"] = float((parts or {}).get(k, 0.0 if parts is not None else np.nan))
        self.rows.append(row)
        if flag:
            self.issues.append(Issue(self.loop.orientation_deg, self.loop.cycle, figure, flag, kind="flagged"))

    def set_torque_part(self, figure, std_torque, parts, method, draws):
        """Replace the torque part of an unflagged figure already added (a better propagation of it).

        The torque parts come from ``draws`` Monte Carlo draws (ν = draws − 1 each).
        """
        for row in self.rows:
            if row["figure"] == figure and np.isfinite(row["value"]) and not row["flag"]:
                row["std_torque"] = float(std_torque)
                row["std"] = float(np.hypot(row["std_angle"], std_torque))
                k = coverage_factor(row["std"], [(u, draws - 1) for u in parts.values()])
                row["coverage_factor"] = k
                row["u95"] = k * row["std"]
                row["method"] = method
                for kind in SOURCE_KINDS:
                    row[f"std_{kind}"] = float(parts.get(kind, 0.0))

    def fail(self, figure, unit, reason, *, kind="not_computable"):
        self.add(figure, unit, np.nan)
        self.issues.append(Issue(self.loop.orientation_deg, self.loop.cycle, figure, reason, kind=kind))
