"""``analyze_session``: every figure of every loop of a session, with uncertainties,
summaries, and a list of what could not be computed and why.

Figures (``figure`` name → unit; see :mod:`.metrics` and :mod:`.models` for the
definitions):

==================================  ============  ====================================
figure                              unit          method of the uncertainty
==================================  ============  ====================================
k_positive_unloading, ...           nm_per_rad    first order (slope), per phase
hysteresis, hysteresis_loss         deg           Monte Carlo
lost_motion_3pct, lost_motion_4pct  deg           Monte Carlo
secant_stiffness                    nm_per_rad    Monte Carlo
loop_energy                         j             Monte Carlo
loss_factor                         1             Monte Carlo
k1, k2, k3 / t1, t2                 nm_per_rad/nm first order (piecewise-linear fit)
bilinear_k_u, bilinear_k_l          nm_per_rad    first order (fit)
bilinear_tau_c                      nm            first order (fit)
bilinear_residual_rms               deg           (none: a fit statistic)
bouc_wen_k_e, bouc_wen_z_s, ...     various       first order (fit)
==================================  ============  ====================================

Torque errors follow the weight pieces when the rig is known (``rig=...``,
``torque_correlation="pieces"``), else one shared error per torque level
(``"level"``); see :mod:`.uncertainty` for both models and the propagation formulas.

A figure that cannot be computed is NaN in the tables and None in JSON, and an
:class:`Issue` says which orientation/cycle and why; it is never replaced by 0.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
import pandas as pd

from ..errors import AnalysisError
from . import metrics
from .loops import LOOP_PHASES, Loop, build_loops, validate_measurements
from .models import BilinearFit, BoucWenFit, fit_bilinear, fit_bouc_wen
from .summary import summarise_figures
from .uncertainty import COVERAGE_FACTOR, check_rig, compact_sources, monte_carlo_std, torque_sources

__all__ = ["Issue", "SessionAnalysis", "analyze_session", "SUMMARY_SCHEMA"]

#: Identifies the layout of :meth:`SessionAnalysis.to_dict` (summary.json).
SUMMARY_SCHEMA = "vision-torsion/analysis-summary/1"

_RAD_TO_ARCMIN = 180.0 * 60.0 / math.pi
_MC_FIGURES = {
    "hysteresis": "deg", "hysteresis_loss": "deg", "lost_motion_3pct": "deg", "lost_motion_4pct": "deg",
    "secant_stiffness": "nm_per_rad", "loop_energy": "j", "loss_factor": "1",
}
_MIN_PHASE_POINTS_FOR_LOOP = 2


@dataclass(frozen=True)
class Issue:
    """A figure that could not be computed (or is doubtful) for an orientation/cycle.

    ``orientation_deg``/``cycle`` are None for session-wide issues; ``figure`` is a
    figure name or ``"*"`` for all figures of that loop.
    """

    orientation_deg: float | None
    cycle: int | None
    figure: str
    reason: str

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
        ``{(orientation_deg, cycle): {"bilinear": BilinearFit | None, "bouc_wen": BoucWenFit | None}}``.
    n_images : int
        Rows of the input table (including reference and failed images).
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

    def to_dict(self) -> dict:
        """JSON-ready dict (the content of summary.json); keys documented in the README.

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
                "u95": "expanded uncertainty = coverage_factor * std",
                "torque_correlation": self.settings.get("torque_correlation"),
                "rig": self.settings.get("rig"),
                "monte_carlo_draws": self.settings.get("n_draws"),
                "seed": self.settings.get("seed"),
            },
            "summary": self.summary,
            "per_orientation": _records(self.per_orientation),
            "loops": _records(self.loops),
            "phases": _records(self.phases),
            "issues": [asdict(i) for i in self.issues],
            "failed_images": _records(self.failed_images),
        }


def _records(frame: pd.DataFrame) -> list:
    return [
        {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in r.items()}
        for r in frame.to_dict(orient="records")
    ]


class _Collector:
    """Accumulates figure rows and issues of one loop."""

    def __init__(self, loop: Loop, issues: list):
        self.loop, self.issues, self.rows = loop, issues, []

    def add(self, figure, unit, value, std_angle=np.nan, std_torque=np.nan, method=""):
        std = float(np.hypot(std_angle, std_torque))
        self.rows.append(
            {
                "orientation_deg": self.loop.orientation_deg,
                "cycle": self.loop.cycle,
                "figure": figure,
                "unit": unit,
                "value": float(value),
                "std": std,
                "std_angle": float(std_angle),
                "std_torque": float(std_torque),
                "u95": COVERAGE_FACTOR * std,
                "method": method,
            }
        )

    def fail(self, figure, unit, reason):
        self.add(figure, unit, np.nan)
        self.issues.append(Issue(self.loop.orientation_deg, self.loop.cycle, figure, reason))


def _tolerance(tau: np.ndarray) -> float:
    levels = np.unique(tau)
    gaps = np.diff(levels)
    return 0.5 * float(gaps.min()) if gaps.size else 0.0


def _phase_figures(col: _Collector, phase_rows: list):
    loop = col.loop
    for phase in LOOP_PHASES:
        m = loop.phase == phase
        name = f"k_{phase}"
        tau = loop.torque_nm[m]
        row = {
            "orientation_deg": loop.orientation_deg,
            "cycle": loop.cycle,
            "phase": phase,
            "torque_from_nm": float(tau[0]) if tau.size else np.nan,
            "torque_to_nm": float(tau[-1]) if tau.size else np.nan,
            "n_points": int(m.sum()),
        }
        if not m.any():
            col.fail(name, "nm_per_rad", f"phase {phase} is missing (no usable image)")
            res = None
        else:
            try:
                res = metrics.phase_stiffness(
                    tau,
                    loop.angle_rad[m],
                    angle_std_rad=loop.angle_std_rad[m],
                    torque_std_nm=loop.torque_std_nm[m],
                    torque_sources=loop.sources()[m],
                )
            except AnalysisError as exc:
                col.fail(name, "nm_per_rad", f"phase {phase}: {exc}")
                res = None
        if res is not None:
            col.add(name, "nm_per_rad", res["value"], res["std_angle"], res["std_torque"], "first-order")
            std = math.hypot(res["std_angle"], res["std_torque"])
            row.update(
                stiffness_nm_per_rad=res["value"],
                stiffness_std_nm_per_rad=std,
                residual_rms_deg=math.degrees(res["residual_rms_rad"]),
            )
        else:
            row.update(stiffness_nm_per_rad=np.nan, stiffness_std_nm_per_rad=np.nan, residual_rms_deg=np.nan)
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
        return (f"too few usable images in phase(s) {', '.join(few)}: the loop needs at least "
                f"{_MIN_PHASE_POINTS_FOR_LOOP} per phase")
    lo, hi = float(loop.torque_nm.min()), float(loop.torque_nm.max())
    if not (lo < 0 < hi):
        return f"torque never reverses sign in this cycle (range {lo:.4g} to {hi:.4g} N·m): there is no loop"
    return None


def _mc_evaluator(is_desc, top, bottom, max_torque, settings, tol):
    fr_lo, fr_hi = settings["secant_interval"]
    lm = settings["lost_motion_fractions"]

    def evaluate(tau, th):
        td, yd, ta, ya = tau[:, is_desc], th[:, is_desc], tau[:, ~is_desc], th[:, ~is_desc]
        hyst, loss = metrics.loop_width(td, yd, ta, ya, tol=tol)
        energy = metrics.loop_energy(tau, th)
        out = {
            "hysteresis": np.degrees(hyst),
            "hysteresis_loss": np.degrees(loss),
            "secant_stiffness": metrics.secant_stiffness(
                td, yd, ta, ya, lower_nm=fr_lo * max_torque, upper_nm=fr_hi * max_torque, tol=tol
            ),
            "loop_energy": energy,
            "loss_factor": metrics.loss_factor(
                energy, tau[:, top].mean(1), th[:, top].mean(1), tau[:, bottom].mean(1), th[:, bottom].mean(1)
            ),
        }
        for name, f in zip(("lost_motion_3pct", "lost_motion_4pct"), lm):
            out[name] = np.degrees(metrics.lost_motion(td, yd, ta, ya, torque_nm=f * max_torque, tol=tol))
        return out

    return evaluate


def _model_free_figures(col: _Collector, settings: dict, max_torque: float, seed: int):
    loop = col.loop
    tau, th, th_std, tau_std, groups, is_desc, sources = loop.runs()
    top = groups == groups[np.argmax(tau)]
    bottom = groups == groups[np.argmin(tau)]
    tol = _tolerance(tau)
    evaluate = _mc_evaluator(is_desc, top, bottom, max_torque, settings, tol)
    nominal = evaluate(tau[None, :], th[None, :])
    std_a, std_t = monte_carlo_std(
        evaluate, tau, th, angle_std_rad=th_std, torque_sources=sources, n_draws=settings["n_draws"], seed=seed
    )
    for name, unit in _MC_FIGURES.items():
        v = float(nominal[name][0])
        if np.isfinite(v):
            col.add(name, unit, v, std_a[name], std_t[name], "monte-carlo")
        else:
            col.fail(name, unit, _mc_reason(name, tau, settings, max_torque))
    seg_mask = (is_desc & (tau <= 0)) | (~is_desc & (tau >= 0))
    try:
        seg = metrics.fit_three_segment(
            tau[seg_mask],
            th[seg_mask],
            branch=np.where(is_desc[seg_mask], -1, 1),
            angle_std_rad=th_std[seg_mask],
            torque_sources=compact_sources(sources[seg_mask]),
        )
    except AnalysisError as exc:
        for name, unit in (
            ("k1", "nm_per_rad"),
            ("k2", "nm_per_rad"),
            ("k3", "nm_per_rad"),
            ("t1", "nm"),
            ("t2", "nm"),
        ):
            col.fail(name, unit, str(exc))
        return
    for name, unit in (("k1", "nm_per_rad"), ("k2", "nm_per_rad"), ("k3", "nm_per_rad"), ("t1", "nm"), ("t2", "nm")):
        col.add(name, unit, seg[name], seg["std_angle"][name], seg["std_torque"][name], "first-order")
    for brk, (ka, kb) in (("t1", ("K1", "K2")), ("t2", ("K2", "K3"))):
        b_std = math.hypot(seg["std_angle"][brk], seg["std_torque"][brk])
        if not b_std < 0.1 * max_torque:
            col.issues.append(
                Issue(
                    loop.orientation_deg,
                    loop.cycle,
                    brk,
                    f"break torque {brk.upper()} is poorly identified (1σ = {b_std:.3g} N·m, more "
                    f"than 10 % of the max torque): {ka} and {kb} hardly differ, so the loading "
                    "branch is closer to two segments than three",
                )
            )


def _mc_reason(name, tau, settings, max_torque):
    lo, hi = float(tau.min()), float(tau.max())
    if name.startswith("lost_motion"):
        f = settings["lost_motion_fractions"][0 if "3pct" in name else 1]
        return f"±{f * max_torque:.4g} N·m is not covered by both runs (torque {lo:.4g} to {hi:.4g} N·m)"
    if name == "secant_stiffness":
        a, b = settings["secant_interval"]
        return (
            f"secant interval {a * max_torque:.4g} to {b * max_torque:.4g} N·m is not covered by both loading branches"
        )
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


def _model_fits(col: _Collector, settings: dict) -> dict:
    loop = col.loop
    kw = dict(angle_std_rad=loop.angle_std_rad, torque_sources=loop.sources())
    out = {"bilinear": None, "bouc_wen": None}
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
        for name, attr, unit in (
            ("k_u", "k_u_nm_per_rad", "nm_per_rad"),
            ("k_l", "k_l_nm_per_rad", "nm_per_rad"),
            ("tau_c", "tau_c_nm", "nm"),
        ):
            col.add(
                f"bilinear_{name}", unit, getattr(bil, attr), bil.std_angle[name], bil.std_torque[name], "first-order"
            )
        col.add("bilinear_residual_rms", "deg", math.degrees(bil.residual_rms_rad), method="fit statistic")
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
    for name, (unit, scale) in _BW_UNITS.items():
        col.add(
            f"bouc_wen_{name}",
            unit,
            bw.params[name] * scale,
            bw.std_angle[name] * scale,
            bw.std_torque[name] * scale,
            "first-order",
        )
    col.add("bouc_wen_residual_rms", "deg", math.degrees(bw.residual_rms_rad), method="fit statistic")
    return out


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


def analyze_session(
    measurements,
    *,
    max_torque_nm=None,
    torque_correlation=None,
    rig=None,
    lost_motion_fractions=(0.03, 0.04),
    secant_interval=(0.5, 1.0),
    n_draws=400,
    seed=0,
    fit_bouc_wen=True,
) -> SessionAnalysis:
    """Analyse the torque–angle table of a session: every figure of every loop.

    Parameters
    ----------
    measurements : pandas.DataFrame
        The ``measurements.csv`` table (see :data:`.loops.REQUIRED_COLUMNS`). Only
        ``status == "ok"`` rows are used; the others are listed as failed images.
    max_torque_nm : float, optional
        Rated/maximum torque for lost motion and the secant interval, N·m. Default:
        the largest ``|torque_nm|`` of the usable loop images.
    torque_correlation : {"pieces", "level", "independent"}, optional
        Error model of the torques (see :mod:`.uncertainty`). Default: ``"pieces"``
        when ``rig`` is given, else ``"level"``.
    rig : TorqueRig or mapping, optional
        Rig constants for the ``"pieces"`` model
        (:class:`vision_torsion.measurements.TorqueRig`, e.g. a session's
        ``config.torque_rig``, or a mapping of its constants): ``step_mass_kg`` (one
        weight piece, kg), ``mass_std_kg`` (1σ of one piece, kg), ``gravity_m_per_s2``,
        ``arm_radius_m`` (m) and optionally ``friction_torque_std_nm`` (1σ per image,
        N·m), ``arm_radius_std_m``, ``gravity_std_m_per_s2`` (see
        :func:`.uncertainty.check_rig`). The pieces per pan of an image are
        ``mass_kg / step_mass_kg`` (:func:`.uncertainty.pieces_per_pan`), the sign
        that of its phase.
    lost_motion_fractions : (float, float)
        Fractions of ``max_torque_nm`` for the two lost-motion figures (3 % and 4 %).
    secant_interval : (float, float)
        Secant stiffness interval as fractions of ``max_torque_nm``.
    n_draws : int
        Monte Carlo draws per error source and loop.
    seed : int
        Base seed; loop ``i`` uses ``seed + i``.
    fit_bouc_wen : bool
        Fit the Bouc–Wen model too (the slowest part, ≈0.1–0.5 s per loop).

    Returns
    -------
    SessionAnalysis

    Raises
    ------
    AnalysisError
        Invalid table (see :func:`.loops.validate_measurements`) or invalid options
        (``"pieces"`` without a rig, an invalid rig, a non-numeric ``mass_kg``).
        Problems of single loops are not raised but listed in ``issues``; so is a
        table whose ``torque_std_nm`` or ``mass_kg`` disagrees with the rig.

    Notes
    -----
    Torque errors are propagated with all their correlations: the loading matrix
    ``L`` of :func:`.uncertainty.torque_sources` (``δτ = L·ξ``) goes into the Monte
    Carlo draws and into the first-order covariance of every slope and fit
    (``cov_τ = (G·J_τ·L)(G·J_τ·L)ᵀ``, :mod:`.uncertainty`).

    Examples
    --------
    >>> import numpy as np
    >>> from vision_torsion.analysis import simulate_measurements
    >>> df = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, orientations_deg=(0,), torque_model="pieces",
    ...                            rng=np.random.default_rng(1))
    >>> rig = dict(step_mass_kg=0.02, mass_std_kg=1e-4, gravity_m_per_s2=9.81, arm_radius_m=0.05)
    >>> a = analyze_session(df, rig=rig, n_draws=50, fit_bouc_wen=False)
    >>> a.settings["torque_correlation"], abs(a.summary["bilinear_k_u"]["mean"] / 4.4 - 1) < 0.01
    ('pieces', True)
    """
    if n_draws < 10:
        raise AnalysisError(f"n_draws must be at least 10, got {n_draws}")
    if not (0 <= secant_interval[0] < secant_interval[1] <= 1):
        raise AnalysisError(
            f"secant_interval must be fractions 0 <= a < b <= 1 of the max torque, got {secant_interval}"
        )
    if len(lost_motion_fractions) != 2 or not all(0 < f < 1 for f in lost_motion_fractions):
        raise AnalysisError(f"lost_motion_fractions must be two fractions in (0, 1), got {lost_motion_fractions}")
    if torque_correlation is None:
        torque_correlation = "level" if rig is None else "pieces"
    if rig is not None:
        rig = check_rig(rig)
    usable, failed = validate_measurements(measurements)
    loops = build_loops(usable, torque_correlation=torque_correlation, rig=rig)
    data_max = float(np.max(np.abs(usable["torque_nm"])))
    if max_torque_nm is None:
        max_torque_nm = data_max
    elif not (np.isfinite(max_torque_nm) and max_torque_nm > 0):
        raise AnalysisError(f"max_torque_nm must be a positive torque (N·m), got {max_torque_nm!r}")
    settings = {
        "max_torque_nm": float(max_torque_nm),
        "torque_correlation": torque_correlation,
        "lost_motion_fractions": [float(f) for f in lost_motion_fractions],
        "secant_interval": [float(f) for f in secant_interval],
        "n_draws": int(n_draws),
        "seed": int(seed),
        "fit_bouc_wen": bool(fit_bouc_wen),
        "coverage_factor": COVERAGE_FACTOR,
        "rig": None if rig is None else rig.to_dict(),
    }
    issues: list[Issue] = []
    if torque_correlation == "pieces":
        issues.extend(_rig_issues(usable, rig))
    for r in failed.itertuples(index=False):
        orient = float(r.orientation_deg) if np.isfinite(r.orientation_deg) else None
        cycle = int(r.cycle) if np.isfinite(r.cycle) else None
        issues.append(Issue(orient, cycle, "*", f"image {r.image} ({r.phase}, step {r.step}) excluded: {r.message}"))
    rows, phase_rows, fits = [], [], {}
    for i, loop in enumerate(loops):
        col = _Collector(loop, issues)
        _phase_figures(col, phase_rows)
        problem = _loop_problem(loop)
        if problem is None:
            _model_free_figures(col, settings, float(max_torque_nm), seed + i)
            fits[(loop.orientation_deg, loop.cycle)] = _model_fits(col, settings)
        else:
            for name, unit in {
                **_MC_FIGURES,
                "k1": "nm_per_rad",
                "k2": "nm_per_rad",
                "k3": "nm_per_rad",
                "t1": "nm",
                "t2": "nm",
                "bilinear_k_u": "nm_per_rad",
                "bilinear_k_l": "nm_per_rad",
                "bilinear_tau_c": "nm",
            }.items():
                col.add(name, unit, np.nan)
            issues.append(Issue(loop.orientation_deg, loop.cycle, "loop figures", problem))
            fits[(loop.orientation_deg, loop.cycle)] = {"bilinear": None, "bouc_wen": None}
        rows.extend(col.rows)
    figures = pd.DataFrame(
        rows,
        columns=[
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
        ],
    )
    summary, per_orientation = summarise_figures(figures)
    return SessionAnalysis(
        figures=figures,
        loops=_wide(figures),
        phases=pd.DataFrame(phase_rows),
        summary=summary,
        per_orientation=per_orientation,
        issues=issues,
        failed_images=failed,
        settings=settings,
        loop_data=loops,
        fits=fits,
        n_images=int(len(measurements)),
    )
