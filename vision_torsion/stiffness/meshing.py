"""The meshing-teeth model: effective meshing tooth pairs from the stiffness.

The stiffness paper treats the meshing zone as tooth springs in parallel,
K = sum(K_i·r_i²) = n(T)·Ks, so the number of effective (fully meshing) tooth pairs
at torque T is

    n(T) = K(T) / Ks

with Ks the torsional stiffness of one fully meshing tooth pair (N·m/rad). One
meshing zone of n pairs on a flexspline of z teeth spans the wrap angle

    phi = 2·pi·n / z   [rad]

(the paper's example: 35 and 50 pairs of 160 teeth give 0.4375·pi and 0.625·pi).

**n is per meshing zone.** A harmonic drive meshes in :data:`MESHING_ZONES` zones,
at both ends of the wave generator's major axis. The paper's pair counts (35 at
10 N·m, 50 at 30 N·m) and its wrap angles are those of a *single* zone, with
K = n·Ks; so Ks is the stiffness one pair in each zone adds together, n = K/Ks is
the count per zone, and both zones together hold 2·n pairs (each pair Ks/2).
Columns and keys say so: ``meshing_pairs_per_zone``, ``meshing_pairs_total``,
``wrap_angle_per_zone_rad``.
Ks comes from the rig file or is calibrated from a reference point (T_ref, n_ref):
Ks = K(T_ref) / n_ref.

Since n is *defined* from K, plotting K against that n is trivially a line; the
paper's linearity claim is about K against meshing-pair counts found independently
(its simulation). :func:`check_linearity` tests that, given such counts.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..errors import AnalysisError, RigError
from ..validate import check_number

__all__ = [
    "MESHING_ZONES",
    "meshing_pairs",
    "wrap_angle_rad",
    "calibrate_tooth_stiffness",
    "LinearityCheck",
    "check_linearity",
]


#: Meshing zones of a harmonic drive (two ends of the wave generator's major axis).
MESHING_ZONES = 2


def meshing_pairs(stiffness_nm_per_rad, *, tooth_stiffness_nm_per_rad: float):
    """Effective meshing tooth pairs of one meshing zone, n = K / Ks.

    Parameters
    ----------
    stiffness_nm_per_rad : array_like
        Gear stiffness K, N·m/rad (its std may be passed the same way: n is linear).
    tooth_stiffness_nm_per_rad : float
        Ks, N·m/rad per pair (> 0).

    Returns
    -------
    ndarray
        n, tooth pairs (not rounded: an effective, not a counted, number).

    Raises
    ------
    RigError
        Ks is not a finite number > 0.

    Examples
    --------
    >>> meshing_pairs([3300.0, 16500.0], tooth_stiffness_nm_per_rad=330.0)
    array([10., 50.])
    """
    ks = check_number(tooth_stiffness_nm_per_rad, name="rig constant tooth_stiffness_nm_per_rad", error=RigError,
                      low=0, low_open=True, unit="N·m/rad")
    return np.asarray(stiffness_nm_per_rad, dtype=float) / ks


def wrap_angle_rad(pairs, *, teeth: int):
    """Wrap angle of one meshing zone, 2·pi·n/z, in radians.

    Parameters
    ----------
    pairs : array_like
        Effective meshing tooth pairs n of one zone.
    teeth : int
        Flexspline tooth count z (> 0).

    Returns
    -------
    ndarray or float
        Wrap angle, rad.

    Raises
    ------
    RigError
        `teeth` is not a whole number > 0.

    Examples
    --------
    The stiffness paper's worked numbers:

    >>> wrap_angle_rad(35, teeth=160) / np.pi, wrap_angle_rad(50, teeth=160) / np.pi
    (np.float64(0.4375), np.float64(0.625))
    """
    if int(teeth) != teeth or teeth <= 0:
        raise RigError(f"rig constant teeth must be a whole number > 0, got {teeth!r}")
    return 2.0 * np.pi * np.asarray(pairs, dtype=float) / int(teeth)


def calibrate_tooth_stiffness(stiffness_nm_per_rad: float, *, pairs: float) -> float:
    """Single-tooth stiffness Ks = K(T_ref) / n_ref from a reference point.

    Parameters
    ----------
    stiffness_nm_per_rad : float
        Measured stiffness at the reference torque, N·m/rad.
    pairs : float
        Known effective meshing pairs at that torque (e.g. from a simulation).

    Returns
    -------
    float
        Ks, N·m/rad.

    Raises
    ------
    AnalysisError
        Non-positive stiffness or pair count.

    Examples
    --------
    >>> calibrate_tooth_stiffness(12210.0, pairs=37)
    330.0
    """
    k, n = float(stiffness_nm_per_rad), float(pairs)
    if not (k > 0 and n > 0):
        raise AnalysisError(f"cannot calibrate Ks from K = {k!r} N·m/rad and n = {n!r} pairs")
    return k / n


@dataclass(frozen=True)
class LinearityCheck:
    """Straight-line fit K = a·n + b of stiffness against independent pair counts.

    Attributes
    ----------
    slope_nm_per_rad : float
        a, an estimate of Ks, N·m/rad per pair.
    intercept_nm_per_rad : float
        b, N·m/rad (the model says 0).
    r_squared : float
        Coefficient of determination of the line.
    max_relative_residual : float
        Largest |K − (a·n + b)| / K.
    is_linear : bool
        ``r_squared >= min_r_squared``.
    min_r_squared : float
        The criterion used.
    """

    slope_nm_per_rad: float
    intercept_nm_per_rad: float
    r_squared: float
    max_relative_residual: float
    is_linear: bool
    min_r_squared: float

    def to_dict(self) -> dict:
        """Plain dict."""
        return asdict(self)


def check_linearity(stiffness_nm_per_rad, pairs, *, min_r_squared: float = 0.99) -> LinearityCheck:
    """Check that stiffness is linear in the number of meshing pairs, as K = n·Ks claims.

    Parameters
    ----------
    stiffness_nm_per_rad : array_like
        Measured K at some torques, N·m/rad.
    pairs : array_like
        Meshing pairs found independently at the same torques.
    min_r_squared : float
        The line counts as linear when R² reaches this.

    Returns
    -------
    LinearityCheck

    Raises
    ------
    AnalysisError
        Fewer than 3 points, unequal lengths, or no spread in `pairs`.

    Examples
    --------
    >>> n = np.array([10.0, 20.0, 37.0, 50.0])
    >>> check = check_linearity(330.0 * n, n)
    >>> round(check.slope_nm_per_rad, 6), check.is_linear
    (330.0, True)
    """
    k = np.asarray(stiffness_nm_per_rad, dtype=float)
    n = np.asarray(pairs, dtype=float)
    if k.shape != n.shape or k.size < 3:
        raise AnalysisError(
            f"the linearity check needs >= 3 (K, n) pairs of equal length, got {k.size} and {n.size}"
        )
    if not np.ptp(n) > 0:
        raise AnalysisError("the linearity check needs different pair counts")
    slope, intercept = np.polyfit(n, k, 1)
    resid = k - (slope * n + intercept)
    total = np.sum((k - k.mean()) ** 2)
    r2 = 1.0 - float(resid @ resid) / float(total) if total > 0 else 0.0
    return LinearityCheck(
        slope_nm_per_rad=float(slope), intercept_nm_per_rad=float(intercept), r_squared=r2,
        max_relative_residual=float(np.max(np.abs(resid) / np.abs(k))),
        is_linear=bool(r2 >= min_r_squared), min_r_squared=float(min_r_squared),
    )
