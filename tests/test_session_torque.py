"""Force-couple torque and its GUM uncertainty."""

import math

import pytest

from vision_torsion.measurements import TorqueRig
from vision_torsion.session.torque import PHASES, couple_torque, pieces_per_pan


def rig(**kw):
    base = dict(step_mass_kg=0.02, arm_radius_m=0.05, mass_std_kg=0.0)
    base.update(kw)
    return TorqueRig(**base)


def test_paper_value_per_100_g():
    # The paper: 0.0981 N·m per 100 g at r = 0.05 m (tau = 2 m g r, g = 9.81).
    t = couple_torque(0.1, "positive_loading", rig())
    assert t.torque_nm == pytest.approx(0.0981, rel=1e-12)


@pytest.mark.parametrize("phase, sign", [("reference", 0), ("positive_unloading", 1),
                                         ("negative_loading", -1),
                                         ("negative_unloading", -1),
                                         ("positive_loading", 1)])
def test_sign_from_phase(phase, sign):
    mass = 0.0 if phase == "reference" else 0.06
    t = couple_torque(mass, phase, rig())
    assert t.torque_nm == pytest.approx(sign * 2 * mass * 9.81 * 0.05, abs=0)
    assert set(PHASES) >= {phase}


def test_gum_uncertainty_against_hand_computation():
    # 0.1 kg per pan of 20 g pieces: 5 pieces per pan, 10 pieces in all.
    # u_w = 0.1 g / sqrt(3); u_g = 0.01; u_r = 0.1 mm; u_f = 2e-4 N·m.
    u_w = 1e-4 / math.sqrt(3)
    r = rig(mass_std_kg=u_w, gravity_std_m_per_s2=0.01, arm_radius_std_m=1e-4,
            friction_torque_std_nm=2e-4)
    t = couple_torque(0.1, "negative_unloading", r)
    # hand computation, term by term (N·m):
    dg = 2 * 0.1 * 0.05 * 0.01            # d tau/d g * u_g  = 1.0e-4
    dr = 2 * 0.1 * 9.81 * 1e-4            # d tau/d r * u_r  = 1.962e-4
    dm = 9.81 * 0.05 * math.sqrt(10) * u_w  # 10 independent pieces = 8.955e-5
    expected = math.sqrt(dg**2 + dr**2 + dm**2 + 2e-4**2)
    assert expected == pytest.approx(3.1067e-4, rel=1e-4)  # sqrt(9.651e-8)
    assert t.torque_std_nm == pytest.approx(expected, rel=1e-12)
    assert t.torque_common_std_nm == pytest.approx(math.hypot(dg, dr), rel=1e-12)
    # the common part is a pure scale error: |tau| * relative uncertainty of g*r
    assert t.torque_common_std_nm == pytest.approx(
        abs(t.torque_nm) * math.hypot(0.01 / 9.81, 1e-4 / 0.05), rel=1e-12)


def test_reference_has_only_friction_uncertainty():
    t = couple_torque(0.0, "reference", rig(mass_std_kg=1e-4, friction_torque_std_nm=3e-4))
    assert (t.torque_nm, t.torque_std_nm, t.torque_common_std_nm) == (0.0, 3e-4, 0.0)


@pytest.mark.parametrize("mass, pieces", [(0.0, 0), (0.02, 1), (0.36, 18), (0.05, 3),
                                          (0.06000000000000001, 3)])
def test_pieces_per_pan(mass, pieces):
    assert pieces_per_pan(mass, 0.02) == pieces
