"""Split a torque-angle record into loading and unloading branches.

Branch names follow the camera rig's ``phase`` column; the stiffness paper's
"forward" is our "positive" (torque > 0) and "reverse" is "negative":

==================== ============================ =========================
kind                 drive moves                  torque
==================== ============================ =========================
positive_loading     forward (drive angle rises)  > +threshold, |T| rising
positive_unloading   backward                     > +threshold, |T| falling
negative_loading     backward                     < −threshold, |T| rising
negative_unloading   forward                      < −threshold, |T| falling
dead_zone            either                       within ±threshold
==================== ============================ =========================

For an encoder record the direction comes from the (filtered) drive position
theta_in/i, which the motor sets, and the torque from the (filtered) sensor signal,
both relative to the zero-torque level. For a camera record the ``phase`` column
already says which branch a step belongs to.

**Holds.** Where the drive speed is inside a dead-band (default
:data:`HOLD_SPEED_FRACTION` of the typical drive speed) the drive is at rest and the
sample is a ``hold``: a dwell at a reversal is one hold, not a string of micro-
branches flickering with the filter's rounding. A hold does not end a branch: the
runs on either side of it of the same kind are one branch, and so are runs split
by a flicker shorter than ``min_points``.

**Cycles.** Loading branches are numbered into cycles in record order. When the
record starts with a loading branch (from the dead zone, no unloading before it),
that first loading is the *virgin* loading (cycle 0, preconditioning: the teeth
bed in, it is not one of the repeated cycles). After it a new cycle starts at
every loading branch whose kind the current cycle already has, so a two-sided
test gives (negative, positive) or (positive, negative) pairs and a one-sided
test one loading per cycle. An unloading branch belongs to the cycle of the
loading before it. A camera record's cycles are its loops (``group``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import AnalysisError
from ..validate import check_number
from .records import TorqueAngleRecord

__all__ = ["BRANCH_KINDS", "LOADING_KINDS", "HOLD_SPEED_FRACTION", "Branch", "BranchSplit", "zero_band",
           "split_branches", "hold_speed", "robust_noise_std"]

BRANCH_KINDS = ("positive_loading", "positive_unloading", "negative_loading", "negative_unloading")
LOADING_KINDS = ("positive_loading", "negative_loading")
#: Threshold in robust noise standard deviations: 5 sigma keeps noise on the
#: plateau out of the branches (a false excursion has probability ~3e-7 per sample).
THRESHOLD_SIGMAS = 5.0
#: Default speed dead-band as a fraction of the typical drive speed (the 90th
#: percentile of |d drive/dt|): a tenth of the running speed is well above the
#: filter's rounding at rest (~1e-12 of it) and well below any real motion.
HOLD_SPEED_FRACTION = 0.1


@dataclass(frozen=True)
class Branch:
    """One branch: the samples of `kind` within ``record[start:stop]`` (holds and
    short flickers inside that span are not part of it).

    Attributes
    ----------
    kind : str
        One of :data:`BRANCH_KINDS`.
    start, stop : int
        Sample span.
    cycle : int
        0 for the virgin loading (and the unloading after it), then 1, 2, ...
        (module docstring); a camera record's loop number.
    """

    kind: str
    start: int
    stop: int
    cycle: int = 1

    def __len__(self) -> int:
        return self.stop - self.start


@dataclass(frozen=True)
class BranchSplit:
    """Per-sample labels and the branches of a record.

    Attributes
    ----------
    labels : ndarray of str
        A branch kind, ``dead_zone``, ``hold`` (drive at rest) or ``reference``.
    branches : tuple of Branch
        Runs of a branch kind with at least ``min_points`` samples, in record order.
    level_nm : float
        Zero-torque level (sensor offset), N·m.
    threshold_nm : float
        Half-width of the zero-torque band, N·m.
    """

    labels: np.ndarray
    branches: tuple[Branch, ...]
    level_nm: float
    threshold_nm: float

    def indices(self, kind: str, *, cycle: int | None = None) -> np.ndarray:
        """Sample indices of every branch of `kind` (of one `cycle`, if given), in record order."""
        runs = [b.start + np.flatnonzero(self.labels[b.start:b.stop] == kind) for b in self.branches
                if b.kind == kind and (cycle is None or b.cycle == cycle)]
        return np.concatenate(runs) if runs else np.empty(0, dtype=int)

    @property
    def cycles(self) -> tuple[int, ...]:
        """Cycle numbers that have a loading branch, ascending (0 = the virgin loading)."""
        return tuple(sorted({b.cycle for b in self.branches if b.kind in LOADING_KINDS}))

    def span(self, cycle: int) -> tuple[int, int]:
        """Sample span of one cycle: from the end of the previous cycle's last loading
        branch to the end of this cycle's last loading branch (so it holds the dead
        zone crossed before each of its loadings)."""
        loads = [b for b in self.branches if b.kind in LOADING_KINDS]
        mine = [b for b in loads if b.cycle == cycle]
        before = [b.stop for b in loads if b.cycle < cycle]
        return (max(before) if before else 0), max(b.stop for b in mine)

    def restricted(self, cycle: int) -> "BranchSplit":
        """The split of one cycle: labels outside :meth:`span` become ``other``."""
        start, stop = self.span(cycle)
        labels = np.full(self.labels.shape, "other", dtype=object)
        labels[start:stop] = self.labels[start:stop]
        branches = tuple(b for b in self.branches if b.cycle == cycle and start <= b.start and b.stop <= stop)
        return BranchSplit(labels=labels, branches=branches, level_nm=self.level_nm,
                           threshold_nm=self.threshold_nm)


def robust_noise_std(values: np.ndarray) -> float:
    """Noise std from second differences (MAD): blind to the smooth signal underneath."""
    d2 = np.diff(values, 2)
    if d2.size == 0:
        return 0.0
    # var(x[i] - 2x[i+1] + x[i+2]) = 6 sigma^2 for white noise; 0.6745 = MAD/sigma.
    return float(np.median(np.abs(d2 - np.median(d2))) / 0.6745 / np.sqrt(6.0))


def zero_band(torque_nm, *, raw_torque_nm=None, threshold_nm: float | None = None):
    """Zero-torque level and the half-width of the band counted as "no torque".

    Parameters
    ----------
    torque_nm : array_like
        Torque, N·m (filtered, if it was).
    raw_torque_nm : array_like, optional
        Unfiltered torque, N·m, for the noise estimate (default `torque_nm`).
    threshold_nm : float, optional
        Band half-width, N·m; default ``THRESHOLD_SIGMAS`` times the robust noise
        std of `raw_torque_nm`, and at least 0.1 % of the torque range.

    Returns
    -------
    level_nm, threshold_nm : float

    Notes
    -----
    The level is the median of the samples within 5 % of the largest |T| of zero:
    the dead-zone plateau, where a sensor offset shows.

    Examples
    --------
    >>> t = np.concatenate([np.zeros(50), np.linspace(0, 10, 50)]) + 0.2
    >>> zero_band(t, threshold_nm=0.5)
    (0.2, 0.5)
    """
    t = np.asarray(torque_nm, dtype=float)
    scale = float(np.max(np.abs(t))) if t.size else 0.0
    near = t[np.abs(t) <= 0.05 * scale]
    level = float(np.median(near)) if near.size else 0.0
    if threshold_nm is None:
        raw = t if raw_torque_nm is None else np.asarray(raw_torque_nm, dtype=float)
        span = float(np.ptp(t)) if t.size else 0.0
        threshold_nm = max(THRESHOLD_SIGMAS * robust_noise_std(raw), 1e-3 * span)
    else:
        threshold_nm = check_number(threshold_nm, name="threshold_nm", error=AnalysisError, low=0, low_open=True,
                                    unit="N·m")
    return level, float(threshold_nm)


def hold_speed(record: TorqueAngleRecord, *, hold_speed_deg_per_s: float | None = None) -> float:
    """The drive-speed dead-band, output degrees per second.

    Parameters
    ----------
    record : TorqueAngleRecord
        Timed record with ``drive_deg`` (best filtered).
    hold_speed_deg_per_s : float, optional
        Given dead-band (> 0); default :data:`HOLD_SPEED_FRACTION` of the 90th
        percentile of |d drive/dt|.

    Raises
    ------
    AnalysisError
        A given dead-band is not > 0, or the drive never moves.
    """
    speed = np.abs(np.gradient(record.drive_deg, record.time_s))
    if hold_speed_deg_per_s is not None:
        return check_number(hold_speed_deg_per_s, name="hold_speed_deg_per_s", error=AnalysisError, low=0,
                            low_open=True, unit="degrees/s")
    typical = float(np.percentile(speed, 90))
    if not typical > 0:
        raise AnalysisError(f"{record.name}: the drive never moves (input position constant)")
    return HOLD_SPEED_FRACTION * typical


def _encoder_labels(record: TorqueAngleRecord, level: float, threshold: float, deadband: float) -> np.ndarray:
    torque = record.torque_nm - level
    speed = np.gradient(record.drive_deg, record.time_s)
    forward = speed > deadband
    backward = speed < -deadband
    labels = np.full(len(record), "hold", dtype=object)
    labels[np.abs(torque) <= threshold] = "dead_zone"
    pos, neg = torque > threshold, torque < -threshold
    labels[forward & pos] = "positive_loading"
    labels[backward & pos] = "positive_unloading"
    labels[backward & neg] = "negative_loading"
    labels[forward & neg] = "negative_unloading"
    return labels


def _runs(labels: np.ndarray, group: np.ndarray | None):
    """(label, group, start, stop) of maximal runs of equal label (and equal group)."""
    key = labels if group is None else np.array([f"{g}/{lab}" for g, lab in zip(group, labels)])
    edges = np.flatnonzero(key[1:] != key[:-1]) + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [len(labels)]])
    return [(labels[a], None if group is None else int(group[a]), int(a), int(b)) for a, b in zip(starts, stops)]


def _merged_branches(labels, group, min_points):
    """Branches of at least `min_points` samples; holds and shorter flickers between
    two runs of one kind (and group) do not split them."""
    kept = []  # [kind, group, start, stop, count]
    for kind, grp, a, b in _runs(labels, group):
        if kind not in BRANCH_KINDS + ("dead_zone",) or b - a < min_points:
            continue
        if kept and kept[-1][0] == kind and kept[-1][1] == grp:
            kept[-1][3], kept[-1][4] = b, kept[-1][4] + (b - a)
        else:
            kept.append([kind, grp, a, b, b - a])
    return [k for k in kept if k[0] in BRANCH_KINDS]


def _number_cycles(runs, group):
    """Cycle number of each branch (module docstring)."""
    if group is not None:
        return [grp for _, grp, *_ in runs]
    cycles, cycle, seen = [], 1, set()
    virgin = bool(runs) and runs[0][0] in LOADING_KINDS
    for i, (kind, *_rest) in enumerate(runs):
        if kind in LOADING_KINDS:
            if i == 0 and virgin:
                cycles.append(0)
                continue
            if kind in seen:
                cycle, seen = cycle + 1, set()
            seen.add(kind)
            cycles.append(cycle)
        else:
            cycles.append(cycles[-1] if cycles else 1)
    return cycles


def split_branches(record: TorqueAngleRecord, *, raw_torque_nm=None,
                   threshold_nm: float | None = None, min_points: int = 5,
                   hold_speed_deg_per_s: float | None = None) -> BranchSplit:
    """Label each sample and collect the loading/unloading branches.

    Parameters
    ----------
    record : TorqueAngleRecord
        Encoder record (best filtered, see :func:`~.filtering.filter_record`) or
        camera record (labelled by its ``phase`` column).
    raw_torque_nm : array_like, optional
        Unfiltered torque, N·m, for the noise estimate of the zero band.
    threshold_nm : float, optional
        Half-width of the zero-torque band, N·m (see :func:`zero_band`).
    min_points : int
        Shorter runs are not branches (noise flicker at a turning point).
    hold_speed_deg_per_s : float, optional
        Drive-speed dead-band of an encoder record, output deg/s (see
        :func:`hold_speed`); slower samples are ``hold``.

    Returns
    -------
    BranchSplit

    Raises
    ------
    AnalysisError
        The record has no loading branch (the torque never leaves the zero band
        while the drive moves away from the dead zone).
    """
    if record.phase is not None:
        level = 0.0
        span = float(np.ptp(record.torque_nm))
        threshold = threshold_nm if threshold_nm is not None else 1e-3 * span
        labels = np.array(record.phase, dtype=object)
    else:
        level, threshold = zero_band(record.torque_nm, raw_torque_nm=raw_torque_nm,
                                     threshold_nm=threshold_nm)
        labels = _encoder_labels(record, level, threshold,
                                 hold_speed(record, hold_speed_deg_per_s=hold_speed_deg_per_s))
    runs = _merged_branches(labels, record.group, min_points)
    branches = tuple(Branch(kind, a, b, cycle)
                     for (kind, _, a, b, _), cycle in zip(runs, _number_cycles(runs, record.group)))
    if not any(b.kind in LOADING_KINDS for b in branches):
        raise AnalysisError(
            f"{record.name}: no loading branch: column 'torque_nm' never leaves the zero "
            f"band {level:g} ± {threshold:g} N·m for {min_points} or more samples while "
            "the drive moves away from the dead zone"
        )
    return BranchSplit(labels=labels, branches=branches, level_nm=level, threshold_nm=threshold)
