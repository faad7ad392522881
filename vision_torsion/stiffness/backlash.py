"""The backlash dead zone: its width in degrees and where it sits.

Within the dead zone the teeth are out of contact, the torque stays at its zero
level and the stiffness is about zero (the horizontal part of the stiffness paper's
torque-angle curve). Its edges are the angles of first contact of the positive and
of the negative loading branch:

    width  = theta_c(positive) − theta_c(negative)
    centre = (theta_c(positive) + theta_c(negative)) / 2

Where the torque crosses a noise threshold is a biased edge (too far out by about
threshold/K(0), and the curve is shallow at first contact), and a polynomial fit of
the whole branch extrapolated to zero is not accurate enough at the kink. Each edge
is therefore found by a **hinge fit** of the samples around it: the dead-zone
samples on its side of the dead-zone centre plus the low-torque part of the loading
branch (|T| up to 5 % of the largest, at least 3 zero-band widths), with

    s·T = L                                   for s·theta <= s·theta_c
    s·T = L + A·(exp(kappa·u) − 1) / kappa    u = s·(theta − theta_c) >= 0

(s = ±1 the branch sign). The exponential is exact when the stiffness grows
linearly with torque near contact, K(T) = A + kappa·T, the first-order form of any
smooth stiffening law. L and A are linear (solved by least squares), theta_c and
kappa are found by a grid search refined with Nelder-Mead. The edge's standard
uncertainty comes from the linearised covariance s²·(JᵀJ)⁻¹ of all four parameters.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..errors import AnalysisError
from ..numerics import fit_breakpoints, numeric_jacobian
from .branches import BranchSplit
from .combine import mean_over_cycles
from .records import TorqueAngleRecord

__all__ = ["Backlash", "contact_edge", "detect_backlash", "summarise_backlash"]

#: Upper end of the hinge-fit window, as a fraction of the largest |T|: the
#: linear-K(T) model of the first contact holds to ~0.3 % of the width there on the
#: synthetic saturating law (0.1 N·m noise), and gets biased beyond ~10 %.
EDGE_WINDOW_FRACTION = 0.05


@dataclass(frozen=True)
class Backlash:
    """Dead zone between the negative and positive contact angles (output degrees).

    Attributes
    ----------
    lower_deg, lower_std_deg : float
        First contact of the negative loading branch, and its std.
    upper_deg, upper_std_deg : float
        First contact of the positive loading branch, and its std.
    width_deg, width_std_deg : float
        upper − lower and its standard uncertainty.
    centre_deg : float
        Midpoint of the dead zone (where it sits relative to the angle zero).
    n_cycles : int
        Cycles behind the figures (1 for one cycle's dead zone).
    """

    lower_deg: float
    lower_std_deg: float
    upper_deg: float
    upper_std_deg: float
    width_deg: float
    width_std_deg: float
    centre_deg: float
    n_cycles: int = 1

    @property
    def width_arcmin(self) -> float:
        """Width in the catalogue unit, arcmin."""
        return 60.0 * self.width_deg

    def to_dict(self) -> dict:
        """Plain dict, with the width also in arcmin."""
        return {**asdict(self), "width_arcmin": self.width_arcmin}


def _hinge_design(x, xc, log_kappa, scale):
    u = np.clip(x - xc, 0.0, None) / scale
    kappa = np.exp(log_kappa)
    return np.column_stack([np.ones_like(u), np.expm1(kappa * u) / kappa])


def contact_edge(angle_rad, torque_nm, *, sign: int, search=None):
    """First-contact angle of a loading branch by a hinge fit (module docstring).

    Parameters
    ----------
    angle_rad : array_like
        Angles of the dead-zone samples on this side and of the low-torque
        loading samples, rad.
    torque_nm : array_like
        Their (unfiltered) torques, N·m.
    sign : {1, -1}
        +1 for the positive loading branch, −1 for the negative one.
    search : (float, float), optional
        Interval of angles (rad) holding the edge; default the span of the data.

    Returns
    -------
    angle_rad, angle_std_rad : float
        The contact angle and its standard uncertainty.

    Raises
    ------
    AnalysisError
        Fewer than 6 samples, or no sample on one side of the edge.

    Examples
    --------
    >>> theta = np.linspace(-0.001, 0.002, 301)
    >>> u = np.clip(theta - 0.0005, 0, None)
    >>> torque = 700 * np.expm1(3000 * u) / 3000          # K(T) = 700 + 3000 T
    >>> edge, edge_std = contact_edge(theta, torque, sign=1)
    >>> round(edge, 8)
    0.0005
    """
    x = sign * np.asarray(angle_rad, dtype=float)
    y = sign * np.asarray(torque_nm, dtype=float)
    if x.size < 6:
        raise AnalysisError(f"the dead-zone edge fit needs at least 6 samples, got {x.size}")
    lo, hi = (x.min(), x.max()) if search is None else sorted(sign * np.asarray(search, dtype=float))
    scale = float(x.max() - x.min())
    starts = [(xc, lk) for xc in np.linspace(lo, hi, 40) for lk in np.linspace(-3, 4, 15)]
    best = fit_breakpoints(lambda t: _hinge_design(x, t[0], t[1], scale), y, starts,
                           xatol=1e-9 * scale, fatol_rel=1e-14, maxiter=4000)
    xc, lk = best.breakpoints
    if not (np.any(x < xc) and np.any(x > xc)):
        raise AnalysisError("the dead-zone edge fit put the edge outside the data")
    # Linearised covariance of (xc, log_kappa, L, A) from a numerical Jacobian.
    coef = best.coef

    def model(p):
        return _hinge_design(x, p[0], p[1], scale) @ p[2:]

    p = np.array([xc, lk, *coef])
    steps = np.array([1e-6 * scale, 1e-6, 1e-6 * max(abs(coef[0]), 1.0), 1e-6 * max(abs(coef[1]), 1.0)])
    jac = numeric_jacobian(model, p, steps)
    s2 = best.sse / max(x.size - 4, 1)
    cov = s2 * np.linalg.pinv(jac.T @ jac)
    return float(sign * xc), float(np.sqrt(max(cov[0, 0], 0.0)))


def _edge_samples(record, filtered, split, kind):
    """Indices for one edge's hinge fit: its side of the dead zone + low-torque loading."""
    sign = 1 if kind.startswith("positive") else -1
    angle = record.angle_deg
    torque = sign * (filtered.torque_nm - split.level_nm)
    # Zero-band samples of any phase (a camera record has no "dead_zone" label).
    dead = (np.abs(torque) <= split.threshold_nm) & (split.labels != "reference")
    loading = split.indices(kind)
    if not dead.any() or loading.size == 0:
        raise AnalysisError(f"{record.name}: no dead-zone samples or no {kind} branch to locate the edge")
    centre = np.median(angle[dead])
    in_contact = loading[torque[loading] > split.threshold_nm]
    if in_contact.size == 0:
        raise AnalysisError(f"{record.name}: the {kind} branch never leaves the zero band")
    ordered = np.sort(torque[in_contact])
    window = max(EDGE_WINDOW_FRACTION * np.max(np.abs(torque)), 3 * split.threshold_nm,
                 ordered[min(3, ordered.size - 1)])
    side = dead & (sign * (angle - centre) >= 0)
    keep = np.union1d(np.flatnonzero(side), loading[torque[loading] <= window])
    search = (np.deg2rad(centre), np.deg2rad(angle[in_contact][np.argmin(sign * angle[in_contact])]))
    return keep, search


def detect_backlash(record: TorqueAngleRecord, filtered: TorqueAngleRecord, split: BranchSplit) -> Backlash:
    """Locate the backlash dead zone of a record.

    Parameters
    ----------
    record : TorqueAngleRecord
        The record as read (its unfiltered torque is fitted).
    filtered : TorqueAngleRecord
        The same after low-pass filtering (used to choose the samples).
    split : BranchSplit
        Its branch split (:func:`~.branches.split_branches`), with both loading
        branches and dead-zone samples.

    Returns
    -------
    Backlash

    Raises
    ------
    AnalysisError
        A loading branch or the dead-zone samples are missing, an edge fit fails,
        or the edges overlap (the branches cross: no dead zone).

    Examples
    --------
    >>> from vision_torsion.stiffness import analysis, filtering, branches
    >>> from vision_torsion.synthetic import encoder as synthetic
    >>> syn = synthetic.synthetic_encoder_record(backlash_deg=0.2, seed=5)
    >>> rec = analysis.as_record(syn.frame, rig=syn.rig)
    >>> filt = filtering.filter_record(rec)
    >>> split = branches.split_branches(filt, raw_torque_nm=rec.torque_nm)
    >>> round(detect_backlash(rec, filt, split).width_deg, 2)
    0.2
    """
    edges = {}
    for kind in ("positive_loading", "negative_loading"):
        keep, search = _edge_samples(record, filtered, split, kind)
        edges[kind] = contact_edge(np.deg2rad(record.angle_deg[keep]), record.torque_nm[keep],
                                   sign=1 if kind.startswith("positive") else -1, search=search)
    (upper, upper_std), (lower, lower_std) = edges["positive_loading"], edges["negative_loading"]
    if upper <= lower:
        raise AnalysisError(
            f"{record.name}: the loading branches overlap at zero torque (positive contact at "
            f"{np.rad2deg(upper):.4g}°, negative at {np.rad2deg(lower):.4g}°): no dead zone"
        )
    deg = np.rad2deg
    return Backlash(
        lower_deg=float(deg(lower)), lower_std_deg=float(deg(lower_std)),
        upper_deg=float(deg(upper)), upper_std_deg=float(deg(upper_std)),
        width_deg=float(deg(upper - lower)), width_std_deg=float(deg(np.hypot(upper_std, lower_std))),
        centre_deg=float(deg(0.5 * (upper + lower))),
    )


def summarise_backlash(per_cycle) -> Backlash:
    """Mean dead zone over cycles, each found on its own cycle's samples.

    The standard uncertainty of each mean combines the scatter between cycles
    (Type A) with the edge fits' own (Type B), :func:`~.combine.mean_over_cycles`.
    With one cycle it is that cycle's dead zone.

    Raises
    ------
    AnalysisError
        No dead zone to summarise.

    Examples
    --------
    >>> a = Backlash(-0.1, 0.001, 0.1, 0.001, 0.2, 0.0014, 0.0)
    >>> b = Backlash(-0.1, 0.001, 0.104, 0.001, 0.204, 0.0014, 0.002)
    >>> s = summarise_backlash([a, b])
    >>> round(s.width_deg, 4), s.n_cycles
    (0.202, 2)
    """
    items = list(per_cycle)
    if not items:
        raise AnalysisError("no dead zone to summarise")
    if len(items) == 1:
        return items[0]
    n = len(items)

    def mean_std(value, std):
        m, u = mean_over_cycles([getattr(b, value) for b in items], [getattr(b, std) for b in items])
        return float(m), float(u)

    lower, lower_std = mean_std("lower_deg", "lower_std_deg")
    upper, upper_std = mean_std("upper_deg", "upper_std_deg")
    width, width_std = mean_std("width_deg", "width_std_deg")
    return Backlash(lower_deg=lower, lower_std_deg=lower_std, upper_deg=upper, upper_std_deg=upper_std,
                    width_deg=width, width_std_deg=width_std, centre_deg=0.5 * (lower + upper), n_cycles=n)
