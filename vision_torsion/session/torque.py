"""Force-couple torque from the weights on the pans, with its GUM standard uncertainty.

The rig of the main paper (seed 001) applies a pure couple: two wires pull
tangentially at radius r on opposite sides of the torque disk, each carrying a pan
with mass m, so ``tau = 2 * m * g * r`` (0.0981 N·m per 100 g at r = 0.05 m). One pair
of pans gives positive torque, the other negative; the phase of a manifest row says
which pair is loaded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..measurements import PHASE_SIGN, PHASES, TorqueRig, couple_torque_nm, pieces_per_pan

# PHASES, PHASE_SIGN and pieces_per_pan are defined in vision_torsion.measurements
# (the one home of the measurements vocabulary) and re-exported here.
__all__ = ["TorqueValue", "PHASES", "PHASE_SIGN", "couple_torque", "pieces_per_pan"]


@dataclass(frozen=True)
class TorqueValue:
    """A torque with its uncertainty.

    Attributes
    ----------
    torque_nm : float
        Signed torque (N·m).
    torque_std_nm : float
        Combined standard uncertainty of this image's torque (N·m).
    torque_common_std_nm : float
        The part of `torque_std_nm` that is fully correlated between all images of the
        session (from r and g: a common scale error, N·m). It does not scatter the
        points of a torque-angle curve; it scales every stiffness by the same factor.
    """

    torque_nm: float
    torque_std_nm: float
    torque_common_std_nm: float


def couple_torque(mass_kg: float, phase: str, rig: TorqueRig) -> TorqueValue:
    """Torque of a force couple with `mass_kg` on each pan of the loaded pair.

    Parameters
    ----------
    mass_kg : float
        Mass on each of the two pans of the loaded pair (kg), >= 0.
    phase : str
        One of :data:`PHASES`; gives the sign (``positive_*`` +, ``negative_*`` -,
        ``reference`` and ``closing`` 0).
    rig : TorqueRig
        r, g and their uncertainties, the mass of one weight piece (to count the
        pieces on a pan) and its uncertainty, and the friction term.

    Returns
    -------
    TorqueValue

    Notes
    -----
    The model is ``tau = s * g * r * (m1 + m2) + tau_f`` with ``m1 = m2 = m`` the
    masses on the two pans, ``s`` the sign of the phase and ``tau_f`` the friction
    torque of the pulleys (nominally 0, standard uncertainty ``u_f``). Each pan
    holds ``n = ceil(m / step_mass_kg)`` pieces whose mass errors are independent,
    each with standard uncertainty ``u_w`` (``mass_tolerance_kg / sqrt(3)`` or
    ``mass_std_kg``). By the law of propagation of uncertainty (GUM 5.1.2) with
    uncorrelated inputs:

    .. math::

        u^2(\\tau) = (2 m r)^2 u^2(g) + (2 m g)^2 u^2(r)
                     + (g r)^2 \\, 2 n u_w^2 + u_f^2

    Correlation between images: ``g`` and ``r`` are the same for every image, so
    their part ``|tau| * sqrt((u_g/g)^2 + (u_r/r)^2)`` is fully correlated
    (:attr:`TorqueValue.torque_common_std_nm`). The pieces are reused, so mass
    errors of images sharing pieces are partly correlated: this value is each
    image's marginal uncertainty, and the analysis models the correlations between
    images (``torque_correlation="pieces"`` in :mod:`vision_torsion.analysis.uncertainty`).
    Pulley friction is taken as independent per image.

    Examples
    --------
    >>> rig = TorqueRig(step_mass_kg=0.02, arm_radius_m=0.05, mass_std_kg=0.0)
    >>> round(couple_torque(0.1, "negative_loading", rig).torque_nm, 6)
    -0.0981
    """
    sign = PHASE_SIGN[phase]
    g, r = rig.gravity_m_per_s2, rig.arm_radius_m
    n = pieces_per_pan(mass_kg, rig.step_mass_kg)
    tau = sign * couple_torque_nm(mass_kg, gravity_m_per_s2=g, arm_radius_m=r)
    var_g = (2.0 * mass_kg * r * rig.gravity_std_m_per_s2) ** 2
    var_r = (2.0 * mass_kg * g * rig.arm_radius_std_m) ** 2
    var_m = (g * r) ** 2 * 2.0 * n * rig.mass_std_kg**2
    std = math.sqrt(var_g + var_r + var_m + rig.friction_torque_std_nm**2)
    return TorqueValue(torque_nm=tau + 0.0, torque_std_nm=std,
                       torque_common_std_nm=math.sqrt(var_g + var_r))
