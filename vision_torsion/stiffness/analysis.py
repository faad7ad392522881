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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import AnalysisError, RigError
from .backlash import Backlash, detect_backlash
from .branches import LOADING_KINDS, BranchSplit, split_branches
from .curve import BranchFit, StiffnessCurve, fit_loading_branch, stiffness_curve
from .filtering import filter_record
from .meshing import (
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

#: Column names of :meth:`StiffnessResult.to_frame`, units in the names.
CURVE_COLUMNS = (
    "branch", "angle_deg", "torque_nm", "stiffness_nm_per_rad", "stiffness_std_nm_per_rad",
    "stiffness_nm_per_arcmin", "meshing_pairs", "meshing_pairs_std", "wrap_angle_rad",
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
    max_pairs, max_pairs_std : float
        Largest effective meshing pairs over the curves, and its std.
    torque_at_max_nm : float
        Torque where it occurs, N·m.
    max_wrap_angle_rad : float or None
        2·pi·max_pairs/z, rad.
    linearity : LinearityCheck or None
        K against independent pair counts (rig ``check_*``), if given.
    """

    tooth_stiffness_nm_per_rad: float
    tooth_stiffness_source: str
    teeth: int | None
    max_pairs: float
    max_pairs_std: float
    torque_at_max_nm: float
    max_wrap_angle_rad: float | None
    linearity: LinearityCheck | None

    def to_dict(self) -> dict:
        """Plain dict; the wrap angle also in units of pi."""
        d = {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "linearity"}
        d["max_wrap_angle_pi"] = None if self.max_wrap_angle_rad is None else self.max_wrap_angle_rad / np.pi
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
        One per loading branch found.
    fits : tuple of BranchFit
        The fits behind them.
    backlash : Backlash or None
        The dead zone (None when it could not be determined; see `notes`).
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

    def to_frame(self) -> pd.DataFrame:
        """The stiffness curves as one table (columns :data:`CURVE_COLUMNS`).

        Meshing columns are NaN (empty in CSV) when Ks is unknown, and the wrap angle
        when z is unknown.
        """
        frames = []
        ks = self.meshing.tooth_stiffness_nm_per_rad if self.meshing else np.nan
        teeth = self.meshing.teeth if self.meshing else None
        for c in self.curves:
            pairs = c.stiffness_nm_per_rad / ks
            frames.append(pd.DataFrame({
                "branch": c.kind,
                "angle_deg": c.angle_deg,
                "torque_nm": c.torque_nm,
                "stiffness_nm_per_rad": c.stiffness_nm_per_rad,
                "stiffness_std_nm_per_rad": c.stiffness_std_nm_per_rad,
                "stiffness_nm_per_arcmin": c.stiffness_nm_per_rad * np.pi / (180 * 60),
                "meshing_pairs": pairs,
                "meshing_pairs_std": c.stiffness_std_nm_per_rad / ks,
                "wrap_angle_rad": wrap_angle_rad(pairs, teeth=teeth) if teeth else np.nan,
            }))
        return pd.concat(frames, ignore_index=True)[list(CURVE_COLUMNS)]

    def to_dict(self) -> dict:
        """JSON-safe summary (no per-point arrays; those are in :meth:`to_frame`)."""
        branches = {}
        for fit, c in zip(self.fits, self.curves):
            branches[fit.kind] = {
                "method": fit.method, "order": fit.order, "n_points": fit.n_points,
                "residual_std_nm": fit.residual_std_nm,
                "torque_range_nm": [float(c.torque_nm[0]), float(c.torque_nm[-1])],
                "stiffness_range_nm_per_rad": [float(c.stiffness_nm_per_rad.min()),
                                               float(c.stiffness_nm_per_rad.max())],
            }
        return {
            "name": self.name, "source": self.source, "settings": dict(self.settings),
            "zero_torque_level_nm": self.split.level_nm,
            "zero_band_nm": self.split.threshold_nm,
            "branches": branches,
            "backlash": None if self.backlash is None else self.backlash.to_dict(),
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


def _fit_branches(record, filtered, split, *, method, order):
    fits = []
    for kind in LOADING_KINDS:
        idx = split.indices(kind)
        if idx.size == 0:
            continue
        sign = 1 if kind.startswith("positive") else -1
        # Past first contact only: the filtered torque has left the zero band.
        in_contact = sign * (filtered.torque_nm[idx] - split.level_nm) > split.threshold_nm
        idx = idx[in_contact]
        fits.append(fit_loading_branch(
            np.deg2rad(record.angle_deg[idx]), record.torque_nm[idx], kind=kind,
            method=method, order=order,
        ))
    return tuple(fits)


def _meshing(curves, rig, notes) -> MeshingSummary | None:
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
        max_pairs=max_pairs, max_pairs_std=float(best.stiffness_std_nm_per_rad[i] / ks),
        torque_at_max_nm=float(best.torque_nm[i]),
        max_wrap_angle_rad=None if rig.teeth is None else float(wrap_angle_rad(max_pairs, teeth=rig.teeth)),
        linearity=linearity,
    )


def analyze_stiffness_curve(
    data,
    *,
    rig: RigConstants | None = None,
    method: str = "polynomial",
    order: int = 7,
    cutoff_hz: float | None = None,
    filter_order: int = 4,
    threshold_nm: float | None = None,
    points: int = 200,
) -> StiffnessResult:
    """Stiffness curve, backlash dead zone and meshing pairs of a torque-angle record.

    Parameters
    ----------
    data : str, Path, pandas.DataFrame or TorqueAngleRecord
        Encoder/torque-sensor CSV (``time_s``, ``torque_nm``, ``input_pulses`` or
        ``input_angle_deg``) or a camera-rig ``measurements.csv``.
    rig : RigConstants, optional
        Needed for an encoder record; Ks (or a reference point) and z for meshing.
    method : {"polynomial", "spline"}
        Fit of each loading branch (:func:`~.curve.fit_loading_branch`).
    order : int
        Polynomial order (7 fits the saturating stiffness law of the paper to well
        under 1 % on synthetic records; lower it for a few camera-rig steps).
    cutoff_hz : float, optional
        Low-pass cut-off, Hz; default 5 % of the sampling rate.
    filter_order : int
        Butterworth order.
    threshold_nm : float, optional
        Half-width of the zero-torque band, N·m; default 5 robust noise stds.
    points : int
        Samples per stiffness curve.

    Returns
    -------
    StiffnessResult

    Raises
    ------
    RecordError
        Bad record (missing column, too few points, non-monotonic ``time_s``, ...).
    RigError
        Bad or missing rig constant (e.g. ``transmission_ratio`` of zero).
    AnalysisError
        Cut-off at or above Nyquist, no loading branch, too few points to fit, a
        non-monotonic fit.

    Examples
    --------
    >>> from vision_torsion.stiffness.synthetic import synthetic_encoder_record
    >>> syn = synthetic_encoder_record(seed=3)
    >>> result = analyze_stiffness_curve(syn.frame, rig=syn.rig)
    >>> round(result.backlash.width_deg, 2)
    0.1
    >>> round(result.meshing.max_pairs)
    49
    """
    record = as_record(data, rig=rig)
    filtered = filter_record(record, cutoff_hz=cutoff_hz, order=filter_order)
    split = split_branches(filtered, raw_torque_nm=record.torque_nm, threshold_nm=threshold_nm,
                           min_points=5 if record.time_s is not None else 2)
    fits = _fit_branches(record, filtered, split, method=method, order=order)
    curves = tuple(stiffness_curve(f, points=points) for f in fits)
    notes: list[str] = []
    backlash = None
    if len(fits) == 2:
        try:
            backlash = detect_backlash(record, filtered, split)
        except AnalysisError as exc:
            notes.append(f"no backlash: {exc}")
    else:
        notes.append("no backlash: it needs both a positive and a negative loading branch")
    meshing = _meshing(curves, rig, notes)
    for note in notes:
        log.info("%s: %s", record.name, note)
    settings = dict(method=method, order=order if method == "polynomial" else None,
                    cutoff_hz=cutoff_hz, filter_order=filter_order, threshold_nm=split.threshold_nm,
                    points=points)
    return StiffnessResult(
        name=record.name, source=record.source, curves=curves, fits=fits, backlash=backlash,
        meshing=meshing, record=record, filtered=filtered, split=split, settings=settings,
        notes=tuple(notes),
    )
