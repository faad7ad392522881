"""``analyze_session``: every figure of every loop of a session, with uncertainties,
summaries, checks on the data, and a list of what could not be computed and why.

The analysis is a short orchestrator over **figure families**, each a module with one
function that takes a loop and the :class:`~.parameters.AnalysisOptions` and returns
its figure rows and its issues (:class:`~.rows.FigureRows`): a new figure touches
the one module of its family.

- :mod:`.phase_figures` — the stiffness of each phase (straight line, two stiffnesses
  around a switch, secant);
- :mod:`.loop_figures` — the loop's figures by Monte Carlo (hysteresis, lost motion,
  secant stiffness, loop energy, loss factor);
- :mod:`.catalogue_figures` — K1–K3 (and fitted T1, T2);
- :mod:`.model_figures` — the bilinear, Preisach and Bouc–Wen fits and their gates;
- :mod:`.data_checks` — failed images, the rig, the angle sign, creep, outliers.

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

Torque errors follow the weight pieces when the rig is known (``rig=...``,
``torque_correlation="pieces"``), else one shared error per torque level
(``"level"``); pulley friction is a torque opposing the motion; see
:mod:`.uncertainty`.

Expanded uncertainties are ``u95 = k·std`` with ``k = 2``, or Student's ``t_0.975``
at the Welch–Satterthwaite degrees of freedom when a Monte Carlo part rests on few
draws (ν = draws − 1), or at the lack-of-fit test's dof when the uncertainty was
inflated by ``√χ²_red`` (the figures' ``coverage_factor`` column).

A figure that cannot be computed is NaN in the tables and None in JSON, and an
:class:`Issue` says which orientation/cycle and why; it is never replaced by 0.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import pandas as pd

from .catalogue_figures import CATALOGUE_UNITS, catalogue_figures
from .data_checks import SessionChecks, outlier_issues, session_checks
from .fitcheck import local_torque_std
from .loop_figures import loop_figure_units, loop_figures
from .loops import Loop, build_loops, validate_measurements
from .model_figures import BILINEAR_UNITS, model_figures, no_fits
from .parameters import AnalysisOptions
from .phase_figures import phase_figures
from .rows import FIGURE_COLUMNS, ISSUE_KINDS, LEVEL_TOL_NM, TORQUE_NOT_MODELLED, FigureRows, Issue
from .summary import summarise_figures
from .uncertainty import COVERAGE_FACTOR, torque_sources

__all__ = [
    "ISSUE_KINDS", "Issue", "SessionAnalysis", "analyze_session", "SUMMARY_SCHEMA", "FIGURE_COLUMNS",
    "TORQUE_NOT_MODELLED"]

#: Identifies the layout of :meth:`SessionAnalysis.to_dict` (summary.json).
SUMMARY_SCHEMA = "vision-torsion/analysis-summary/2"

_MIN_PHASE_POINTS_FOR_LOOP = 2


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


def analyze_session(measurements, *, options: AnalysisOptions | None = None, **keywords) -> SessionAnalysis:
    """Analyse the torque–angle table of a session: every figure of every loop, checked.

    Parameters
    ----------
    measurements : pandas.DataFrame
        The ``measurements.csv`` table (see :data:`.loops.REQUIRED_COLUMNS`; the
        optional ``torque_common_std_nm`` is used when present). Only
        ``status == "ok"`` rows are used; the others are listed as failed images.
    options : AnalysisOptions, optional
        What to compute and how (:class:`~.parameters.AnalysisOptions`).
    **keywords
        Or the same options as keywords (``rig=..., n_draws=..., rated_torque_nm=...``: the
        fields of :class:`~.parameters.AnalysisOptions`), not both.

    Returns
    -------
    SessionAnalysis

    Raises
    ------
    AnalysisError
        Invalid table (see :func:`.loops.validate_measurements`) or invalid options
        (:class:`~.parameters.AnalysisOptions`). Problems of single loops are not raised
        but listed in ``issues``.
    TypeError
        An unknown keyword, or both `options` and keywords.

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
    if options is not None and keywords:
        raise TypeError(f"give the analysis options either as options= or as keywords, not both: {sorted(keywords)}")
    options = AnalysisOptions(**keywords) if options is None else options
    usable, failed, closing = validate_measurements(measurements, with_closing=True)
    options = options.for_data(float(np.max(np.abs(usable["torque_nm"]))))
    loops = build_loops(usable, torque_correlation=options.torque_correlation, rig=options.rig)
    found = session_checks(usable, failed, closing, options)
    levels = np.unique(np.round(usable["torque_nm"].to_numpy(float) / LEVEL_TOL_NM) * LEVEL_TOL_NM)
    all_sources, _, kinds = torque_sources(usable, correlation=options.torque_correlation, rig=options.rig,
                                           return_kinds=True)
    issues, rows, phase_rows, fits, outliers = list(found.issues), [], [], {}, []
    orientation_all = usable["orientation_deg"].to_numpy(float)
    # each row's image-to-image torque 1σ, as the loops have it (a later cycle's loop also holds the image it
    # borrows from the cycle before, so the loops' arrays laid end to end are not the rows)
    common = usable["torque_common_std_nm"].to_numpy(float) if "torque_common_std_nm" in usable else None
    local_all = local_torque_std(usable["torque_std_nm"].to_numpy(float), common)
    for orient, seq in usable.groupby("orientation_deg", sort=True):
        in_orientation = [lp for lp in loops if lp.orientation_deg == float(orient)]
        context = {
            "seq": seq.reset_index(drop=True),
            "local_std": local_all[orientation_all == orient],
            "sources": all_sources[orientation_all == orient],
            "kinds": kinds,
            "levels": levels,
        }
        for lp in in_orientation:
            families, phases, fits[(lp.orientation_deg, lp.cycle)], found_out = _analyze_loop(
                lp, found, options, seed=options.seed + loops.index(lp), **context)
            for family in families:
                rows.extend(family.rows)
                issues.extend(family.issues)
            phase_rows.extend(phases)
            outliers.extend(found_out[1])
            issues.extend(found_out[0])
    figures = pd.DataFrame(rows, columns=FIGURE_COLUMNS)
    figures = figures[figures["figure"] != "*"].reset_index(drop=True)
    summary, per_orientation = summarise_figures(figures)
    _output_side(summary, options)
    return SessionAnalysis(
        figures=figures,
        loops=_wide(figures),
        phases=pd.DataFrame(phase_rows),
        summary=summary,
        per_orientation=per_orientation,
        issues=issues,
        failed_images=failed,
        settings=options.settings(),
        loop_data=loops,
        fits=fits,
        n_images=int(len(measurements)),
        checks=found.to_dict(outliers),
    )


def _analyze_loop(loop: Loop, found: SessionChecks, options: AnalysisOptions, *, seed: int, seq, local_std,
                  sources, kinds, levels):
    """The figure families of one loop: ``(families' FigureRows, phase rows, fits, (outlier issues, rows))``."""
    why = found.withheld(loop.orientation_deg)
    if why is not None:
        withheld = FigureRows(loop)
        withheld.fail("*", "", why)
        return [withheld], [], no_fits(), ([], [])
    phases, phase_rows = phase_figures(loop, seq, local_std=local_std, sources=sources, kinds=kinds, levels=levels)
    problem = _loop_problem(loop)
    if problem is not None:
        missing = FigureRows(loop)
        for name, unit in {**loop_figure_units(options), **CATALOGUE_UNITS, **BILINEAR_UNITS}.items():
            missing.add(name, unit, np.nan)
        missing.issues.append(Issue(loop.orientation_deg, loop.cycle, "loop figures", problem))
        families, fits, out = [phases, missing], no_fits(), ([], [])
    else:
        models, fits = model_figures(loop, options)
        whole, secants = loop_figures(loop, options, seed=seed, levels=levels)
        for name, (std_torque, parts, method, draws) in secants.items():
            phases.set_torque_part(name, std_torque, parts, method, draws)
        families = [phases, models, whole, catalogue_figures(loop, options)]
        out = outlier_issues(loop, fits)
    for family in families:
        found.mark(family)
    return families, phase_rows, fits, out


#: Caveat of the output-side conversion.
OUTPUT_SIDE_CAVEAT = (
    "K_out = i²·K_in refers the input-side stiffness to the output through an ideal transmission "
    "(θ_in = i·θ_out, τ_out = i·τ_in, no loss). Friction and efficiency losses, and any compliance between the "
    "measured shaft and the gear, make the real output-side stiffness differ; measure at the output to be sure."
)


def _output_side(summary: dict, options: AnalysisOptions) -> None:
    i = options.gear_ratio
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
