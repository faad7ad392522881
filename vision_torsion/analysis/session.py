"""``analyze_session``: every figure of every loop of a session, with uncertainties,
summaries, checks on the data, and a list of what could not be computed and why.

Figures (``figure`` name → unit; see :mod:`.metrics`, :mod:`.models`,
:mod:`.preisach`, :mod:`.catalogue` for the definitions), and what happens when a
check fails:

=====================================  ============  =============  ===============================
figure                                 unit          uncertainty    when its check fails
=====================================  ============  =============  ===============================
k_<phase> (straight line)              nm_per_rad    first order    lack of fit: **withheld**
k_<phase>_below / _above, switch_nm    nm_per_rad/nm first order    lack of fit: **withheld**
k_<phase>_secant (phase ends)          nm_per_rad    first order    phase start/end missing: withheld
hysteresis, hysteresis_loss            deg           Monte Carlo    gap in the levels: **withheld**
                                                                    hysteresis over a flat top: flagged
lost_motion_<x>pct                     deg           Monte Carlo    ±x·T not bracketed: withheld
secant_stiffness                       nm_per_rad    Monte Carlo    ends not bracketed: withheld
loop_energy, loss_factor               j, 1          Monte Carlo    gap in the levels: withheld
k1, k2, k3 (catalogue T1, T2 fixed)    nm_per_rad    first order    lack of fit: **flagged**, u×√χ²_red
k1..k3, t1, t2 (breaks fitted)         various       bootstrap      lack of fit: **flagged**, u×√χ²_red
bilinear_k_u, _k_l, _tau_c             various       first order    lack of fit: **flagged**, u×√χ²_red
preisach_residual_rms                  deg           (fit stat.)    lack of fit: **flagged**
bouc_wen_* (optional)                  various       first order    lack of fit: flagged, u×√χ²_red;
                                                                    a parameter on its bound: flagged
=====================================  ============  =============  ===============================

A straight-line slope is withheld rather than inflated because it has no meaning
when the stiffness switches inside the phase; the phase is then described by its two
stiffnesses (below/above the switch) and its secant, which sit beside it. Model
parameters keep a meaning when a model is only approximately right, so they are
shown, flagged, with the uncertainty multiplied by ``√χ²_red`` (the lack of fit
becomes part of the uncertainty budget).

Every phase range starts at the phase's **starting image** (the last image of the
phase before: the paper's "0 to −0.36" for negative loading).

Checks on the data (:mod:`.checks`): the angle sign, per orientation and run (an
inverted sign withholds every figure with the advice to set ``angle_sign = -1``; one
orientation whose sign alone is inverted is named and its figures withheld), the
loop's direction (a loop running clockwise, negative area beyond its u95, has its
width and energy figures withheld), gaps (nothing is interpolated across a failed
image), loop closure and creep (the ``closing`` image; every figure of that
orientation is flagged), points far off their loop's model (listed by image, judged
by a fit that does not include them). Each is an :class:`Issue`.

Torque errors follow the weight pieces when the rig is known (``rig=...``,
``torque_correlation="pieces"``), else one shared error per torque level
(``"level"``); pulley friction is a torque opposing the motion; see
:mod:`.uncertainty`.

Expanded uncertainties are ``u95 = k·std`` with ``k = 2``, or Student's ``t_0.975``
at the Welch–Satterthwaite degrees of freedom when a Monte Carlo part rests on few
draws (ν = draws − 1), or at the lack-of-fit test's dof when the uncertainty was
inflated by ``√χ²_red`` (the figures' ``coverage_factor`` column); K1–K3 and T1/T2
with fitted breaks take the bootstrap draws' own 95 % half-width where it is wider
(:func:`.catalogue.break_bootstrap`), and their ``coverage_factor`` is then
``u95/std``. The Monte Carlo of
the loop figures carries each torque error as the data would show it: the torque
axis of the image and, at the loop's tips, the loop's amplitude
(:func:`.uncertainty.tip_amplitude_response`); the phase secants take their torque
part from it. A largest loop width that is a maximum over a flat top is flagged
(:func:`.checks.flat_top`).

A figure that cannot be computed is NaN in the tables and None in JSON, and an
:class:`Issue` says which orientation/cycle and why; it is never replaced by 0.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
import pandas as pd
from scipy import special  # stdtrit is scipy.stats.t.ppf, without importing scipy.stats

from ..errors import AnalysisError
from ..numerics import numeric_jacobian
from ..validate import check_number
from . import checks, metrics
from .catalogue import fit_catalogue_breaks, fit_fixed_breaks
from .fitcheck import (
    LACK_OF_FIT_ALPHA,
    fit_switch,
    lack_of_fit,
    path_compliance,
    secant,
    side_compliance,
    spike_scores,
)
from .loops import LOOP_PHASES, Loop, build_loops, validate_measurements
from .models import BilinearFit, BoucWenFit, fit_bilinear, fit_bouc_wen
from .preisach import fit_preisach, torque_sensitivity
from .summary import summarise_figures
from .uncertainty import (
    COVERAGE_FACTOR,
    check_rig,
    compact_sources,
    least_squares_weights,
    monte_carlo_std,
    std_by_kind,
    tip_amplitude_response,
    torque_sources,
)

__all__ = [
    "ISSUE_KINDS", "Issue", "SessionAnalysis", "analyze_session", "SUMMARY_SCHEMA", "FIGURE_COLUMNS",
    "TORQUE_NOT_MODELLED"]

#: Identifies the layout of :meth:`SessionAnalysis.to_dict` (summary.json).
SUMMARY_SCHEMA = "vision-torsion/analysis-summary/2"

_RAD_TO_ARCMIN = 180.0 * 60.0 / math.pi
_MIN_PHASE_POINTS_FOR_LOOP = 2
_TOL = 1e-9  # N·m: torque levels closer than this are the same level
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


def _coverage_factor(std: float, parts_dof) -> float:
    """``k`` of ``u95 = k·std``: 2, or Student's ``t_0.975`` at the Welch–Satterthwaite ν when larger.

    ``parts_dof`` lists ``(std_i, ν_i)`` of the independently estimated parts (a Monte
    Carlo std from D draws has ν = D − 1); ``ν_eff = std⁴ / Σ std_i⁴/ν_i``.
    """
    den = sum(u**4 / nu for u, nu in parts_dof if np.isfinite(u) and u > 0 and nu and np.isfinite(nu))
    if not (np.isfinite(std) and std > 0 and den > 0):
        return COVERAGE_FACTOR
    return max(COVERAGE_FACTOR, float(special.stdtrit(std**4 / den, 0.975)))


#: The flag of every figure of an orientation with a creep/closure finding.
_CREEP_FLAG = "flagged: creep or drift in this orientation (see checks)"


def _lm_name(fraction: float) -> str:
    return f"lost_motion_{round(100 * fraction, 6):g}pct".replace(".", "p")


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


@dataclass(frozen=True)
class SessionAnalysis:
    """Result of :func:`analyze_session`.

    Attributes
    ----------
    figures : pandas.DataFrame
        Long table, one row per orientation, cycle and figure: ``orientation_deg,
        cycle, figure, unit, value, std, std_angle, std_torque, u95, method``.
    loops : pandas.DataFrame
        Wide table, one row per orientation and cycle: ``<figure>_<unit>`` and
        ``<figure>_std_<unit>`` columns (``loss_factor``, ``loss_factor_std`` unitless).
    phases : pandas.DataFrame
        One row per orientation, cycle, phase: ``torque_from_nm, torque_to_nm,
        n_points, stiffness_nm_per_rad, stiffness_std_nm_per_rad,
        stiffness_nm_per_arcmin, stiffness_std_nm_per_arcmin, residual_rms_deg``.
    summary : dict
        Per figure across loops (:func:`.summary.summarise_figures`).
    per_orientation : pandas.DataFrame
        Per orientation and figure: mean over cycles with its uncertainty.
    issues : list of Issue
    failed_images : pandas.DataFrame
        ``image, orientation_deg, cycle, phase, step, message``.
    settings : dict
    loop_data : list of Loop
        The samples of each loop (for plots).
    fits : dict
        ``{(orientation_deg, cycle): {"bilinear": BilinearFit | None, "bouc_wen": BoucWenFit | None,
        "preisach": PreisachFit | None, "checks": {model: LackOfFit}}}``.
    n_images : int
        Rows of the input table (including reference and failed images).
    checks : dict
        ``angle_sign_inverted`` (bool: the whole session), ``angle_sign_inverted_orientations``
        (orientations whose sign alone is wrong, their figures withheld), ``angle_sign`` (per
        orientation and run, :func:`.checks.angle_sign_by_run`), ``closure`` (list of closure/creep comparisons,
        :func:`.checks.closure_checks`), ``outliers`` (images beyond 4σ of their
        loop's model).
    """

    figures: pd.DataFrame
    loops: pd.DataFrame
    phases: pd.DataFrame
    summary: dict
    per_orientation: pd.DataFrame
    issues: list
    failed_images: pd.DataFrame
    settings: dict
    loop_data: list = field(repr=False)
    fits: dict = field(repr=False)
    n_images: int = 0
    checks: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """JSON-ready dict (the content of summary.json); keys documented in docs/analysis.md.

        Top-level keys: ``schema``, ``settings``, ``counts``, ``uncertainty``,
        ``summary``, ``per_orientation``, ``loops``, ``phases``, ``issues``,
        ``failed_images``. Non-finite numbers are written as null by
        :func:`vision_torsion.fileio.write_json`.
        """
        return {
            "schema": SUMMARY_SCHEMA,
            "settings": dict(self.settings),
            "counts": {
                "images": int(self.n_images),
                "images_failed": int(len(self.failed_images)),
                "loops": int(len(self.loops)),
                "orientations": int(self.loops["orientation_deg"].nunique()) if len(self.loops) else 0,
                "issues": len(self.issues),
            },
            "uncertainty": {
                "coverage_factor": COVERAGE_FACTOR,
                "std": "1-sigma standard uncertainty (angle and torque parts in quadrature)",
                "u95": "expanded uncertainty = coverage_factor * std (per figure: 2, or Student's t at the "
                "Welch-Satterthwaite degrees of freedom when its Monte Carlo had few draws)",
                "torque_correlation": self.settings.get("torque_correlation"),
                "rig": self.settings.get("rig"),
                "monte_carlo_draws": self.settings.get("n_draws"),
                "seed": self.settings.get("seed"),
            },
            "summary": self.summary,
            "per_orientation": _records(self.per_orientation),
            "loops": _loop_records(self.loops, self.figures),
            "phases": _records(self.phases),
            "issues": [asdict(i) for i in self.issues],
            "failed_images": _records(self.failed_images),
            "gear": _jsonable(self.settings.get("test_metadata", {}).get("gear")),
            "test": _jsonable(self.settings.get("test_metadata", {}).get("test")),
            "checks": _jsonable(self.checks),
            "model_checks": [
                {"orientation_deg": o, "cycle": c, "model": m, **chk.to_dict()}
                for (o, c), f in self.fits.items()
                for m, chk in f.get("checks", {}).items()
            ],
        }


def _loop_records(loops: pd.DataFrame, figures: pd.DataFrame) -> list:
    """The wide loop records, each with ``flags`` (figure → why it is flagged, for the flagged ones)
    and ``coverage_factors`` (figure → k of its u95) of its figures."""
    out = _records(loops)
    by_loop = {}
    for r in figures.itertuples(index=False):
        d = by_loop.setdefault((float(r.orientation_deg), int(r.cycle)), ({}, {}))
        if r.flag:
            d[0][r.figure] = r.flag
        if np.isfinite(r.value) and np.isfinite(r.coverage_factor):
            d[1][r.figure] = float(r.coverage_factor)
    for rec in out:
        flags, ks = by_loop.get((float(rec["orientation_deg"]), int(rec["cycle"])), ({}, {}))
        rec["flags"], rec["coverage_factors"] = flags, ks
    return out


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def _records(frame: pd.DataFrame) -> list:
    return [
        {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in r.items()}
        for r in frame.to_dict(orient="records")
    ]


class _Collector:
    """Accumulates figure rows and issues of one loop."""

    def __init__(self, loop: Loop, issues: list):
        self.loop, self.issues, self.rows = loop, issues, []

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
        the measured levels (:func:`_sampling_bounds`): its 1σ (``half/√3``,
        rectangular) is in ``std``, and ``u95`` is at least ``k·std_rest + half`` (a
        bias known only to lie within the bound is added linearly to the rest's
        interval: on a kinked loop the truth sits at the bound's edge).
        ``interval``: half-width of the figure's 95 % interval read from the draws of
        its own distribution (a bootstrap's, :func:`.catalogue.break_bootstrap`):
        ``u95`` is at least it (times any inflation), where that distribution has
        heavier tails than the normal one ``k·std`` assumes.
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
            k = _coverage_factor(std0, [(std_angle, draws - 1)] + [(u, draws - 1) for u in (parts or {}).values()])
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
                k = _coverage_factor(row["std"], [(u, draws - 1) for u in parts.values()])
                row["coverage_factor"] = k
                row["u95"] = k * row["std"]
                row["method"] = method
                for kind in SOURCE_KINDS:
                    row[f"std_{kind}"] = float(parts.get(kind, 0.0))

    def fail(self, figure, unit, reason, *, kind="not_computable"):
        self.add(figure, unit, np.nan)
        self.issues.append(Issue(self.loop.orientation_deg, self.loop.cycle, figure, reason, kind=kind))


def _expected_start_end(phase, tmax, tmin):
    return {
        "positive_unloading": (tmax, 0.0),
        "negative_loading": (0.0, tmin),
        "negative_unloading": (tmin, 0.0),
        "positive_loading": (0.0, tmax),
    }[phase]


_PREVIOUS = {
    "negative_loading": "positive_unloading",
    "negative_unloading": "negative_loading",
    "positive_loading": "negative_unloading",
    "positive_unloading": "positive_loading",
}


def _phase_samples(seq: pd.DataFrame, loop: Loop, phase: str, tmax: float, tmin: float):
    """Indices (into ``seq``) of a phase's samples, its starting image first when it was measured."""
    pos = np.flatnonzero(((seq["cycle"] == loop.cycle) & (seq["phase"] == phase)).to_numpy())
    if pos.size == 0:
        return pos
    start, _ = _expected_start_end(phase, tmax, tmin)
    first = seq.iloc[pos[0]]
    if abs(float(first["torque_nm"]) - start) > _TOL and pos[0] > 0:
        prev = seq.iloc[pos[0] - 1]
        if prev["phase"] == _PREVIOUS[phase] and abs(float(prev["torque_nm"]) - start) <= _TOL:
            pos = np.concatenate([[pos[0] - 1], pos])
    return pos


def _parts_first_order(gt_row_kinds: dict, index: int, scale: float) -> dict:
    return {k: float(v[index]) * scale for k, v in gt_row_kinds.items()}


def _phase_figures(
    col: _Collector,
    phase_rows: list,
    seq: pd.DataFrame,
    rows_local: np.ndarray,
    sources: np.ndarray,
    kinds: np.ndarray,
    levels: np.ndarray,
):
    """Stiffness of each phase: straight line (gated), two stiffnesses if it switches, secant."""
    loop = col.loop
    tau_all = seq["torque_nm"].to_numpy(float)
    tmax, tmin = float(tau_all.max()), float(tau_all.min())
    for phase in LOOP_PHASES:
        name = f"k_{phase}"
        pos = _phase_samples(seq, loop, phase, tmax, tmin)
        tau = tau_all[pos]
        th = np.radians(seq["angle_deg"].to_numpy(float)[pos])
        sa = np.radians(seq["angle_std_deg"].to_numpy(float)[pos])
        st = rows_local[pos]
        src, knd = compact_sources(sources[pos], kinds)
        src_local = src[:, np.asarray(knd) != "g_r"]
        start, end = _expected_start_end(phase, tmax, tmin)
        row = {
            "orientation_deg": loop.orientation_deg,
            "cycle": loop.cycle,
            "phase": phase,
            "torque_from_nm": float(tau[0]) if tau.size else np.nan,
            "torque_to_nm": float(tau[-1]) if tau.size else np.nan,
            "n_points": int(pos.size),
            "stiffness_nm_per_rad": np.nan,
            "stiffness_std_nm_per_rad": np.nan,
            "residual_rms_deg": np.nan,
            "reduced_chi2": np.nan,
            "stiffness_below_nm_per_rad": np.nan,
            "stiffness_above_nm_per_rad": np.nan,
            "switch_torque_nm": np.nan,
            "secant_nm_per_rad": np.nan,
            "secant_std_nm_per_rad": np.nan,
            "note": "",
        }
        if pos.size == 0:
            col.fail(name, "nm_per_rad", f"phase {phase} is missing (no usable image)")
            _finish_phase_row(row, phase_rows)
            continue
        lo, hi = sorted((start, end))
        expected = levels[(levels >= lo - _TOL) & (levels <= hi + _TOL)]
        missing = checks.missing_levels(tau, expected)
        switched = False
        try:
            res = metrics.phase_stiffness(tau, th, angle_std_rad=sa, torque_std_nm=st, torque_sources=src)
        except AnalysisError as exc:
            col.fail(name, "nm_per_rad", f"phase {phase}: {exc}")
            res = None
        if res is not None:
            b = res["compliance_rad_per_nm"]
            chk = lack_of_fit(
                res["residual_rad"],
                angle_std_rad=sa,
                torque_std_nm=st,
                compliance_rad_per_nm=b,
                n_params=2,
                torque_sources=src_local,
                jacobian=np.column_stack([np.ones_like(tau), tau]),
                weights=1.0 / np.maximum(sa**2 + (b * st) ** 2, 1e-300),
            )
            row.update(residual_rms_deg=math.degrees(res["residual_rms_rad"]), reduced_chi2=chk.reduced_chi2)
            if chk.rejected:
                switched = True
                col.fail(
                    name,
                    "nm_per_rad",
                    f"phase {phase}: a straight line does not fit, withheld ({chk.describe()}); "
                    "the phase is given as its stiffness below and above the switch, and its secant",
                    kind="rejected",
                )
                row["note"] = "straight line rejected (lack of fit)"
            else:
                col.add(
                    name,
                    "nm_per_rad",
                    res["value"],
                    res["std_angle"],
                    res["std_torque"],
                    "first-order",
                    parts=_slope_parts(tau, th, sa, st, src, knd, res["value"]),
                    check=chk,
                )
                row.update(
                    stiffness_nm_per_rad=res["value"],
                    stiffness_std_nm_per_rad=math.hypot(res["std_angle"], res["std_torque"]),
                )
        if switched:
            _switch_figures(col, row, phase, tau, th, sa, st, src_local, src)
        _phase_secant(col, row, phase, tau, th, sa, seq["torque_std_nm"].to_numpy(float)[pos], start, end, missing)
        _finish_phase_row(row, phase_rows)


def _slope_parts(tau, th, sa, st, src, knd, k):
    """Torque part of a phase slope by kind of source (first order)."""
    b = 1.0 / k
    x = np.column_stack([np.ones_like(tau), tau])
    w = 1.0 / np.maximum(sa**2 + (b * st) ** 2, 1e-300)
    g = np.linalg.solve(x.T @ (x * w[:, None]), (x * w[:, None]).T)
    gt = g @ (b * src)
    parts = std_by_kind(gt, knd)
    return {kk: float(v[1]) * k * k for kk, v in parts.items()}


def _switch_figures(col, row, phase, tau, th, sa, st, src_local, src):
    names = (f"k_{phase}_below", f"k_{phase}_above", f"switch_{phase}")
    try:
        sw = fit_switch(tau, th, angle_std_rad=sa, torque_std_nm=st, torque_sources=src)
    except AnalysisError as exc:
        for n, u in zip(names, ("nm_per_rad", "nm_per_rad", "nm")):
            col.fail(n, u, f"phase {phase}: {exc}")
        return
    chk = lack_of_fit(
        th - sw["model"],
        angle_std_rad=sa,
        torque_std_nm=st,
        compliance_rad_per_nm=sw["compliance"],
        n_params=sw["n_params"],
        torque_sources=src_local,
        jacobian=sw["design"],
        weights=sw["weights"],
    )
    if chk.rejected:
        for n, u in zip(names, ("nm_per_rad", "nm_per_rad", "nm")):
            col.fail(
                n,
                u,
                f"phase {phase}: two stiffnesses with one switch do not fit either, withheld "
                f"({chk.describe()}); see the secant and the model fits",
                kind="rejected",
            )
        return
    for n, key in zip(names[:2], ("k_below", "k_above")):
        col.add(n, "nm_per_rad", sw[key], sw["std_angle"][key], sw["std_torque"][key], "first-order", check=chk)
    col.add(
        names[2],
        "nm",
        sw["switch_nm"],
        sw["std_angle"]["switch_nm"],
        sw["std_torque"]["switch_nm"],
        "first-order (switch torque from the phase start)",
        check=chk,
    )
    row.update(
        stiffness_below_nm_per_rad=sw["k_below"],
        stiffness_above_nm_per_rad=sw["k_above"],
        switch_torque_nm=sw["switch_nm"],
    )


def _phase_secant(col, row, phase, tau, th, sa, st, start, end, missing):
    name = f"k_{phase}_secant"
    if abs(tau[0] - start) > _TOL or abs(tau[-1] - end) > _TOL:
        which = "starting" if abs(tau[0] - start) > _TOL else "last"
        col.fail(
            name,
            "nm_per_rad",
            f"phase {phase}: its {which} image ({start if which == 'starting' else end:+.4g} "
            "N·m) is missing, so the secant over the phase cannot be formed",
        )
        return
    try:
        k, s_a, s_t = secant(tau, th, angle_std_rad=sa, torque_std_nm=st)
    except AnalysisError as exc:
        col.fail(name, "nm_per_rad", f"phase {phase}: {exc}")
        return
    col.add(name, "nm_per_rad", k, s_a, s_t, "first-order (two ends)")
    row.update(secant_nm_per_rad=k, secant_std_nm_per_rad=math.hypot(s_a, s_t))


def _finish_phase_row(row, phase_rows):
    row["stiffness_nm_per_arcmin"] = row["stiffness_nm_per_rad"] / _RAD_TO_ARCMIN
    row["stiffness_std_nm_per_arcmin"] = row["stiffness_std_nm_per_rad"] / _RAD_TO_ARCMIN
    phase_rows.append(row)


def _loop_problem(loop: Loop) -> str | None:
    """Why the loop-level figures cannot be computed, or None."""
    counts = loop.phase_counts()
    missing = [p for p, n in counts.items() if n == 0]
    if missing:
        return f"phase(s) {', '.join(missing)} missing: the loop is not closed"
    few = [f"{p} ({n})" for p, n in counts.items() if n < _MIN_PHASE_POINTS_FOR_LOOP]
    if few:
        return (
            f"too few usable images in phase(s) {', '.join(few)}: the loop needs at least "
            f"{_MIN_PHASE_POINTS_FOR_LOOP} per phase"
        )
    lo, hi = float(loop.torque_nm.min()), float(loop.torque_nm.max())
    if not (lo < 0 < hi):
        return f"torque never reverses sign in this cycle (range {lo:.4g} to {hi:.4g} N·m): there is no loop"
    return None


def _mc_evaluator(is_desc, top, bottom, settings, tol=_TOL):
    sec_lo, sec_hi = settings["secant_interval_nm"]
    lm_ref = settings["lost_motion_reference_nm"]

    def evaluate(tau, th):
        td, yd, ta, ya = tau[:, is_desc], th[:, is_desc], tau[:, ~is_desc], th[:, ~is_desc]
        hyst, loss = metrics.loop_width(td, yd, ta, ya, tol=tol)
        (xd, fd), (xa, fa) = _branches(td, yd, ta, ya)
        # ∮τ dθ of the continuous loop: the polygon through the samples, less what its chords add to the area
        # between the branches (metrics.chord_area: the descending branch's chords raise it, the ascending's lower)
        energy = metrics.loop_energy(tau, th) - metrics.chord_area(xd, fd)[0] + metrics.chord_area(xa, fa)[0]
        out = {
            "hysteresis": np.degrees(hyst),
            "hysteresis_loss": np.degrees(loss),
            "secant_stiffness": metrics.secant_stiffness(td, yd, ta, ya, lower_nm=sec_lo, upper_nm=sec_hi, tol=tol),
            "loop_energy": energy,
            "loss_factor": metrics.loss_factor(
                energy, tau[:, top].mean(1), th[:, top].mean(1), tau[:, bottom].mean(1), th[:, bottom].mean(1)
            ),
        }
        for f in settings["lost_motion_fractions"]:
            x = f * lm_ref
            lm = metrics.lost_motion(td, yd, ta, ya, torque_nm=x, tol=tol)
            # less the interpolation's own error at ±x (metrics.chord_error), from the branches' curvature
            err = sum(
                sgn * metrics.chord_error(xb, fb, sgn * x)[0] for xb, fb in ((xd, fd), (xa, fa)) for sgn in (1, -1)
            )
            out[_lm_name(f)] = np.degrees(lm - 0.5 * err)
        out.update(
            metrics.phase_secants(td, yd, ta, ya, top_nm=tau[0, top].mean(), bottom_nm=tau[0, bottom].mean(), tol=tol)
        )
        return out

    return evaluate


def _branches(td, yd, ta, ya):
    """The loop's two branches as ``(x, y)`` rows sorted by torque: the descending run, and the ascending run
    from the bottom tip (the descending run's last image, where the ascending branch starts, unless the ascending
    run has its own image there)."""
    gaps = np.diff(np.unique(td[0]))
    if gaps.size and ta[0].min() > td[0].min() + 0.5 * gaps.min():
        ta = np.concatenate([td[:, -1:], ta], axis=1)
        ya = np.concatenate([yd[:, -1:], ya], axis=1)
    xa, fa = ta, ya
    return _sorted_rows(td, yd), _sorted_rows(xa, fa)


def _sorted_rows(x, y):
    o = np.argsort(x, axis=1, kind="stable")
    return np.take_along_axis(x, o, axis=1), np.take_along_axis(y, o, axis=1)


def _sampling_bounds(tau, th, is_desc, settings) -> dict:
    """Half-widths of the sampling terms of the loop figures (figure → half-width, in the figure's unit), from
    the nominal loop.

    The loop energy is ``∮τ dθ`` of the continuous loop estimated from the polygon through the measured levels
    (corrected by :func:`.metrics.chord_area`); lost motion at ``±x`` between levels is corrected by
    :func:`.metrics.chord_error`. The systematic half-widths are added linearly, the random ones (a
    segment whose curvature is below the noise) in quadrature. NaN where a branch is too short to bound them.
    """
    td, yd, ta, ya = (v[None, :] for v in (tau[is_desc], th[is_desc], tau[~is_desc], th[~is_desc]))
    (xd, fd), (xa, fa) = _branches(td, yd, ta, ya)
    _, sd, rd = metrics.chord_area(xd, fd)
    _, sa_, ra = metrics.chord_area(xa, fa)
    energy = float(sd[0] + sa_[0]) + math.hypot(float(rd[0]), float(ra[0]))
    out = {"loop_energy": energy}
    top, bottom = float(tau.max()), float(tau.min())
    u = 0.5 * (0.5 * (top - bottom)) * 0.5 * (float(th[np.argmax(tau)]) - float(th[np.argmin(tau)]))
    out["loss_factor"] = energy / (2 * math.pi * u) if u > 0 else float("nan")
    for f in settings["lost_motion_fractions"]:
        x = f * settings["lost_motion_reference_nm"]
        half = sum(float(metrics.chord_error(xb, fb, sgn * x)[1][0]) for xb, fb in ((xd, fd), (xa, fa))
                   for sgn in (1, -1))
        out[_lm_name(f)] = math.degrees(0.5 * half)
    return out


def _unbounded_reasons(nominal, sampling, tau, settings) -> dict:
    """Why a loop figure's sampling term cannot be bounded (figure → reason): the bound needs a measured
    neighbour segment beside the one that holds the evaluation torque, and a lost motion whose interpolation
    bound exceeds the figure itself is not determined by the levels measured."""
    out = {}
    lv = np.unique(np.abs(tau))
    for name in ("loop_energy", "loss_factor"):
        if not np.isfinite(sampling.get(name, np.nan)):
            out[name] = ("a branch has a segment between measured levels with no measured neighbour to bound the "
                         "continuous loop's area there: withheld")
    for f in settings["lost_motion_fractions"]:
        name, x = _lm_name(f), f * settings["lost_motion_reference_nm"]
        lo, hi = float(lv[lv <= x].max(initial=0.0)), float(lv[lv >= x].min(initial=np.inf))
        where = f"±{x:.4g} N·m lies between the measured levels {lo:.4g} and {hi:.4g} N·m"
        half, v = sampling.get(name, np.nan), float(nominal[name][0])
        if not np.isfinite(half):
            out[name] = f"{where}, which have no measured neighbour on a branch to bound the interpolation: withheld"
        elif np.isfinite(v) and half > abs(v):
            out[name] = (f"{where}: too far apart to bound the interpolation usefully (its bound ±{half:.2g}° "
                         f"exceeds the figure, {v:.2g}°): withheld")
    return out


#: Figures of the phases whose torque part the loop's Monte Carlo carries (their value and angle part stay
#: the phase's own, :func:`_phase_secant`).
_PHASE_SECANTS = (
    "k_positive_unloading_secant",
    "k_negative_loading_secant",
    "k_negative_unloading_secant",
    "k_positive_loading_secant",
)


def _mc_units(settings):
    units = {
        "hysteresis": "deg",
        "hysteresis_loss": "deg",
        "secant_stiffness": "nm_per_rad",
        "loop_energy": "j",
        "loss_factor": "1",
    }
    units.update({_lm_name(f): "deg" for f in settings["lost_motion_fractions"]})
    return units


def _gap_reasons(settings, tau, is_desc, levels) -> dict:
    """Why each model-free figure would interpolate across a gap (figure → reason), from the runs' levels."""
    runs = {"descending": np.unique(tau[is_desc]), "ascending": np.unique(tau[~is_desc])}
    out = {}
    holes = {}
    for rn, lv in runs.items():
        exp = levels[(levels >= lv.min() - _TOL) & (levels <= lv.max() + _TOL)] if lv.size else levels[:0]
        miss = checks.missing_levels(lv, exp)
        if miss:
            holes[rn] = miss
    # the loop's tips: the descending run holds both (+Tmax, then down to −Tmax); the ascending run starts one
    # level above −Tmax (the turning image is the descending run's last, photographed once) and ends at +Tmax
    lo_tip, hi_tip = float(levels.min()), float(levels.max())
    second = float(levels[1]) if levels.size > 1 else lo_tip
    need = {"descending": (lo_tip, hi_tip), "ascending": (hi_tip,)}
    for rn, lv in runs.items():
        short = [t for t in need[rn] if not lv.size or np.min(np.abs(lv - t)) > _TOL]
        if rn == "ascending" and lv.size and lv.min() > second + _TOL:
            short.append(second)
        if short:
            holes.setdefault(rn, []).extend(short)
    if holes:
        txt = "; ".join(f"{rn} run lacks {', '.join(f'{v:+.4g}' for v in m)} N·m" for rn, m in holes.items())
        for name in ("hysteresis", "loop_energy", "loss_factor"):
            out[name] = f"a failed image leaves a gap ({txt}): the loop would be interpolated across it, withheld"

    def point(name, where):
        for rn, at in where:
            g = checks.gap_between(runs[rn], levels, at)
            if g:
                out[name] = (
                    f"{at:+.4g} N·m is not bracketed by adjacent measured levels in the {rn} run "
                    f"(missing {', '.join(f'{v:+.4g}' for v in g)} N·m): not interpolated across the gap, withheld"
                )
                return

    point("hysteresis_loss", [("descending", 0.0), ("ascending", 0.0)])
    lo, hi = settings["secant_interval_nm"]
    point("secant_stiffness", [("ascending", lo), ("ascending", hi), ("descending", -lo), ("descending", -hi)])
    for f in settings["lost_motion_fractions"]:
        x = f * settings["lost_motion_reference_nm"]
        point(_lm_name(f), [("descending", x), ("descending", -x), ("ascending", x), ("ascending", -x)])
    return out


def _model_free_figures(col: _Collector, settings: dict, seed: int, levels: np.ndarray):
    loop = col.loop
    tau, th, th_std, tau_std, groups, is_desc, sources = loop.runs()
    top = groups == groups[np.argmax(tau)]
    bottom = groups == groups[np.argmin(tau)]
    evaluate = _mc_evaluator(is_desc, top, bottom, settings)
    nominal = evaluate(tau[None, :], th[None, :])
    kinds = loop.source_kinds if loop.source_kinds is not None else np.array(["level"] * sources.shape[1], object)
    # a draw that moves the torque axis may put an edge level a hair inside an evaluation torque: allow half a
    # step of extrapolation for the draws (the nominal value itself is never extrapolated)
    gaps_ = np.diff(np.unique(tau))
    evaluate_mc = _mc_evaluator(is_desc, top, bottom, settings, tol=0.5 * float(gaps_.min()) if gaps_.size else _TOL)
    std_a, std_t, by_kind = monte_carlo_std(
        evaluate_mc,
        tau,
        th,
        angle_std_rad=th_std,
        torque_sources=sources,
        n_draws=settings["n_draws"],
        seed=seed,
        kinds=kinds,
        torque_response=tip_amplitude_response(tau, th, is_desc),
    )
    method = "monte-carlo (torque errors with the loop's amplitude)"
    gaps = _gap_reasons(settings, tau, is_desc, levels)
    sampling = _sampling_bounds(tau, th, is_desc, settings)
    gaps.update({k: v for k, v in _unbounded_reasons(nominal, sampling, tau, settings).items() if k not in gaps})
    for name in _PHASE_SECANTS:
        if np.isfinite(std_t.get(name, np.nan)):
            col.set_torque_part(
                name, std_t[name], by_kind[name], f"first-order (two ends); torque part {method}", settings["n_draws"]
            )
    flat = checks.flat_top(tau[is_desc], th[is_desc], th_std[is_desc], tau[~is_desc], th[~is_desc], th_std[~is_desc])
    for name, unit in _mc_units(settings).items():
        v = float(nominal[name][0])
        if name in gaps:
            col.fail(name, unit, gaps[name])
        elif np.isfinite(v):
            flag = ""
            if name == "hysteresis" and flat:
                flag = (
                    f"flagged: the largest loop width is the maximum over {flat['levels']} torque levels whose widths "
                    f"agree within the noise (a flat-topped loop), so noise biases it upward by about "
                    f"{math.degrees(flat['bias_rad']):.2g}° (σ of one width {math.degrees(flat['sigma_rad']):.2g}°); "
                    "the width at zero torque (hysteresis_loss) is not biased"
                )
            col.add(name, unit, v, std_a[name], std_t[name], method, parts=by_kind[name], flag=flag,
                    draws=settings["n_draws"], sampling=sampling.get(name, 0.0))
        else:
            col.fail(name, unit, _mc_reason(name, tau, settings))
    _loop_direction(col, settings)
    return tau, th, th_std, is_desc, sources, kinds


def _loop_direction(col: _Collector, settings: dict) -> None:
    """Withhold the loop-width figures of a loop that runs clockwise; flag an area not resolved from zero.

    See :func:`.checks.loop_direction`: a passive gear's loop runs anticlockwise (positive energy).
    """
    row = next((r for r in col.rows if r["figure"] == "loop_energy"), None)
    if row is None or not np.isfinite(row["value"]):
        return
    energy, u95 = row["value"], row["u95"]
    direction = checks.loop_direction(energy, u95)
    if direction == "clockwise":
        names = {"hysteresis", "hysteresis_loss", "loop_energy", "loss_factor",
                 *(_lm_name(f) for f in settings["lost_motion_fractions"])}
        for r in col.rows:
            if r["figure"] in names:
                r.update(value=np.nan, std=np.nan, u95=np.nan, flag="")
        col.issues.append(Issue(
            col.loop.orientation_deg, col.loop.cycle, "loop figures",
            f"the loop runs the other way round (clockwise: its area is {energy:+.3g} J, beyond its u95 "
            f"{u95:.2g} J), but a gear's loop dissipates and runs anticlockwise: phases or torque signs "
            "look mislabelled (check the phase and torque_nm columns). Hysteresis, lost motion, loop energy and "
            "loss factor are withheld", kind="rejected"))
    elif direction == "unresolved" and row["value"] < 0:
        why = (f"flagged: the loop's area {energy:+.2g} J is within its u95 ({u95:.2g} J) of zero: no "
               "dissipation is resolved, and a negative area is noise, not an energy")
        for r in col.rows:
            if r["figure"] in ("loop_energy", "loss_factor") and np.isfinite(r["value"]):
                r["flag"] = "; ".join(x for x in (r["flag"], why) if x)
                col.issues.append(Issue(col.loop.orientation_deg, col.loop.cycle, r["figure"], why, kind="flagged"))


def _catalogue_figures(col: _Collector, settings: dict, runs):
    tau, th, th_std, is_desc, sources, kinds = runs
    seg_mask = (is_desc & (tau <= 0)) | (~is_desc & (tau >= 0))
    t, y, sa = tau[seg_mask], th[seg_mask], th_std[seg_mask]
    branch = np.where(is_desc[seg_mask], -1, 1)
    src, knd = compact_sources(sources[seg_mask], kinds)
    src_local = src[:, np.asarray(knd) != "g_r"]
    st_local = np.sqrt(np.sum(src_local**2, axis=1))
    names = (("k1", "nm_per_rad"), ("k2", "nm_per_rad"), ("k3", "nm_per_rad"))
    breaks = settings.get("catalogue_breaks_nm")
    data = dict(branch=branch, angle_std_rad=sa, torque_std_nm=st_local, torque_sources=src, gate_sources=src_local)
    try:
        if breaks is not None:
            res = fit_fixed_breaks(t, y, breaks_nm=breaks, **data)
            method = "linear least squares, catalogue T1/T2 fixed"
        elif settings["fit_breaks"]:
            res = fit_catalogue_breaks(t, y, **data, n_draws=settings["n_draws"], seed=settings["seed"])
            method = "breaks fitted; uncertainty by a parametric bootstrap that refits the breaks"
        else:
            for n, u in names:
                col.fail(n, u, "no catalogue T1/T2 given and fitting the breaks is off")
            return
    except AnalysisError as exc:
        for n, u in names + (("t1", "nm"), ("t2", "nm")):
            col.fail(n, u, str(exc))
        return
    chk = res["check"]
    draws = res.get("draws")
    for j, (n, u) in enumerate(names):
        if j < len(res["k"]):
            col.add(n, u, res["k"][j], res["std_angle"][j], res["std_torque"][j], method, check=chk, draws=draws,
                    interval=res["u95"][j] if "u95" in res else np.nan)
        else:
            col.fail(n, u, f"one break describes the loading branches (two segments: K1, K2); {res['criterion']}",
                     kind="not_applicable")
    if breaks is None and settings["fit_breaks"]:
        for j, n in enumerate(("t1", "t2")):
            if j < len(res["breaks_nm"]):
                col.add(n, "nm", res["breaks_nm"][j], res["breaks_std_angle"][j], res["breaks_std_torque"][j],
                        method, check=chk, draws=draws, interval=res["breaks_u95"][j])
            else:
                col.fail(n, "nm", "one break describes the loading branches (two segments)", kind="not_applicable")


def _mc_reason(name, tau, settings):
    lo, hi = float(tau.min()), float(tau.max())
    if name.startswith("lost_motion"):
        return f"the lost-motion torques are not covered by both runs (torque {lo:.4g} to {hi:.4g} N·m)"
    if name == "secant_stiffness":
        a, b = settings["secant_interval_nm"]
        return f"secant interval {a:.4g} to {b:.4g} N·m is not covered by both loading branches"
    if name == "hysteresis_loss":
        return "zero torque is not covered by both runs"
    return f"the two runs do not overlap in torque or the loop is degenerate (torque {lo:.4g} to {hi:.4g} N·m)"


_BW_UNITS = {
    "k_e": ("nm_per_rad", 1.0),
    "z_s": ("deg", 180 / math.pi),
    "a": ("per_nm", 1.0),
    "rho": ("1", 1.0),
    "n": ("1", 1.0),
}
_BW_BOUNDS = {"rho": (1e-12, 0.5), "n": (0.3, 40.0)}


def _bilinear_jacobian(bil: BilinearFit, tau: np.ndarray) -> np.ndarray:
    """d(model)/d(θ₀, c_u, c_l, τ_c) of a bilinear fit along the torque path (central differences)."""
    from .models import bilinear_response

    p = np.array([bil.theta0_rad, 1 / bil.k_u_nm_per_rad, 1 / bil.k_l_nm_per_rad, bil.tau_c_nm])

    def f(q):
        return bilinear_response(tau, k_u=1 / q[1], k_l=1 / q[2], tau_c=q[3], theta_start=q[0])

    amp = float(np.max(np.abs(tau)))
    return numeric_jacobian(f, p, np.array([1e-6, p[1] * 1e-6, p[2] * 1e-6, amp * 1e-7]))


def _model_check(loop, model: np.ndarray, torque_std_nm, *, n_params: int, compliance=None, **options):
    """Lack-of-fit test of a model of `loop` (its angle, rad, along the loop's torque path):
    the residual, the model's compliance (``compliance``, else its path compliance) and the loop's
    own torque sources."""
    return lack_of_fit(
        loop.angle_rad - model,
        angle_std_rad=loop.angle_std_rad,
        torque_std_nm=torque_std_nm,
        compliance_rad_per_nm=path_compliance(loop.torque_nm, model) if compliance is None else compliance,
        n_params=n_params,
        torque_sources=loop.local_sources(),
        **options,
    )


def _model_fits(col: _Collector, settings: dict) -> dict:
    loop = col.loop
    st = loop.local_std()
    kw = dict(angle_std_rad=loop.angle_std_rad, torque_sources=loop.sources())
    out = {"bilinear": None, "bouc_wen": None, "preisach": None, "checks": {}}
    try:
        bil: BilinearFit = fit_bilinear(loop.torque_nm, loop.angle_rad, **kw)
    except AnalysisError as exc:
        for name, unit in (
            ("bilinear_k_u", "nm_per_rad"),
            ("bilinear_k_l", "nm_per_rad"),
            ("bilinear_tau_c", "nm"),
            ("bilinear_residual_rms", "deg"),
        ):
            col.fail(name, unit, str(exc))
    else:
        out["bilinear"] = bil
        chk = _model_check(
            loop,
            bil.predict(loop.torque_nm),
            st,
            n_params=4,
            compliance=side_compliance(bil.predict, loop.torque_nm),
            jacobian=_bilinear_jacobian(bil, loop.torque_nm),
            weights=least_squares_weights(loop.angle_std_rad),
        )
        out["checks"]["bilinear"] = chk
        for name, attr, unit in (
            ("k_u", "k_u_nm_per_rad", "nm_per_rad"),
            ("k_l", "k_l_nm_per_rad", "nm_per_rad"),
            ("tau_c", "tau_c_nm", "nm"),
        ):
            col.add(
                f"bilinear_{name}",
                unit,
                getattr(bil, attr),
                bil.std_angle[name],
                bil.std_torque[name],
                "first-order",
                check=chk,
            )
        col.add("bilinear_residual_rms", "deg", math.degrees(bil.residual_rms_rad), method="fit statistic")
    if settings["fit_preisach"]:
        try:
            pre = fit_preisach(
                loop.torque_nm,
                loop.angle_rad,
                angle_std_rad=loop.angle_std_rad,
                torque_std_nm=st,
                torque_sources=loop.local_sources(),
            )
        except AnalysisError as exc:
            col.fail("preisach_residual_rms", "deg", str(exc))
        else:
            out["preisach"] = pre
            out["checks"]["preisach"] = pre.check
            col.add(
                "preisach_residual_rms",
                "deg",
                math.degrees(pre.residual_rms_rad),
                method="fit statistic",
                flag=f"Preisach model rejected: {pre.check.describe()}" if pre.check.rejected else "",
            )
    if not settings["fit_bouc_wen"]:
        return out
    try:
        bw: BoucWenFit = fit_bouc_wen(loop.torque_nm, loop.angle_rad, **kw)
    except AnalysisError as exc:
        for name, (unit, _) in _BW_UNITS.items():
            col.fail(f"bouc_wen_{name}", unit, str(exc))
        col.fail("bouc_wen_residual_rms", "deg", str(exc))
        return out
    out["bouc_wen"] = bw
    chk = _model_check(loop, bw.predict(loop.torque_nm), st, n_params=6)
    out["checks"]["bouc_wen"] = chk
    for name, (unit, scale) in _BW_UNITS.items():
        v = bw.params[name]
        lo_hi = _BW_BOUNDS.get(name)
        on_bound = lo_hi is not None and (v <= lo_hi[0] * 1.001 or v >= lo_hi[1] * 0.999)
        if on_bound:
            col.add(
                f"bouc_wen_{name}",
                unit,
                v * scale,
                method="first-order",
                flag=f"parameter on its bound ({lo_hi[0]:g} to {lo_hi[1]:g}): not identified, no uncertainty given",
            )
        else:
            col.add(
                f"bouc_wen_{name}",
                unit,
                v * scale,
                bw.std_angle[name] * scale,
                bw.std_torque[name] * scale,
                "first-order",
                check=chk,
            )
    col.add("bouc_wen_residual_rms", "deg", math.degrees(bw.residual_rms_rad), method="fit statistic")
    return out


def _bilinear_spikes(loop, keep, fit=None):
    """Spike scores (:func:`.fitcheck.spike_scores`) of the bilinear fit to the kept samples of `loop`
    (NaN at the others), with the loop's correlated torque sources; `fit`: that fit, when made."""
    tau, th, sa = loop.torque_nm[keep], loop.angle_rad[keep], loop.angle_std_rad[keep]
    bil = fit_bilinear(tau, th, angle_std_rad=sa) if fit is None else fit
    out = np.full(loop.torque_nm.size, np.nan)
    out[keep] = spike_scores(
        th - bil.predict(tau),
        angle_std_rad=sa,
        compliance_rad_per_nm=side_compliance(bil.predict, tau),
        torque_sources=loop.local_sources()[keep],
        jacobian=_bilinear_jacobian(bil, tau),
        weights=least_squares_weights(sa),
    )
    return out


def _preisach_spikes(loop, keep, fit=None):
    """Spike scores of the Preisach fit to the kept samples of `loop` (NaN at the others): its active set
    as the Jacobian, each angle's marginal noise as its gate has it (:func:`.preisach.fit_preisach`);
    `fit`: that fit, when made."""
    tau, th, sa = loop.torque_nm[keep], loop.angle_rad[keep], loop.angle_std_rad[keep]
    src = loop.local_sources()[keep]
    pre = fit if fit is not None else fit_preisach(tau, th, angle_std_rad=sa, torque_std_nm=loop.local_std()[keep],
                                                    torque_sources=src)
    st_eff = np.sqrt(np.sum((torque_sensitivity(tau, th - pre.residual_rad) @ src) ** 2, axis=1))
    out = np.full(loop.torque_nm.size, np.nan)
    out[keep] = spike_scores(pre.residual_rad, angle_std_rad=sa, compliance_rad_per_nm=1.0,
                             torque_sources=np.diag(st_eff), jacobian=pre.active_design(tau),
                             weights=least_squares_weights(sa))
    return out


def _outliers_found(loop, fit_set: dict):
    """Outliers of `loop` and the model they were judged by (see :mod:`.checks`), or ``([], "")``.

    Each sample's score as a lone spike (:func:`.fitcheck.spike_scores`) in the bilinear fit, with the
    weight pieces' correlated errors, when that model describes the loop but for its worst sample (its
    gate passes with that sample's ``t²`` taken out of χ²); else in the flexible Preisach fit (its
    active set; a sample it follows exactly is not judged, and a sample its symmetry ties to its mirror
    image cannot be told from it); none when neither model describes the loop. Found one at a time
    (:func:`.checks.backward_outliers`).
    """
    n = loop.torque_nm.size
    for model, spikes, name in (("bilinear", _bilinear_spikes, "bilinear fit"),
                                ("preisach", _preisach_spikes, "Preisach fit")):
        chk = fit_set.get("checks", {}).get(model)
        if fit_set.get(model) is None or chk is None or not chk.testable or chk.dof <= 1:
            continue
        try:
            t = spikes(loop, np.ones(n, bool), fit_set[model])
        except AnalysisError:
            continue
        if not np.any(np.isfinite(t)):
            continue
        if special.chdtrc(chk.dof - 1, max(chk.chi2 - float(np.nanmax(t**2)), 0.0)) < LACK_OF_FIT_ALPHA:
            continue

        def scores(keep, t=t, spikes=spikes):  # the first round is the scores just computed
            return t if keep.all() else spikes(loop, keep)

        return checks.backward_outliers(loop.images, scores), name
    return [], ""


def _outlier_issues(col: _Collector, fit_set: dict):
    loop = col.loop
    found, name = _outliers_found(loop, fit_set)
    for image, z in found:
        col.issues.append(
            Issue(
                loop.orientation_deg,
                loop.cycle,
                "outlier",
                f"image {image} is {z:+.1f}σ off the loop's model ({name}, as a lone spike): a forgotten or extra "
                "weight, or a missed or extra shot? Check the image and its weights, re-take it or mark it failed",
            )
        )
    return found


def _wide(figures: pd.DataFrame) -> pd.DataFrame:
    if figures.empty:
        return pd.DataFrame(columns=["orientation_deg", "cycle"])
    f = figures.copy()
    suffix = f["unit"].where(f["unit"] != "1", "")
    f["col"] = f["figure"] + np.where(suffix != "", "_" + suffix, "")
    f["col_std"] = f["figure"] + "_std" + np.where(suffix != "", "_" + suffix, "")
    order = list(dict.fromkeys(c for pair in zip(f["col"], f["col_std"]) for c in pair))
    val = f.pivot_table(
        index=["orientation_deg", "cycle"], columns="col", values="value", aggfunc="first", dropna=False
    )
    std = f.pivot_table(
        index=["orientation_deg", "cycle"], columns="col_std", values="std", aggfunc="first", dropna=False
    )
    wide = pd.concat([val, std], axis=1).reindex(columns=order)
    wide.columns.name = None
    return wide.reset_index()


def _rig_issues(usable: pd.DataFrame, rig: dict) -> list:
    """Where ``measurements.csv`` disagrees with the rig of the ``"pieces"`` model.

    Checks that each pan load is a whole number of pieces (to 1 %) and that the
    table's ``torque_std_nm`` is the marginal 1σ of the model (to 5 %; the tables of
    :func:`vision_torsion.session.torque.couple_torque` agree exactly).
    """
    out = []
    mass = pd.to_numeric(usable["mass_kg"], errors="coerce").to_numpy(float)
    frac = mass / rig.step_mass_kg
    off = np.abs(frac - np.rint(frac)) > 0.01
    if off.any():
        i = int(np.flatnonzero(off)[0])
        out.append(
            Issue(
                None,
                None,
                "torque uncertainty",
                f"{int(off.sum())} image(s) carry a pan load that is not a whole number of "
                f"{rig.step_mass_kg:g} kg pieces (first: {usable['image'].iloc[i]}, {mass[i]:g} kg); "
                "the 'pieces' torque model counts a partial piece as a whole one",
            )
        )
    sources, _ = torque_sources(usable, correlation="pieces", rig=rig)
    model_std = np.sqrt(np.sum(sources**2, axis=1))
    table_std = usable["torque_std_nm"].to_numpy(float)
    scale = max(float(np.max(model_std)), float(np.max(table_std)), 1e-300)
    bad = np.abs(table_std - model_std) > 0.05 * np.maximum(model_std, table_std) + 1e-9 * scale
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        out.append(
            Issue(
                None,
                None,
                "torque uncertainty",
                f"torque_std_nm of {int(bad.sum())} image(s) differs from the rig's weight-piece model "
                f"(first: {usable['image'].iloc[i]}, table {table_std[i]:.3g} N·m, model "
                f"{model_std[i]:.3g} N·m); the uncertainties use the rig",
            )
        )
    return out


def _sign_issues(signs: list, issues: list) -> dict:
    """Orientations whose angle falls as the torque rises (:func:`.checks.angle_sign_by_run`) when the
    session as a whole has the right sign: an issue each, and ``{orientation: why its figures are withheld}``."""
    out = {}
    for sg in signs:
        if not sg["falls"]:
            continue
        o = sg["orientation_deg"]
        t = ", ".join(f"{run} t = {v:+.3g}" for run, v in sg["t"].items())
        if len(sg["falls"]) == len(checks.RUNS):
            why = (f"the angle falls as the torque rises in orientation {o:g}° ({t}), not in the others: its "
                   "angle sign is inverted (a mis-set orientation, or the camera flipped between orientations); "
                   "check its images and setup, or multiply this orientation's angle_deg by -1. Its figures are "
                   "withheld")
        else:
            why = (f"in orientation {o:g}° the angle falls as the torque rises on the {' and '.join(sg['falls'])} "
                   f"run but not on the other ({t}): phases or torque signs look mislabelled; check the "
                   "table's phase and torque_nm columns. Its figures are withheld")
        out[o] = why
        issues.append(Issue(o, None, "angle sign", why))
    return out


def analyze_session(
    measurements,
    *,
    max_torque_nm=None,
    rated_torque_nm=None,
    catalogue_breaks_nm=None,
    fit_breaks=True,
    secant_interval_nm=None,
    gear_ratio=None,
    torque_correlation=None,
    rig=None,
    lost_motion_fractions=(0.03, 0.04),
    secant_interval=(0.5, 1.0),
    n_draws=400,
    seed=0,
    fit_bouc_wen=False,
    fit_preisach=True,
    torque_model_declared=True,
) -> SessionAnalysis:
    """Analyse the torque–angle table of a session: every figure of every loop, checked.

    Parameters
    ----------
    measurements : pandas.DataFrame
        The ``measurements.csv`` table (see :data:`.loops.REQUIRED_COLUMNS`; the
        optional ``torque_common_std_nm`` is used when present). Only
        ``status == "ok"`` rows are used; the others are listed as failed images.
    max_torque_nm : float, optional
        Maximum test torque, N·m (default: the largest ``|torque_nm|`` of the usable
        loop images): the secant interval's fractions refer to it.
    rated_torque_nm : float, optional
        The gear's rated torque T_R, N·m: lost motion is evaluated at
        ``±fraction·T_R``. Without it, at ``±fraction·max_torque_nm`` (and
        ``settings["lost_motion_reference"]`` says so).
    catalogue_breaks_nm : (float, float), optional
        The catalogue's T1, T2 (N·m): K1, K2, K3 by linear least squares with these
        breaks fixed.
    fit_breaks : bool
        Without catalogue breaks, fit them (one or two, :mod:`.catalogue`).
    secant_interval_nm : (float, float), optional
        Secant interval in N·m (overrides ``secant_interval``).
    gear_ratio : float, optional
        Transmission ratio i (input turns per output turn): stiffnesses are also given
        on the output side, ``K_out = i²·K_in`` (see ``output_side`` in the summary for
        the caveat).
    torque_correlation : {"pieces", "level", "independent"}, optional
        Error model of the torques (see :mod:`.uncertainty`). Default: ``"pieces"``
        when ``rig`` is given, else ``"level"``.
    rig : TorqueRig or mapping, optional
        Rig constants for the ``"pieces"`` model
        (:class:`vision_torsion.measurements.TorqueRig`, e.g. a session's
        ``config.torque_rig``, or a mapping of its constants; see
        :func:`.uncertainty.check_rig`). The pieces per pan of an image are
        ``mass_kg / step_mass_kg``, the sign that of its phase.
    lost_motion_fractions : sequence of float
        Fractions of T_R (or the max torque) for the lost-motion figures; 3 % and
        4 % by default (GB/T 35089 and the catalogues).
    secant_interval : (float, float)
        Secant stiffness interval as fractions of ``max_torque_nm``.
    n_draws : int
        Monte Carlo draws per error source and loop.
    seed : int
        Base seed; loop ``i`` uses ``seed + i``.
    fit_bouc_wen : bool
        Fit the Bouc–Wen model too (slow, ≈0.1–0.5 s per loop; it does not describe
        the sharp bilinear loop, and its gate says so).
    fit_preisach : bool
        Fit the Preisach model (:mod:`.preisach`), also used to find outliers.
    torque_model_declared : bool
        False when the caller has no torque-error model to declare (a table analysed
        without its rig and without explicit rig options, :func:`vision_torsion.report.analyze_table`):
        then, without a ``rig``, every figure is **flagged**
        :data:`TORQUE_NOT_MODELLED` (each level's ``torque_std_nm`` taken as its own
        error misses the weight pieces' accumulation step by step, which moves slopes
        and the loop energy) and a session issue says so.

    Returns
    -------
    SessionAnalysis

    Raises
    ------
    AnalysisError
        Invalid table (see :func:`.loops.validate_measurements`) or invalid options.
        Problems of single loops are not raised but listed in ``issues``.

    Examples
    --------
    >>> import numpy as np
    >>> from vision_torsion.synthetic import simulate_measurements
    >>> df = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0,), torque_model="pieces",
    ...                            rng=np.random.default_rng(1))
    >>> rig = dict(step_mass_kg=0.02, mass_std_kg=1e-4, gravity_m_per_s2=9.81, arm_radius_m=0.05)
    >>> a = analyze_session(df, rig=rig, n_draws=50)
    >>> a.settings["torque_correlation"], abs(a.summary["bilinear_k_u"]["mean"] / 4.4 - 1) < 0.01
    ('pieces', True)
    """
    if n_draws < 10:
        raise AnalysisError(f"n_draws must be at least 10, got {n_draws}")
    if not (0 <= secant_interval[0] < secant_interval[1] <= 1):
        raise AnalysisError(
            f"secant_interval must be fractions 0 <= a < b <= 1 of the max torque, got {secant_interval}"
        )
    fr = list(lost_motion_fractions)
    if not fr or not all(isinstance(f, (int, float)) and 0 < f < 1 for f in fr):
        raise AnalysisError(f"lost_motion_fractions must be fractions in (0, 1), got {lost_motion_fractions}")
    for name, v, unit in (("rated_torque_nm", rated_torque_nm, "N·m"), ("gear_ratio", gear_ratio, "")):
        if v is not None:
            check_number(v, name=name, error=AnalysisError, low=0, low_open=True, unit=unit)
    if catalogue_breaks_nm is not None:
        cb = [float(v) for v in catalogue_breaks_nm]
        if len(cb) != 2 or not (0 < cb[0] < cb[1]):
            raise AnalysisError(
                f"catalogue_breaks_nm must be (T1, T2) with 0 < T1 < T2 (N·m), got {catalogue_breaks_nm}"
            )
        catalogue_breaks_nm = cb
    if torque_correlation is None:
        torque_correlation = "level" if rig is None else "pieces"
    if rig is not None:
        rig = check_rig(rig)
    usable, failed, closing = validate_measurements(measurements, with_closing=True)
    loops = build_loops(usable, torque_correlation=torque_correlation, rig=rig)
    data_max = float(np.max(np.abs(usable["torque_nm"])))
    if max_torque_nm is None:
        max_torque_nm = data_max
    else:
        max_torque_nm = check_number(max_torque_nm, name="max_torque_nm", error=AnalysisError, low=0,
                                     low_open=True, unit="N·m")
    if secant_interval_nm is None:
        secant_interval_nm = (secant_interval[0] * max_torque_nm, secant_interval[1] * max_torque_nm)
    elif not (len(secant_interval_nm) == 2 and 0 <= secant_interval_nm[0] < secant_interval_nm[1]):
        raise AnalysisError(f"secant_interval_nm must be (a, b) with 0 <= a < b (N·m), got {secant_interval_nm}")
    lm_ref = float(rated_torque_nm) if rated_torque_nm is not None else float(max_torque_nm)
    settings = {
        "max_torque_nm": float(max_torque_nm),
        "torque_correlation": torque_correlation,
        "lost_motion_fractions": [float(f) for f in fr],
        "lost_motion_reference_nm": lm_ref,
        "lost_motion_reference": "rated torque T_R"
        if rated_torque_nm is not None
        else "maximum test torque (no rated torque given)",
        "rated_torque_nm": None if rated_torque_nm is None else float(rated_torque_nm),
        "secant_interval": [float(f) for f in secant_interval],
        "secant_interval_nm": [float(v) for v in secant_interval_nm],
        "catalogue_breaks_nm": catalogue_breaks_nm,
        "fit_breaks": bool(fit_breaks),
        "gear_ratio": None if gear_ratio is None else float(gear_ratio),
        "n_draws": int(n_draws),
        "seed": int(seed),
        "fit_bouc_wen": bool(fit_bouc_wen),
        "fit_preisach": bool(fit_preisach),
        "coverage_factor": COVERAGE_FACTOR,
        "rig": None if rig is None else rig.to_dict(),
    }
    issues: list[Issue] = []
    unmodelled = not torque_model_declared and rig is None
    settings["torque_uncertainty_modelled"] = not unmodelled
    if unmodelled:
        issues.append(Issue(None, None, "torque uncertainty", TORQUE_NOT_MODELLED, kind="flagged"))
    if torque_correlation == "pieces":
        issues.extend(_rig_issues(usable, rig))
    for r in failed.itertuples(index=False):
        orient = float(r.orientation_deg) if np.isfinite(r.orientation_deg) else None
        cycle = int(r.cycle) if np.isfinite(r.cycle) else None
        issues.append(Issue(orient, cycle, "*", f"image {r.image} ({r.phase}, step {r.step}) excluded: {r.message}"))
    signs = checks.angle_sign_by_run(usable)
    inverted = checks.angle_sign_inverted(usable["torque_nm"], usable["angle_deg"]) and all(
        len(sg["falls"]) == len(checks.RUNS) for sg in signs)
    wrong_sign = {} if inverted else _sign_issues(signs, issues)
    if inverted:
        issues.append(
            Issue(
                None,
                None,
                "angle sign",
                "angle_sign looks inverted; set angle_sign = -1 in session.toml (the angle falls as the "
                "torque rises; or multiply angle_deg by -1). Every figure is withheld until then.",
            )
        )
    closure = checks.closure_checks(usable, closing)
    creep = {}
    for c in closure:
        if c["creep"]:
            creep.setdefault(c["orientation_deg"], []).append(c)
            issues.append(
                Issue(
                    c["orientation_deg"],
                    None,
                    "creep",
                    f"{c['check']}: the angle moved by {c['difference_deg']:+.4g}° ({c['z']:+.1f}σ; "
                    f"{c['image_first']} → {c['image_last']}): creep or a disturbed rig",
                )
            )
    levels = np.unique(np.round(usable["torque_nm"].to_numpy(float) / _TOL) * _TOL)
    all_sources, _, kinds = torque_sources(usable, correlation=torque_correlation, rig=rig, return_kinds=True)
    rows, phase_rows, fits, outlier_rows = [], [], {}, []
    for orient, seq in usable.groupby("orientation_deg", sort=True):
        seq = seq.reset_index(drop=True)
        idx = np.flatnonzero(usable["orientation_deg"].to_numpy(float) == orient)
        src_all = [lp for lp in loops if lp.orientation_deg == float(orient)]
        sources = all_sources[idx]
        local = np.concatenate([lp.local_std() for lp in src_all]) if src_all else np.zeros(0)
        for lp in src_all:
            i = loops.index(lp)
            col = _Collector(lp, issues)
            if inverted or float(orient) in wrong_sign:
                col.fail("*", "", wrong_sign.get(float(orient),
                                                 "angle_sign looks inverted (set angle_sign = -1): figures withheld"))
                fits[(lp.orientation_deg, lp.cycle)] = {
                    "bilinear": None,
                    "bouc_wen": None,
                    "preisach": None,
                    "checks": {},
                }
                rows.extend(col.rows)
                continue
            _phase_figures(col, phase_rows, seq, local, sources, kinds, levels)
            problem = _loop_problem(lp)
            if problem is None:
                fits[(lp.orientation_deg, lp.cycle)] = _model_fits(col, settings)
                runs = _model_free_figures(col, settings, seed + i, levels)
                _catalogue_figures(col, settings, runs)
                for image, z in _outlier_issues(col, fits[(lp.orientation_deg, lp.cycle)]):
                    outlier_rows.append(
                        {"orientation_deg": lp.orientation_deg, "cycle": lp.cycle, "image": image, "z": z}
                    )
            else:
                for name, unit in {
                    **_mc_units(settings),
                    "k1": "nm_per_rad",
                    "k2": "nm_per_rad",
                    "k3": "nm_per_rad",
                    "bilinear_k_u": "nm_per_rad",
                    "bilinear_k_l": "nm_per_rad",
                    "bilinear_tau_c": "nm",
                }.items():
                    col.add(name, unit, np.nan)
                issues.append(Issue(lp.orientation_deg, lp.cycle, "loop figures", problem))
                fits[(lp.orientation_deg, lp.cycle)] = {
                    "bilinear": None,
                    "bouc_wen": None,
                    "preisach": None,
                    "checks": {},
                }
            if float(orient) in creep:
                for r in col.rows:  # every figure of the orientation, beside any flag of its own
                    if np.isfinite(r["value"]) and "creep or drift" not in r["flag"]:
                        r["flag"] = "; ".join(x for x in (r["flag"], _CREEP_FLAG) if x)
            if unmodelled:
                for r in col.rows:
                    if np.isfinite(r["value"]):
                        r["flag"] = "; ".join(x for x in (r["flag"], "flagged: " + TORQUE_NOT_MODELLED) if x)
            rows.extend(col.rows)
    figures = pd.DataFrame(rows, columns=FIGURE_COLUMNS)
    figures = figures[figures["figure"] != "*"].reset_index(drop=True)
    summary, per_orientation = summarise_figures(figures)
    _output_side(summary, settings)
    phases = pd.DataFrame(phase_rows)
    return SessionAnalysis(
        figures=figures,
        loops=_wide(figures),
        phases=phases,
        summary=summary,
        per_orientation=per_orientation,
        issues=issues,
        failed_images=failed,
        settings=settings,
        loop_data=loops,
        fits=fits,
        n_images=int(len(measurements)),
        checks={"angle_sign_inverted": bool(inverted), "angle_sign_inverted_orientations": sorted(wrong_sign),
                "angle_sign": signs, "closure": closure, "outliers": outlier_rows},
    )


#: Caveat of the output-side conversion.
OUTPUT_SIDE_CAVEAT = (
    "K_out = i²·K_in refers the input-side stiffness to the output through an ideal transmission "
    "(θ_in = i·θ_out, τ_out = i·τ_in, no loss). Friction and efficiency losses, and any compliance between the "
    "measured shaft and the gear, make the real output-side stiffness differ; measure at the output to be sure."
)


def _output_side(summary: dict, settings: dict) -> None:
    i = settings.get("gear_ratio")
    if not i:
        return
    for name, s in summary.items():
        if s.get("unit") == "nm_per_rad" and s.get("mean") is not None:
            s["output_side"] = {
                "gear_ratio": i,
                "mean_nm_per_rad": s["mean"] * i * i,
                "mean_std_nm_per_rad": None if s.get("mean_std") is None else s["mean_std"] * i * i,
                "caveat": OUTPUT_SIDE_CAVEAT,
            }
