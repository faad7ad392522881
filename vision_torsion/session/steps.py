"""Does each photographed step fit the plan? Capture mistakes found from the angles.

At the rig the usual mistakes are an extra shot (the same load photographed
twice), a missed shot (a load step not photographed, so every later file is bound
to the row before its own), and a weight piece forgotten on a pan. Each shows in
the angle step Δθ between an image and the one before it, compared with the
torque step Δτ the plan says was made between them:

- **no movement**: ``|Δθ|`` below 5 σ_Δ (σ_Δ the angle step's standard
  uncertainty) for a planned torque step: an extra shot, or no weight changed;
- **wrong direction**: Δθ and Δτ of opposite signs (beyond 5 σ_Δ): the wrong pair
  of pans, a wrong ``angle_sign``, or files out of order;
- **out of line**: the step's compliance ``Δθ/Δτ`` against the previous step's in
  the same direction of loading (e = that compliance × Δτ): below 0.6 e (a piece
  forgotten on one pan gives ≈ 0.5 e) or between 1.6 e and 2.6 e (a missed shot or
  an extra piece gives ≈ 2 e).

An out-of-line step can also be the gear itself: in the paper's bilinear model the
compliance jumps by k_u/k_l ≈ 15 where the load passes zero (soft) and back where
it passes ±τ_c (stiff), and a jump that falls inside a step gives any ratio in
between. The step after tells them apart, by its compliance against this step's:
after a forgotten piece the next step makes up for it (≈ 1.5 e after ≈ 0.5 e: 3×,
kept as a mistake when ≥ 1.8×), after a missed shot the next goes on as before (≈ e
after ≈ 2 e: 0.5×, kept when ≤ 0.7×), after a switch the next goes on at the new
compliance (≈ 1×); comparing with this step rather than with the step before keeps
a gear whose compliance drifts along the branch (a Masing loop) apart from a
mistake. At the end of a branch (the load reverses next) no step can tell: such a
warning is undecided, and it is the gear's when the same step elsewhere in the
loop (or in another cycle or orientation) shows it too (:func:`gear_kinks`). A
live sequence's newest step has no next step yet: ``watch`` waits for the next
image (``open_end``). A mistake's
ratio (0.5, 2 or 0) is far from 1 by many times the scatter of the ratio (σ_Δ/Δθ ≈
0.3 % for the paper's 0.25° steps at 0.0005° noise). A flagged step, and the step
after it, are not used as the reference of the next, so one mistake gives one
warning, on the image where it happened. Checked only across one or two planned
weight steps (not across the unphotographed pre-load or the return to zero before a
closing image) and only between images of one orientation. These are warnings for
the person at the rig, not a statistical test; the false-alarm rate on the paper's
loops is tested (tests/test_rig_bind_inputs.py); ``bind`` tries fixes against them (:mod:`.bind`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["StepPoint", "StepWarning", "check_steps", "first_load_inverted", "gear_kinks", "WARNING_KINDS"]

#: Kinds of step warning.
WARNING_KINDS = ("no_movement", "wrong_direction", "small_step", "large_step")
_STILL_SIGMAS = 5.0
_SMALL = 0.6
_LARGE = (1.6, 2.6)
_RECOVERY = 1.8
_GOES_ON = 0.7


@dataclass(frozen=True)
class StepPoint:
    """One image of an orientation's sequence, in capture order.

    Attributes
    ----------
    torque_nm : float
        Planned torque of the row the image is bound to (N·m).
    angle_deg : float or None
        Measured angle (deg, ``angle_sign`` applied), None if it failed.
    angle_std_deg : float
        Its standard uncertainty (deg).
    """

    torque_nm: float
    angle_deg: float | None
    angle_std_deg: float = 0.0


@dataclass(frozen=True)
class StepWarning:
    """A step that does not fit the plan.

    Attributes
    ----------
    index : int
        Position of the image in the sequence given to :func:`check_steps`.
    kind : str
        One of :data:`WARNING_KINDS`.
    delta_angle_deg, delta_torque_nm : float
        The measured angle step and the planned torque step from the previous image.
    ratio : float
        Δθ divided by the expected step (NaN when nothing was expected yet).
    message : str
        What it looks like, in words (the caller adds the file and the row).
    decided : bool
        The next step confirmed it. False for an out-of-line step at the end of a
        branch (the load reverses after it) or of the sequence: it may be the
        gear's own change of stiffness (:func:`gear_kinks` tells, when it recurs).
    torque_span_nm : tuple of float
        The planned torques (N·m) of the step's two images, in capture order.
    """

    index: int
    kind: str
    delta_angle_deg: float
    delta_torque_nm: float
    ratio: float
    message: str
    decided: bool = True
    torque_span_nm: tuple = ()


def check_steps(points, *, step_torque_nm: float, open_end: bool = False) -> list[StepWarning]:
    """Warnings for the steps of one orientation's image sequence (module docstring).

    Parameters
    ----------
    points : sequence of StepPoint
        The orientation's images in capture order, the reference (zero torque) first.
    step_torque_nm : float
        Torque of one planned weight step, ``2 m g r`` (N·m).
    open_end : bool
        The sequence goes on (a live one): an out-of-line newest step, which only
        the next step can confirm, is not reported yet (``watch`` reports it at the
        next image, or never when the next goes on at the new stiffness: an
        expected change of stiffness is not a mistake). False: it is reported,
        saying the next step would tell.

    Returns
    -------
    list of StepWarning
        In sequence order; at most one per image. An out-of-line step is confirmed
        by the step after it: kept when the next step makes up for it (a forgotten
        piece: the next step's compliance ≥ 1.8× this one's) or goes on as before (a
        missed shot: ≤ 0.7×); else it was the gear's stiffness switching, no
        warning, and the new compliance is taken. One at the end of a branch or of
        the sequence cannot be confirmed: it is warned about, undecided
        (:attr:`StepWarning.decided`), unless `open_end`.
    """
    steps = []  # (index, d_tau, d_theta, sigma, torques) between consecutive images with an angle
    prev = None
    for i, p in enumerate(points):
        if p.angle_deg is None or not math.isfinite(p.angle_deg):
            continue
        if prev is not None:
            q = points[prev]
            steps.append((i, p.torque_nm - q.torque_nm, p.angle_deg - q.angle_deg,
                          math.hypot(p.angle_std_deg, q.angle_std_deg), (q.torque_nm, p.torque_nm)))
        prev = i

    def single(d_tau):
        return 0.5 < abs(d_tau) / step_torque_nm < 2.5

    out: list[StepWarning] = []
    compliance = None  # (deg per N·m, sign of Δτ) of the last step that fitted
    after_warning = False
    for k, (i, d_tau, d_theta, sigma, span) in enumerate(steps):
        if not single(d_tau):
            compliance, after_warning = None, False  # the pre-load, a return to zero
            continue
        direction = 1.0 if d_tau > 0 else -1.0
        if compliance is not None and compliance[1] != direction:
            compliance = None  # the load reversed: a new branch
        expected = compliance[0] * d_tau if compliance is not None else math.nan
        ratio = d_theta / expected if compliance is not None and expected != 0 else math.nan
        warn, hedge = None, False
        if abs(d_theta) < _STILL_SIGMAS * sigma:
            warn = ("no_movement", f"no movement: Δangle {d_theta:+.4f}° for a planned torque step "
                                   f"of {d_tau:+.5f} N·m (an extra shot of the same load, or no "
                                   "weight changed?)")
        elif d_theta * d_tau < 0:
            warn = ("wrong_direction", f"wrong direction: Δangle {d_theta:+.4f}° for a planned "
                                       f"torque step of {d_tau:+.5f} N·m (the wrong pans loaded, "
                                       "files out of order, or a wrong angle_sign?)")
        elif compliance is not None and (ratio < _SMALL or _LARGE[0] < ratio < _LARGE[1]):
            small = ratio < _SMALL
            nxt = steps[k + 1] if k + 1 < len(steps) else None
            hedge = not (nxt is not None and single(nxt[1]) and nxt[1] * d_tau > 0)
            if nxt is None and open_end:
                after_warning = False
                continue  # undecided until the next image: neither a warning nor a reference
            if not hedge:
                follow = (nxt[2] / nxt[1]) / (d_theta / d_tau)  # the next step's compliance / this one's
                confirmed = follow >= _RECOVERY if small else follow <= _GOES_ON
            else:
                confirmed = True
            tell = ("the next step will tell" if nxt is None else
                    "the same step elsewhere in the loop will tell")
            if confirmed and small:
                warn = ("small_step", f"step out of line: Δangle {d_theta:+.4f}° is {ratio:.2f}× "
                                      f"the previous step's {expected:+.4f}° (a weight piece "
                                      "forgotten on a pan?"
                                      + (f" or the gear stiffening: {tell}" if hedge else "")
                                      + ")")
            elif confirmed:
                warn = ("large_step", f"step out of line: Δangle {d_theta:+.4f}° is {ratio:.2f}× "
                                      f"the previous step's {expected:+.4f}° (a missed shot, or an "
                                      "extra weight piece?"
                                      + (f" or the gear softening: {tell}" if hedge else "")
                                      + ")")
        if warn is None:
            if not after_warning:  # the step after a mistake makes up for it: no reference
                compliance = (d_theta / d_tau, direction)
            after_warning = False
        else:
            out.append(StepWarning(i, warn[0], d_theta, d_tau, ratio, warn[1], decided=not hedge,
                                   torque_span_nm=span))
            after_warning = True
    return out


def first_load_inverted(points) -> int | None:
    """Whether the first loaded image of a sequence turned against its torque.

    Parameters
    ----------
    points : sequence of StepPoint
        An orientation's images in capture order, its reference (zero torque) first,
        angles with the session's ``angle_sign`` applied.

    Returns
    -------
    int or None
        The position of the first image with a planned torque and an angle when
        that angle's sign is opposite to the torque's by more than 5 σ (the
        ``angle_sign`` is inverted, or the wrong pans were loaded); None when it
        turned with the torque, or there is no such image yet. The first load is
        the largest step of a session (the reference to ±T_max): a sign read there
        is unambiguous.
    """
    for i, p in enumerate(points[1:], start=1):
        if p.torque_nm == 0 or p.angle_deg is None or not math.isfinite(p.angle_deg):
            continue
        still = abs(p.angle_deg) < _STILL_SIGMAS * math.hypot(p.angle_std_deg, points[0].angle_std_deg)
        return i if (p.angle_deg * p.torque_nm < 0 and not still) else None
    return None


def gear_kinks(warnings) -> set[int]:
    """The undecided warnings that are the gear's own change of stiffness.

    An out-of-line step at the end of a branch has no next step of its branch to
    confirm it: a weight piece forgotten there and the gear stiffening there look
    the same. The gear's kink recurs: at the same load on the other side of the
    loop (the planned torques' magnitudes the same, moving away from or towards
    zero alike), in the next cycle, in the next orientation; a mistake happens
    once. Two undecided warnings of one kind at such a step, with ratios within a
    factor 1.5 of each other, are both the gear's.

    Parameters
    ----------
    warnings : sequence of StepWarning
        The warnings of every sequence of a session (any order).

    Returns
    -------
    set of int
        Positions in `warnings` of those that are the gear's (not mistakes).
    """
    def key(w):
        a, b = (abs(t) for t in w.torque_span_nm)
        return w.kind, round(min(a, b), 9), round(max(a, b), 9), b > a

    groups: dict = {}
    for n, w in enumerate(warnings):
        if not w.decided and len(w.torque_span_nm) == 2 and w.kind in ("small_step", "large_step"):
            groups.setdefault(key(w), []).append(n)
    out: set[int] = set()
    for members in groups.values():
        for n in members:
            r = warnings[n].ratio
            if any(m != n and 1 / 1.5 <= warnings[m].ratio / r <= 1.5 for m in members):
                out.add(n)
    return out
