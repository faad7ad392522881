"""Checks on the data of a session, and the issues they raise: images that failed, the rig
against the table (:func:`_rig_issues`), the angle sign per orientation and run (an inverted
sign withholds every figure with the advice to set ``angle_sign = -1``; one orientation
whose sign alone is inverted is named and its figures withheld), loop closure and creep
(the ``closing`` image; every figure of that orientation is flagged), a torque-error model
that was not declared (every figure flagged), and points far off their loop's model
(listed by image, judged by a fit that does not include them). See :mod:`.checks` for the
tests themselves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import special

from ..errors import AnalysisError
from . import checks
from .fitcheck import LACK_OF_FIT_ALPHA, side_compliance, spike_scores
from .model_figures import bilinear_jacobian
from .models import fit_bilinear
from .parameters import AnalysisOptions
from .preisach import fit_preisach, torque_sensitivity
from .rows import CREEP_FLAG, TORQUE_NOT_MODELLED, FigureRows, Issue
from .uncertainty import least_squares_weights, torque_sources

__all__ = ["SessionChecks", "session_checks", "outlier_issues"]


@dataclass(frozen=True)
class SessionChecks:
    """What the checks of a session found, before any figure is computed (:func:`session_checks`).

    Attributes
    ----------
    issues : list of Issue
        Session-wide and per-orientation issues, in the order found.
    inverted : bool
        The whole session's angle sign is inverted: every figure is withheld.
    wrong_sign : dict
        ``{orientation_deg: why}`` of the orientations whose sign alone is inverted (their figures withheld).
    creep : dict
        ``{orientation_deg: [closure comparisons]}`` of the orientations with a creep/closure finding (every
        figure of the orientation flagged).
    signs, closure : list
        :func:`.checks.angle_sign_by_run` and :func:`.checks.closure_checks`.
    torque_modelled : bool
        False when the torques' error model is missing (every figure flagged).
    """

    issues: list
    inverted: bool
    wrong_sign: dict
    creep: dict
    signs: list
    closure: list
    torque_modelled: bool = True

    def withheld(self, orientation_deg: float) -> str | None:
        """Why every figure of the orientation is withheld (its angle sign), or None."""
        if self.inverted or float(orientation_deg) in self.wrong_sign:
            return self.wrong_sign.get(float(orientation_deg),
                                       "angle_sign looks inverted (set angle_sign = -1): figures withheld")
        return None

    def mark(self, rows: FigureRows) -> None:
        """Flag every shown figure of `rows` that a finding of its orientation invalidates (creep; no torque
        model), beside any flag of its own."""
        flags = []
        if float(rows.loop.orientation_deg) in self.creep:
            flags.append(CREEP_FLAG)
        if not self.torque_modelled:
            flags.append("flagged: " + TORQUE_NOT_MODELLED)
        for r in rows.rows:
            for flag in flags:
                if np.isfinite(r["value"]) and flag not in r["flag"]:
                    r["flag"] = "; ".join(x for x in (r["flag"], flag) if x)

    def to_dict(self, outliers: list) -> dict:
        """The ``checks`` of :class:`.session.SessionAnalysis`, with the `outliers` found in the loops
        (:func:`outlier_issues`)."""
        return {"angle_sign_inverted": bool(self.inverted), "angle_sign_inverted_orientations": sorted(self.wrong_sign),
                "angle_sign": self.signs, "closure": self.closure, "outliers": outliers}


def session_checks(usable: pd.DataFrame, failed: pd.DataFrame, closing: pd.DataFrame,
                   options: AnalysisOptions) -> SessionChecks:
    """Check a session's data before its figures: the torque model, the rig, failed images, the angle sign,
    loop closure and creep.

    Parameters
    ----------
    usable, failed, closing : pandas.DataFrame
        The table split by :func:`.loops.validate_measurements`.
    options : AnalysisOptions
        The analysis options (the rig and the torque model).

    Returns
    -------
    SessionChecks
    """
    issues = []
    if not options.torque_modelled:
        issues.append(Issue(None, None, "torque uncertainty", TORQUE_NOT_MODELLED, kind="flagged"))
    if options.torque_correlation == "pieces":
        issues.extend(_rig_issues(usable, options.rig))
    for r in failed.itertuples(index=False):
        orient = float(r.orientation_deg) if np.isfinite(r.orientation_deg) else None
        cycle = int(r.cycle) if np.isfinite(r.cycle) else None
        issues.append(Issue(orient, cycle, "*", f"image {r.image} ({r.phase}, step {r.step}) excluded: {r.message}"))
    signs = checks.angle_sign_by_run(usable)
    inverted = checks.angle_sign_inverted(usable["torque_nm"], usable["angle_deg"]) and all(
        len(sg["falls"]) == len(checks.RUNS) for sg in signs)
    wrong_sign = {} if inverted else _sign_issues(signs, issues)
    if inverted:
        issues.append(Issue(None, None, "angle sign",
                            "angle_sign looks inverted; set angle_sign = -1 in session.toml (the angle falls as the "
                            "torque rises; or multiply angle_deg by -1). Every figure is withheld until then."))
    closure = checks.closure_checks(usable, closing)
    creep = {}
    for c in closure:
        if c["creep"]:
            creep.setdefault(c["orientation_deg"], []).append(c)
            issues.append(Issue(c["orientation_deg"], None, "creep",
                                f"{c['check']}: the angle moved by {c['difference_deg']:+.4g}° ({c['z']:+.1f}σ; "
                                f"{c['image_first']} → {c['image_last']}): creep or a disturbed rig"))
    return SessionChecks(issues=issues, inverted=bool(inverted), wrong_sign=wrong_sign, creep=creep, signs=signs,
                         closure=closure, torque_modelled=options.torque_modelled)


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
        jacobian=bilinear_jacobian(bil, tau),
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


def outlier_issues(loop, fits: dict) -> tuple[list, list]:
    """The images of `loop` far off its model (see :func:`_outliers_found`), judged by the loop's `fits`
    (:func:`.model_figures.model_figures`).

    Returns
    -------
    issues : list of Issue
        One ``"outlier"`` issue per image, naming it and its score.
    rows : list of dict
        ``orientation_deg, cycle, image, z`` per image (the ``outliers`` of the checks).
    """
    found, name = _outliers_found(loop, fits)
    issues = [
        Issue(
            loop.orientation_deg,
            loop.cycle,
            "outlier",
            f"image {image} is {z:+.1f}σ off the loop's model ({name}, as a lone spike): a forgotten or extra "
            "weight, or a missed or extra shot? Check the image and its weights, re-take it or mark it failed",
        )
        for image, z in found
    ]
    rows = [{"orientation_deg": loop.orientation_deg, "cycle": loop.cycle, "image": image, "z": z}
            for image, z in found]
    return issues, rows
