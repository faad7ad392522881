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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import AnalysisError
from .records import TorqueAngleRecord

__all__ = ["BRANCH_KINDS", "LOADING_KINDS", "Branch", "BranchSplit", "zero_band", "split_branches"]

BRANCH_KINDS = ("positive_loading", "positive_unloading", "negative_loading", "negative_unloading")
LOADING_KINDS = ("positive_loading", "negative_loading")
#: Threshold in robust noise standard deviations: 5 sigma keeps noise on the
#: plateau out of the branches (a false excursion has probability ~3e-7 per sample).
THRESHOLD_SIGMAS = 5.0


@dataclass(frozen=True)
class Branch:
    """One contiguous run of samples of one kind: ``record[start:stop]``."""

    kind: str
    start: int
    stop: int

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

    def indices(self, kind: str) -> np.ndarray:
        """Sample indices of every branch of `kind`, in record order."""
        runs = [np.arange(b.start, b.stop) for b in self.branches if b.kind == kind]
        return np.concatenate(runs) if runs else np.empty(0, dtype=int)


def _robust_noise_std(values: np.ndarray) -> float:
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
        threshold_nm = max(THRESHOLD_SIGMAS * _robust_noise_std(raw), 1e-3 * span)
    elif not threshold_nm > 0:
        raise AnalysisError(f"threshold_nm must be > 0, got {threshold_nm!r}")
    return level, float(threshold_nm)


def _encoder_labels(record: TorqueAngleRecord, level: float, threshold: float) -> np.ndarray:
    torque = record.torque_nm - level
    forward = np.gradient(record.drive_deg) > 0
    backward = np.gradient(record.drive_deg) < 0
    labels = np.full(len(record), "hold", dtype=object)
    labels[np.abs(torque) <= threshold] = "dead_zone"
    pos, neg = torque > threshold, torque < -threshold
    labels[forward & pos] = "positive_loading"
    labels[backward & pos] = "positive_unloading"
    labels[backward & neg] = "negative_loading"
    labels[forward & neg] = "negative_unloading"
    return labels


def _runs(labels: np.ndarray, group: np.ndarray | None):
    """(label, start, stop) of maximal runs of equal label (and equal group)."""
    key = labels if group is None else np.array([f"{g}/{lab}" for g, lab in zip(group, labels)])
    edges = np.flatnonzero(key[1:] != key[:-1]) + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [len(labels)]])
    return [(labels[a], int(a), int(b)) for a, b in zip(starts, stops)]


def split_branches(record: TorqueAngleRecord, *, raw_torque_nm=None,
                   threshold_nm: float | None = None, min_points: int = 5) -> BranchSplit:
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
        labels = _encoder_labels(record, level, threshold)
    branches = tuple(
        Branch(kind, a, b) for kind, a, b in _runs(labels, record.group)
        if kind in BRANCH_KINDS and b - a >= min_points
    )
    if not any(b.kind in LOADING_KINDS for b in branches):
        raise AnalysisError(
            f"{record.name}: no loading branch: column 'torque_nm' never leaves the zero "
            f"band {level:g} ± {threshold:g} N·m for {min_points} or more samples while "
            "the drive moves away from the dead zone"
        )
    return BranchSplit(labels=labels, branches=branches, level_nm=level, threshold_nm=threshold)
