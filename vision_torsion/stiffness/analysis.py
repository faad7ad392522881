"""One call from a torque-angle record to the stiffness curve, dead zone and meshing pairs.

Steps (each a public function of its own module):

1. read the record (:func:`~.records.read_record`; encoder output angle
   theta_out = theta_in/i − T/K_sensor);
2. zero-phase Butterworth low-pass (:func:`~.filtering.filter_record`; encoder
   records only);
3. split into branches on the filtered signals (:func:`~.branches.split_branches`);
4. fit each loading branch on its **unfiltered** samples past first contact
   (:func:`~.curve.fit_loading_branch`; cycles pooled), and sample K(T) with its band;
5. the dead zone from the two loading fits (:func:`~.backlash.detect_backlash`);
6. meshing pairs n = K/Ks and wrap angle 2·pi·n/z (:mod:`~.meshing`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import AnalysisError, RecordError, RigError
from .backlash import Backlash, detect_backlash, summarise_backlash
from .branches import LOADING_KINDS, BranchSplit, robust_noise_std, split_branches, zero_band
from .curve import BranchFit, StiffnessCurve, fit_loading_branch, stiffness_curve, summarise_curves
from .filtering import filter_record
from .meshing import (
    MESHING_ZONES,
    LinearityCheck,
    calibrate_tooth_stiffness,
    check_linearity,
    meshing_pairs,
    wrap_angle_rad,
)
from .records import TorqueAngleRecord, read_record, record_from_encoder, record_from_measurements
from .rig import RigConstants

__all__ = ["MeshingSummary", "StiffnessResult", "analyze_stiffness_curve", "as_record"]

log = logging.getLogger(__name__)

#: Column names of :meth:`StiffnessResult.to_frame`, units in the names. ``curve`` is
#: ``summary`` (mean over cycles), ``cycle`` (one cycle; ``cycle`` gives which) or
#: ``virgin`` (the first loading, preconditioning, cycle 0). Meshing pairs are per
#: meshing zone (module docstring of :mod:`.meshing`); both zones hold twice as many.
CURVE_COLUMNS = (
    "curve", "cycle", "n_cycles", "branch", "angle_deg", "torque_nm", "stiffness_nm_per_rad",
    "stiffness_std_nm_per_rad", "stiffness_nm_per_arcmin", "meshing_pairs_per_zone",
    "meshing_pairs_per_zone_std", "meshing_pairs_total", "wrap_angle_per_zone_rad",
)


@dataclass(frozen=True)
class MeshingSummary:
    """Meshing-teeth figures of a stiffness result.

    Attributes
    ----------
    tooth_stiffness_nm_per_rad : float
        Ks used, N·m/rad.
    tooth_stiffness_source : {"rig", "reference point"}
    teeth : int or None
        Flexspline tooth count z (None: no wrap angles).
    max_pairs_per_zone, max_pairs_per_zone_std : float
        Largest effective meshing pairs of one meshing zone over the summary
        curves, and its std (both zones together hold twice as many).
    torque_at_max_nm : float
        Torque where it occurs, N·m.
    max_wrap_angle_per_zone_rad : float or None
        2·pi·max_pairs_per_zone/z, rad: the arc one meshing zone spans.
    linearity : LinearityCheck or None
        K against independent pair counts (rig ``check_*``), if given.
    """

    tooth_stiffness_nm_per_rad: float
    tooth_stiffness_source: str
    teeth: int | None
    max_pairs_per_zone: float
    max_pairs_per_zone_std: float
    torque_at_max_nm: float
    max_wrap_angle_per_zone_rad: float | None
    linearity: LinearityCheck | None

    def to_dict(self) -> dict:
        """Plain dict; the wrap angle also in units of pi."""
        d = {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "linearity"}
        d["meshing_zones"] = MESHING_ZONES
        d["max_pairs_total"] = MESHING_ZONES * self.max_pairs_per_zone
        d["max_wrap_angle_per_zone_pi"] = (None if self.max_wrap_angle_per_zone_rad is None
                                           else self.max_wrap_angle_per_zone_rad / np.pi)
        d["linearity"] = None if self.linearity is None else self.linearity.to_dict()
        return d


@dataclass(frozen=True)
class StiffnessResult:
    """Stiffness analysis of one record.

    Attributes
    ----------
    name, source : str
        Record name and rig kind (``encoder`` or ``camera``).
    curves : tuple of StiffnessCurve
        The stiffness curve of each loading branch: the mean over the cycles
        (virgin loading excluded) at common torques, with the scatter between
        cycles in its uncertainty (:func:`~.curve.summarise_curves`).
    cycle_curves : tuple of StiffnessCurve
        One per loading branch and cycle, each fitted on its own; cycle 0 is the
        virgin loading (preconditioning), shown but never averaged in.
    fits : tuple of BranchFit
        The fits behind `cycle_curves`.
    backlash : Backlash or None
        The dead zone, mean over the cycles that have both loading branches (None
        when it could not be determined; see `notes`).
    cycle_backlash : tuple of (int, Backlash)
        The dead zone of each such cycle.
    meshing : MeshingSummary or None
        None when the rig gives no Ks (and no reference point).
    record, filtered : TorqueAngleRecord
        The record as read, and after low-pass filtering.
    split : BranchSplit
        Branch labels of the samples.
    settings : dict
        Options used.
    notes : tuple of str
        Why a part is missing.
    """

    name: str
    source: str
    curves: tuple[StiffnessCurve, ...]
    fits: tuple[BranchFit, ...]
    backlash: Backlash | None
    meshing: MeshingSummary | None
    record: TorqueAngleRecord = field(repr=False)
    filtered: TorqueAngleRecord = field(repr=False)
    split: BranchSplit = field(repr=False)
    settings: dict = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    cycle_curves: tuple[StiffnessCurve, ...] = ()
    cycle_backlash: tuple = ()

    def curve(self, kind: str) -> StiffnessCurve:
        """The stiffness curve of one loading branch.

        Raises
        ------
        AnalysisError
            The record has no such branch.
        """
        for c in self.curves:
            if c.kind == kind:
                return c
        raise AnalysisError(f"{self.name}: no {kind} branch")

    @property
    def virgin(self) -> tuple[StiffnessCurve, ...]:
        """The virgin (first) loading's curve, if the record starts with one."""
        return tuple(c for c in self.cycle_curves if self.is_virgin(c))

    def is_virgin(self, curve: StiffnessCurve) -> bool:
        """Whether `curve` is the virgin loading's (cycle 0 of an encoder record)."""
        return curve.cycle == 0 and self.source == "encoder"

    def to_frame(self) -> pd.DataFrame:
        """The stiffness curves as one table (columns :data:`CURVE_COLUMNS`): the
        summary curves, then each cycle's (the virgin loading's as ``virgin``).

        Meshing columns are NaN (empty in CSV) when Ks is unknown, and the wrap angle
        when z is unknown.
        """
        frames = []
        ks = self.meshing.tooth_stiffness_nm_per_rad if self.meshing else np.nan
        teeth = self.meshing.teeth if self.meshing else None
        for c in self.curves + self.cycle_curves:
            pairs = c.stiffness_nm_per_rad / ks
            curve = "summary" if c.cycle is None else "virgin" if self.is_virgin(c) else "cycle"
            frames.append(pd.DataFrame({
                "curve": curve,
                "cycle": pd.array([c.cycle] * len(c.torque_nm), dtype="Int64"),
                "n_cycles": c.n_cycles,
                "branch": c.kind,
                "angle_deg": c.angle_deg,
                "torque_nm": c.torque_nm,
                "stiffness_nm_per_rad": c.stiffness_nm_per_rad,
                "stiffness_std_nm_per_rad": c.stiffness_std_nm_per_rad,
                "stiffness_nm_per_arcmin": c.stiffness_nm_per_rad * np.pi / (180 * 60),
                "meshing_pairs_per_zone": pairs,
                "meshing_pairs_per_zone_std": c.stiffness_std_nm_per_rad / ks,
                "meshing_pairs_total": MESHING_ZONES * pairs,
                "wrap_angle_per_zone_rad": wrap_angle_rad(pairs, teeth=teeth) if teeth else np.nan,
            }))
        if not frames:
            return pd.DataFrame(columns=list(CURVE_COLUMNS))
        return pd.concat(frames, ignore_index=True)[list(CURVE_COLUMNS)]

    def to_dict(self) -> dict:
        """JSON-safe summary (no per-point arrays; those are in :meth:`to_frame`)."""
        def ranges(c):
            return {"torque_range_nm": [float(c.torque_nm[0]), float(c.torque_nm[-1])],
                    "stiffness_range_nm_per_rad": [float(c.stiffness_nm_per_rad.min()),
                                                   float(c.stiffness_nm_per_rad.max())]}

        branches = {c.kind: {"n_cycles": c.n_cycles, **ranges(c)} for c in self.curves}
        cycles = []
        for fit, c in zip(self.fits, self.cycle_curves):
            cycles.append({
                "cycle": fit.cycle, "virgin": self.is_virgin(c), "branch": fit.kind,
                "method": fit.method, "order": fit.order, "n_points": fit.n_points,
                "residual_std_nm": fit.residual_std_nm, **ranges(c),
            })
        return {
            "name": self.name, "source": self.source, "settings": dict(self.settings),
            "zero_torque_level_nm": self.split.level_nm,
            "zero_band_nm": self.split.threshold_nm,
            "branches": branches,
            "cycles": cycles,
            "backlash": None if self.backlash is None else self.backlash.to_dict(),
            "cycle_backlash": [{"cycle": k, **b.to_dict()} for k, b in self.cycle_backlash],
            "meshing": None if self.meshing is None else self.meshing.to_dict(),
            "notes": list(self.notes),
        }


def as_record(data, *, rig: RigConstants | None = None) -> TorqueAngleRecord:
    """A record from a path, a DataFrame (either rig's table) or a record.

    Raises
    ------
    RecordError, RigError
        As :func:`~.records.read_record`.
    """
    if isinstance(data, TorqueAngleRecord):
        return data
    if isinstance(data, pd.DataFrame):
        if {"phase", "status"} <= set(data.columns):
            return record_from_measurements(data)
        if rig is None:
            raise RigError("an encoder record needs rig constants (rig=...)")
        return record_from_encoder(data, rig=rig)
    if isinstance(data, (str, Path)):
        return read_record(data, rig=rig)
    raise AnalysisError(f"cannot analyse a {type(data).__name__}; give a path, DataFrame or record")


def _check_torque(record: TorqueAngleRecord) -> None:
    """A torque that never changes is a sensor not read, not a gear: say so."""
    torque = record.torque_nm
    span = float(np.ptp(torque))
    if span == 0:
        raise RecordError(
            f"{record.name}: column 'torque_nm' never changes (every value is {torque[0]:g} N·m): "
            "the torque sensor was not read or not connected; no stiffness can be computed",
            reason="torque_constant",
        )
    if record.time_s is not None:
        noise = robust_noise_std(torque)
        if span < 20 * noise:
            raise RecordError(
                f"{record.name}: column 'torque_nm' changes by only {span:.3g} N·m, within its "
                f"noise (std {noise:.2g} N·m): the gear was not loaded, or the torque sensor was "
                "not read; no stiffness can be computed",
                reason="torque_not_loaded",
            )


def _check_sign(record, filtered, level, threshold, rig) -> None:
    """Torque must rise with the drive position (input angle / transmission_ratio)."""
    if record.drive_deg is None:
        return
    contact = np.abs(filtered.torque_nm - level) > threshold
    if contact.sum() < 3:
        return
    slope = np.polyfit(filtered.drive_deg[contact], filtered.torque_nm[contact], 1)[0]
    if slope < 0:
        ratio = "" if rig is None else f" = {rig.transmission_ratio:g}"
        raise AnalysisError(
            f"{record.name}: the torque falls as the output angle rises (torque against input "
            f"angle / transmission_ratio has a negative slope): the sign of transmission_ratio{ratio} "
            "or of the torque sensor is inverted; change the sign of transmission_ratio in the rig file",
            reason="inverted_sign",
        )


def _fit_cycles(record, filtered, split, *, method, order, points, notes):
    """One fit per loading branch and cycle; a failure is a note naming the cycle."""
    fits, curves = [], []
    for cycle in split.cycles:
        for kind in LOADING_KINDS:
            idx = split.indices(kind, cycle=cycle)
            if idx.size == 0:
                continue
            sign = 1 if kind.startswith("positive") else -1
            # Past first contact only: the filtered torque has left the zero band.
            in_contact = sign * (filtered.torque_nm[idx] - split.level_nm) > split.threshold_nm
            idx = idx[in_contact]
            try:
                fit = fit_loading_branch(np.deg2rad(record.angle_deg[idx]), record.torque_nm[idx],
                                         kind=kind, method=method, order=order)
            except AnalysisError as exc:
                notes.append(f"{_cycle_name(record, cycle)}: {exc}")
                continue
            fit = replace(fit, cycle=cycle)
            fits.append(fit)
            curves.append(stiffness_curve(fit, points=points, cycle=cycle))
    return tuple(fits), tuple(curves)


def _cycle_name(record, cycle) -> str:
    if record.source == "camera":
        return f"loop {cycle + 1}"
    return "virgin loading (cycle 0)" if cycle == 0 else f"cycle {cycle}"


def _summarise(cycle_curves, *, points, notes, source):
    summary = []
    for kind in LOADING_KINDS:
        # The virgin loading (cycle 0 of an encoder record) is preconditioning.
        mine = [c for c in cycle_curves if c.kind == kind and not (source == "encoder" and c.cycle == 0)]
        if not mine:
            mine = [c for c in cycle_curves if c.kind == kind]
            if not mine:
                continue
            notes.append(f"{kind}: only the virgin (first) loading was recorded; its curve stands for "
                         "the branch (preconditioning could not be separated)")
        try:
            summary.append(summarise_curves(mine, points=points))
        except AnalysisError as exc:
            notes.append(f"no {kind} summary: {exc}")
    return tuple(summary)


def _backlash(record, filtered, split, cycles, notes):
    per_cycle = []
    for cycle in cycles:
        sub = split.restricted(cycle)
        if {b.kind for b in sub.branches} >= set(LOADING_KINDS):
            try:
                per_cycle.append((cycle, detect_backlash(record, filtered, sub)))
            except AnalysisError as exc:
                notes.append(f"{_cycle_name(record, cycle)}: no backlash: {exc}")
    if not per_cycle:
        if {b.kind for b in split.branches} >= set(LOADING_KINDS):
            try:
                backlash = detect_backlash(record, filtered, split)
            except AnalysisError as exc:
                notes.append(f"no backlash: {exc}")
                return (), None
            notes.append("backlash from the whole record: no cycle after the virgin loading has both "
                         "a positive and a negative loading branch")
            return (), backlash
        notes.append("no backlash: it needs both a positive and a negative loading branch")
        return (), None
    return tuple(per_cycle), summarise_backlash([b for _, b in per_cycle])


def _meshing(curves, rig, notes) -> MeshingSummary | None:
    if not curves:
        return None
    if rig is None or (rig.tooth_stiffness_nm_per_rad is None and rig.reference_torque_nm is None):
        notes.append("no meshing pairs: the rig gives neither tooth_stiffness_nm_per_rad "
                     "nor reference_torque_nm/reference_pairs")
        return None

    def curve_for(torque):
        kind = "positive_loading" if torque > 0 else "negative_loading"
        for c in curves:
            if c.kind == kind:
                return c
        raise AnalysisError(f"no {kind} branch to read the stiffness at {torque:g} N·m from")

    if rig.tooth_stiffness_nm_per_rad is not None:
        ks, source = rig.tooth_stiffness_nm_per_rad, "rig"
    else:
        k_ref = curve_for(rig.reference_torque_nm).at_torque(rig.reference_torque_nm)[0][0]
        ks, source = calibrate_tooth_stiffness(k_ref, pairs=rig.reference_pairs), "reference point"
    best = max(curves, key=lambda c: c.stiffness_nm_per_rad.max())
    i = int(np.argmax(best.stiffness_nm_per_rad))
    max_pairs = float(meshing_pairs(best.stiffness_nm_per_rad[i], tooth_stiffness_nm_per_rad=ks))
    linearity = None
    if rig.check_torque_nm is not None:
        k_check = np.array([curve_for(t).at_torque(t)[0][0] for t in rig.check_torque_nm])
        linearity = check_linearity(k_check, rig.check_pairs)
    return MeshingSummary(
        tooth_stiffness_nm_per_rad=float(ks), tooth_stiffness_source=source, teeth=rig.teeth,
        max_pairs_per_zone=max_pairs, max_pairs_per_zone_std=float(best.stiffness_std_nm_per_rad[i] / ks),
        torque_at_max_nm=float(best.torque_nm[i]),
        max_wrap_angle_per_zone_rad=(None if rig.teeth is None
                                     else float(wrap_angle_rad(max_pairs, teeth=rig.teeth))),
        linearity=linearity,
    )


def analyze_stiffness_curve(
    data,
    *,
    rig: RigConstants | None = None,
    method: str | None = None,
    order: int = 7,
    cutoff_hz: float | None = None,
    filter_order: int = 4,
    threshold_nm: float | None = None,
    hold_speed_deg_per_s: float | None = None,
    points: int = 200,
) -> StiffnessResult:
    """Stiffness curve per cycle, its summary, the backlash dead zone and meshing pairs.

    Each cycle's loading branches are fitted on their own (a cycle's zero offset
    and contact angle stay its own; cycles are never pooled in angle), the virgin
    (first) loading is kept apart as preconditioning, and the cycles are then
    summarised at equal torque (:func:`~.curve.summarise_curves`).

    Parameters
    ----------
    data : str, Path, pandas.DataFrame or TorqueAngleRecord
        Encoder/torque-sensor CSV (``time_s``, ``torque_nm``, ``input_pulses`` or
        ``input_angle_deg``) or a camera-rig ``measurements.csv``.
    rig : RigConstants, optional
        Needed for an encoder record; Ks (or a reference point) and z for meshing.
    method : {"polynomial", "spline"}, optional
        Fit of each loading branch (:func:`~.curve.fit_loading_branch`). Default:
        ``polynomial`` for an encoder record; for a camera record no smooth fit
        (its stiffness per load step is :func:`~.steps.step_stiffness`), unless one
        is asked for, then one per loop.
    order : int
        Polynomial order (7 fits the saturating stiffness law of the paper to well
        under 1 % on synthetic records; lower it for a few camera-rig steps).
    cutoff_hz : float, optional
        Low-pass cut-off, Hz; default 5 % of the sampling rate, at most 20 Hz.
    filter_order : int
        Butterworth order.
    threshold_nm : float, optional
        Half-width of the zero-torque band, N·m; default 5 robust noise stds.
    hold_speed_deg_per_s : float, optional
        Drive-speed dead-band, output deg/s: slower samples are holds (dwells);
        default a tenth of the typical drive speed (:func:`~.branches.hold_speed`).
    points : int
        Samples per stiffness curve.

    Returns
    -------
    StiffnessResult

    Raises
    ------
    RecordError
        Bad record (missing column, too few points, non-monotonic ``time_s``, ...),
        or a torque that never changes (the sensor was not read).
    RigError
        Bad or missing rig constant (e.g. ``transmission_ratio`` of zero).
    AnalysisError
        Cut-off at or above Nyquist, no loading branch, the torque falling as the
        angle rises (transmission ratio or sensor sign inverted), or no cycle whose
        loading branch could be fitted (each cycle's reason given).

    Examples
    --------
    >>> from vision_torsion.synthetic.encoder import synthetic_encoder_record
    >>> syn = synthetic_encoder_record(seed=3)
    >>> result = analyze_stiffness_curve(syn.frame, rig=syn.rig)
    >>> round(result.backlash.width_deg, 2)
    0.1
    >>> round(result.meshing.max_pairs_per_zone)
    49
    """
    record = as_record(data, rig=rig)
    _check_torque(record)
    filtered = filter_record(record, cutoff_hz=cutoff_hz, order=filter_order)
    if record.time_s is not None:
        level, threshold = zero_band(filtered.torque_nm, raw_torque_nm=record.torque_nm,
                                     threshold_nm=threshold_nm)
        _check_sign(record, filtered, level, threshold, rig)
    split = split_branches(filtered, raw_torque_nm=record.torque_nm, threshold_nm=threshold_nm,
                           min_points=5 if record.time_s is not None else 2,
                           hold_speed_deg_per_s=hold_speed_deg_per_s)
    notes: list[str] = []
    fit_method = method if method is not None else ("polynomial" if record.source == "encoder" else None)
    if fit_method is None:
        fits, cycle_curves = (), ()
        notes.append("no smooth curve: a camera record's stiffness is given per load step "
                     "(step_stiffness); ask for method='polynomial' or 'spline' to fit each loop")
    else:
        fits, cycle_curves = _fit_cycles(record, filtered, split, method=fit_method, order=order,
                                         points=points, notes=notes)
        if not fits:
            raise AnalysisError(f"{record.name}: no loading branch could be fitted: " + "; ".join(notes),
                                reason="no_fit")
    curves = _summarise(cycle_curves, points=points, notes=notes, source=record.source)
    if record.source == "encoder":
        cycle_backlash, backlash = _backlash(record, filtered, split,
                                             [c for c in split.cycles if c != 0], notes)
    else:
        cycle_backlash, backlash = (), None
    meshing = _meshing(curves, rig, notes)
    for note in notes:
        log.info("%s: %s", record.name, note)
    settings = dict(method=fit_method, order=order if fit_method == "polynomial" else None,
                    cutoff_hz=cutoff_hz, filter_order=filter_order, threshold_nm=split.threshold_nm,
                    hold_speed_deg_per_s=hold_speed_deg_per_s, points=points)
    return StiffnessResult(
        name=record.name, source=record.source, curves=curves, fits=fits, backlash=backlash,
        meshing=meshing, record=record, filtered=filtered, split=split, settings=settings,
        notes=tuple(notes), cycle_curves=cycle_curves, cycle_backlash=cycle_backlash,
    )
