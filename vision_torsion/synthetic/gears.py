"""Gears with kinks: responses of a torque sequence besides the paper's bilinear model.

The capture-mistake checks (:mod:`vision_torsion.session.steps`) must tell a gear's own
change of stiffness from a mistake at the rig; these are the gears they are tried on
(``tests/test_rig_mistakes.py``, ``benchmarks/bench_capture.py``), with the paper's
bilinear model (:func:`~vision_torsion.analysis.models.bilinear_response`):

- :func:`three_segment_response`: a spring stiffening twice with the load, behind
  friction (a play on the torque): its compliance peaks where the felt torque passes
  zero, and the first step after each reversal is shortened by the play;
- :func:`masing_response`: Masing's rule on a stiffening skeleton curve, every branch
  the skeleton doubled from its reversal: the compliance falls all along a branch.

Both take the torque sequence in the order it was applied (N·m; between two samples
the torque changes monotonically) and return angles in radians relative to the first
sample, positive with positive torque.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["three_segment_response", "masing_response"]


def three_segment_response(torque_nm, *, breaks_nm=(0.02, 0.05), stiffness_nm_per_rad=(1.0, 2.5, 6.0),
                           play_nm: float = 0.004) -> np.ndarray:
    """Angles (rad) of a three-segment spring behind friction, for a torque sequence.

    Parameters
    ----------
    torque_nm : array_like, shape (n,)
        Applied torque, N·m, in the order applied.
    breaks_nm : (float, float)
        Felt-torque magnitudes (N·m) where the stiffness changes.
    stiffness_nm_per_rad : (float, float, float)
        Stiffness below, between and above the breaks (N·m/rad).
    play_nm : float
        Friction torque (N·m): after a reversal the applied torque must move by
        twice this before the spring follows (a play operator on the torque).

    Returns
    -------
    numpy.ndarray, shape (n,)
        Angle (rad) relative to the first sample.

    Examples
    --------
    >>> th = three_segment_response([0.0, 0.01, 0.03, 0.01])
    >>> bool(th[2] > th[1] > 0 and th[3] < th[2])
    True
    """
    tau = np.asarray(torque_nm, float)
    (b1, b2), (k1, k2, k3) = breaks_nm, stiffness_nm_per_rad

    def spring(t):
        a = abs(t)
        th = min(a, b1) / k1 + max(min(a, b2) - b1, 0) / k2 + max(a - b2, 0) / k3
        return math.copysign(th, t)

    out, felt = [], 0.0
    for t in tau:
        felt = min(max(felt, t - play_nm), t + play_nm)
        out.append(spring(felt))
    return np.asarray(out) - out[0]


def masing_response(torque_nm, *, k_low_nm_per_rad: float = 0.8, k_high_nm_per_rad: float = 5.0,
                    tau0_nm: float = 0.03) -> np.ndarray:
    """Angles (rad) of a Masing gear for a torque sequence.

    The skeleton is ``θ(τ) = τ/k_high + (τ0/k_low − τ0/k_high)·tanh(τ/τ0)`` (stiffness
    `k_low` at zero torque, `k_high` far from it), followed from the first sample
    (the gear at rest there); after the first reversal every branch is the
    skeleton scaled by two from its reversal point (Masing's rule).

    Parameters
    ----------
    torque_nm : array_like, shape (n,)
        Applied torque, N·m, in the order applied.
    k_low_nm_per_rad, k_high_nm_per_rad : float
        Stiffness at zero torque and far from it (N·m/rad).
    tau0_nm : float
        Torque scale of the change between them (N·m).

    Returns
    -------
    numpy.ndarray, shape (n,)
        Angle (rad) of each sample, 0 at the first (the gear at rest there).

    Examples
    --------
    >>> th = masing_response([0.0, 0.06, 0.0, -0.06, 0.06])
    >>> bool(abs(th[4] - th[1]) < 1e-12 and th[2] < th[1])
    True
    """
    tau = np.asarray(torque_nm, float)

    soft = tau0_nm / k_low_nm_per_rad - tau0_nm / k_high_nm_per_rad

    def skeleton(t):
        return t / k_high_nm_per_rad + soft * math.tanh(t / tau0_nm)

    out = [0.0]
    rev_t, rev_th, direction, reversed_ = float(tau[0]), 0.0, 0.0, False
    for i in range(1, len(tau)):
        d = np.sign(tau[i] - tau[i - 1])
        if d and d != direction:
            if direction:
                rev_t, rev_th, reversed_ = float(tau[i - 1]), out[-1], True
            direction = d
        scale = 2.0 if reversed_ else 1.0
        out.append(rev_th + scale * skeleton((tau[i] - rev_t) / scale))
    return np.asarray(out)
