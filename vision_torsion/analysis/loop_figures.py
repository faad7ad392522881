"""Figure family: the figures of a whole loop, with their uncertainty by Monte Carlo — hysteresis
(largest width) and hysteresis loss (width at zero torque), lost motion at ``±x·T_R``, the
secant stiffness, the loop energy and the loss factor.

Each torque error is drawn as the data would show it: on the torque axis of the image and,
at the loop's tips, on the loop's amplitude (:func:`.uncertainty.tip_amplitude_response`);
the same draws give the torque part of the phase secants (:mod:`.phase_figures`). The
loop energy is ``∮τ dθ`` of the continuous loop, estimated from the polygon through the
measured levels and corrected by :func:`.metrics.chord_area`; lost motion between levels
is corrected by :func:`.metrics.chord_error`; the bounds of both corrections are the
figures' sampling terms. Nothing is interpolated across a failed image; a figure whose
sampling term cannot be bounded is withheld; a loop running clockwise has its width and
energy figures withheld (:func:`.checks.loop_direction`); a largest width that is a
maximum over a flat top is flagged (:func:`.checks.flat_top`).
"""

from __future__ import annotations

import math

import numpy as np

from . import checks, metrics
from .loops import Loop
from .parameters import AnalysisOptions
from .rows import LEVEL_TOL_NM as _TOL
from .rows import FigureRows, Issue
from .uncertainty import monte_carlo_std, tip_amplitude_response

__all__ = ["loop_figures", "loop_figure_units"]


def _lm_name(fraction: float) -> str:
    return f"lost_motion_{round(100 * fraction, 6):g}pct".replace(".", "p")


def _mc_evaluator(is_desc, top, bottom, options, tol=_TOL):
    sec_lo, sec_hi = options.secant_interval_nm
    lm_ref = options.lost_motion_reference_nm

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
        for f in options.lost_motion_fractions:
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


def _sampling_bounds(tau, th, is_desc, options) -> dict:
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
    for f in options.lost_motion_fractions:
        x = f * options.lost_motion_reference_nm
        half = sum(float(metrics.chord_error(xb, fb, sgn * x)[1][0]) for xb, fb in ((xd, fd), (xa, fa))
                   for sgn in (1, -1))
        out[_lm_name(f)] = math.degrees(0.5 * half)
    return out


def _unbounded_reasons(nominal, sampling, tau, options) -> dict:
    """Why a loop figure's sampling term cannot be bounded (figure → reason): the bound needs a measured
    neighbour segment beside the one that holds the evaluation torque, and a lost motion whose interpolation
    bound exceeds the figure itself is not determined by the levels measured."""
    out = {}
    lv = np.unique(np.abs(tau))
    for name in ("loop_energy", "loss_factor"):
        if not np.isfinite(sampling.get(name, np.nan)):
            out[name] = ("a branch has a segment between measured levels with no measured neighbour to bound the "
                         "continuous loop's area there: withheld")
    for f in options.lost_motion_fractions:
        name, x = _lm_name(f), f * options.lost_motion_reference_nm
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
#: the phase's own, :mod:`.phase_figures`).
_PHASE_SECANTS = (
    "k_positive_unloading_secant",
    "k_negative_loading_secant",
    "k_negative_unloading_secant",
    "k_positive_loading_secant",
)


def loop_figure_units(options: AnalysisOptions) -> dict:
    """The figures of this family, name → unit (one lost motion per fraction of the options)."""
    units = {
        "hysteresis": "deg",
        "hysteresis_loss": "deg",
        "secant_stiffness": "nm_per_rad",
        "loop_energy": "j",
        "loss_factor": "1",
    }
    units.update({_lm_name(f): "deg" for f in options.lost_motion_fractions})
    return units


def _gap_reasons(options, tau, is_desc, levels) -> dict:
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
    lo, hi = options.secant_interval_nm
    point("secant_stiffness", [("ascending", lo), ("ascending", hi), ("descending", -lo), ("descending", -hi)])
    for f in options.lost_motion_fractions:
        x = f * options.lost_motion_reference_nm
        point(_lm_name(f), [("descending", x), ("descending", -x), ("ascending", x), ("ascending", -x)])
    return out


def loop_figures(loop: Loop, options: AnalysisOptions, *, seed: int, levels: np.ndarray):
    """The loop's figures (:func:`loop_figure_units`) with their Monte Carlo uncertainties.

    Parameters
    ----------
    loop : Loop
        A closed loop (every phase measured, the torque reversing sign).
    options : AnalysisOptions
        After :meth:`~.parameters.AnalysisOptions.for_data` (the secant interval and the
        lost-motion reference in N·m, the draws).
    seed : int
        Seed of this loop's draws.
    levels : numpy.ndarray
        The session's nominal torque levels (N·m), to tell a gap left by a failed image.

    Returns
    -------
    rows : FigureRows
        The figures and their issues.
    secant_torque_parts : dict
        ``{k_<phase>_secant: (std_torque, parts by kind, method, draws)}``: the torque part of each
        phase secant as the loop's draws carry it (for :meth:`.rows.FigureRows.set_torque_part`).
    """
    col = FigureRows(loop)
    tau, th, th_std, tau_std, groups, is_desc, sources = loop.runs()
    top = groups == groups[np.argmax(tau)]
    bottom = groups == groups[np.argmin(tau)]
    evaluate = _mc_evaluator(is_desc, top, bottom, options)
    nominal = evaluate(tau[None, :], th[None, :])
    kinds = loop.source_kinds if loop.source_kinds is not None else np.array(["level"] * sources.shape[1], object)
    # a draw that moves the torque axis may put an edge level a hair inside an evaluation torque: allow half a
    # step of extrapolation for the draws (the nominal value itself is never extrapolated)
    gaps_ = np.diff(np.unique(tau))
    evaluate_mc = _mc_evaluator(is_desc, top, bottom, options, tol=0.5 * float(gaps_.min()) if gaps_.size else _TOL)
    std_a, std_t, by_kind = monte_carlo_std(
        evaluate_mc,
        tau,
        th,
        angle_std_rad=th_std,
        torque_sources=sources,
        n_draws=options.n_draws,
        seed=seed,
        kinds=kinds,
        torque_response=tip_amplitude_response(tau, th, is_desc),
    )
    method = "monte-carlo (torque errors with the loop's amplitude)"
    gaps = _gap_reasons(options, tau, is_desc, levels)
    sampling = _sampling_bounds(tau, th, is_desc, options)
    gaps.update({k: v for k, v in _unbounded_reasons(nominal, sampling, tau, options).items() if k not in gaps})
    secants = {name: (std_t[name], by_kind[name], f"first-order (two ends); torque part {method}", options.n_draws)
               for name in _PHASE_SECANTS if np.isfinite(std_t.get(name, np.nan))}
    flat = checks.flat_top(tau[is_desc], th[is_desc], th_std[is_desc], tau[~is_desc], th[~is_desc], th_std[~is_desc])
    for name, unit in loop_figure_units(options).items():
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
                    draws=options.n_draws, sampling=sampling.get(name, 0.0))
        else:
            col.fail(name, unit, _mc_reason(name, tau, options))
    _loop_direction(col, options)
    return col, secants


def _loop_direction(col: FigureRows, options: AnalysisOptions) -> None:
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
                 *(_lm_name(f) for f in options.lost_motion_fractions)}
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


def _mc_reason(name, tau, options):
    lo, hi = float(tau.min()), float(tau.max())
    if name.startswith("lost_motion"):
        return f"the lost-motion torques are not covered by both runs (torque {lo:.4g} to {hi:.4g} N·m)"
    if name == "secant_stiffness":
        a, b = options.secant_interval_nm
        return f"secant interval {a:.4g} to {b:.4g} N·m is not covered by both loading branches"
    if name == "hysteresis_loss":
        return "zero torque is not covered by both runs"
    return f"the two runs do not overlap in torque or the loop is degenerate (torque {lo:.4g} to {hi:.4g} N·m)"
