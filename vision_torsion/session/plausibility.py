"""Plausibility of a session's numbers: unit slips caught before anything is measured.

A mass typed in grams (``360`` for 0.36 kg) or an arm radius in millimetres
(``arm_radius_m = 50``) is a valid number, and without these checks gave torques a
thousand times the session's own planned maximum, with status ``ok``. Checked
here, against the session's protocol and against physical ranges, with the unit and
the likely slip in the message:

- ``[rig] arm_radius_m`` within :data:`ARM_RADIUS_RANGE_M`; ``gravity_m_per_s2``
  within :data:`GRAVITY_RANGE_M_PER_S2` (the Earth's surface);
  ``[protocol] step_mass_kg`` within :data:`STEP_MASS_RANGE_KG`; at most
  :data:`MAX_STEPS_PER_PHASE` weight pieces per pan at ``max_torque_nm`` (a torque
  in N·mm, or a step mass in tonnes, would ask for millions);
- every manifest ``mass_kg`` a whole number of ``step_mass_kg`` pieces, and no more
  pieces than the protocol loads at ``max_torque_nm`` (what ``plan`` would put on
  a pan); a mass 1000 times too large is asked about as grams;
- every measured ``torque_nm`` at most :data:`TORQUE_SLIP_FACTOR` times the
  protocol's ``max_torque_nm`` (beyond that it is a unit slip, N·mm for N·m, not a
  sensor reading a little above the plan).

These are the one home of the rules: ``plan`` applies the configuration's
(:func:`check_config_numbers`) before it writes anything, ``process`` and every
command that loads a session apply them all (:func:`check_session_numbers`), so a
plan that ``process`` would refuse is never written. Each lists every problem at
once, like the manifest's own checks: the configuration's by key, the manifest's by
CSV line.
"""

from __future__ import annotations

import math

from ..errors import ManifestError, SessionError

__all__ = ["check_session_numbers", "check_config_numbers", "ARM_RADIUS_RANGE_M", "GRAVITY_RANGE_M_PER_S2",
           "STEP_MASS_RANGE_KG", "TORQUE_SLIP_FACTOR", "MAX_STEPS_PER_PHASE"]

#: Radius of a torque arm or disk where the wires pull (m): 1 mm to 2 m.
ARM_RADIUS_RANGE_M = (1e-3, 2.0)
#: Gravitational acceleration at the Earth's surface (m/s²), poles to equator with
#: altitude: 9.76 to 9.84.
GRAVITY_RANGE_M_PER_S2 = (9.76, 9.84)
#: One weight piece (kg): 0.1 g to 50 kg.
STEP_MASS_RANGE_KG = (1e-4, 50.0)
#: Most weight pieces on one pan at the protocol's maximum torque (steps per phase):
#: each is placed by hand and photographed four times per cycle.
MAX_STEPS_PER_PHASE = 1000
#: A measured torque this many times the planned maximum is a unit slip.
TORQUE_SLIP_FACTOR = 10.0
# masses are typed with a few decimals: 0.02 * 18 is written 0.36
_WHOLE_TOLERANCE = 1e-6


def _config_problems(config) -> list[str]:
    rig, proto = config.rig, config.protocol
    problems = []
    lo, hi = ARM_RADIUS_RANGE_M
    r = rig.arm_radius_m
    if not lo <= r <= hi:
        hint = (": millimetres? (write metres, e.g. 0.05)" if lo <= r / 1000 <= hi
                else ": centimetres?" if lo <= r / 100 <= hi else "")
        problems.append(f"rig.arm_radius_m = {r:g} m is outside {lo:g}..{hi:g} m{hint}")
    lo, hi = GRAVITY_RANGE_M_PER_S2
    g = rig.gravity_m_per_s2
    if not lo <= g <= hi:
        hint = ": cm/s²? (write m/s², e.g. 9.81)" if lo <= g / 100 <= hi else ""
        problems.append(f"rig.gravity_m_per_s2 = {g:g} m/s² is outside the Earth's "
                        f"{lo:g}..{hi:g} m/s²{hint}")
    lo, hi = STEP_MASS_RANGE_KG
    m = rig.step_mass_kg
    if not lo <= m <= hi:
        hint = ": grams? (write kg, e.g. 0.02)" if lo <= m / 1000 <= hi else ""
        problems.append(f"protocol.step_mass_kg = {m:g} kg is outside {lo:g}..{hi:g} kg{hint}")
    if not problems and _pieces(config) > MAX_STEPS_PER_PHASE:
        problems.append(f"protocol.max_torque_nm = {proto.max_torque_nm:g} N·m needs "
                        f"{_pieces(config):.3g} pieces of {m:g} kg per pan, more than the "
                        f"{MAX_STEPS_PER_PHASE} a protocol may load (N·mm for N·m? a step mass too small?)")
    return problems


def check_config_numbers(config, *, source=None) -> None:
    """Check the rig and protocol of a session.toml for unit slips (the module docstring).

    Parameters
    ----------
    config : SessionConfig
        The validated session.toml.
    source : path or str, optional
        The file (or ``"plan_session"``), for the message.

    Raises
    ------
    SessionError
        Every implausible value listed, by key, with its unit and the likely slip.
    """
    problems = _config_problems(config)
    if problems:
        where = f"{source}: " if source is not None else ""
        raise SessionError(f"{where}{len(problems)} implausible value(s)\n  " + "\n  ".join(problems))


def _pieces(config) -> float:
    return config.protocol.max_torque_nm / config.rig.step_torque_nm


def _max_pieces(config) -> int:
    """Pieces per pan at the protocol's maximum torque (tau = 2 m g r), as plan loads."""
    return int(math.floor(_pieces(config) + 1e-6))


def _row_problems(config, manifest) -> list[str]:
    proto, step = config.protocol, config.rig.step_mass_kg
    most = _max_pieces(config)
    top_mass = most * step
    problems = []
    for row in manifest.rows:
        if row.mass_kg is not None and row.mass_kg > 0:
            pieces = row.mass_kg / step
            whole = round(pieces)
            if abs(pieces - whole) > _WHOLE_TOLERANCE * max(1.0, pieces):
                problems.append(f"line {row.line}: mass_kg {row.mass_kg:g} kg is not a whole number "
                                f"of {step:g} kg pieces ({pieces:.4g} pieces)")
            elif whole > most:
                grams = (row.mass_kg / 1000 <= top_mass + 1e-9
                         and abs(row.mass_kg / 1000 / step - round(row.mass_kg / 1000 / step)) < 1e-6)
                hint = ": grams? (write kg)" if grams else ""
                problems.append(f"line {row.line}: mass {row.mass_kg:g} kg on each pan is {whole} pieces, "
                                f"more than the {most} ({top_mass:g} kg) the protocol loads for "
                                f"max_torque_nm {proto.max_torque_nm:g} N·m{hint}")
        if row.torque_nm is not None and abs(row.torque_nm) > TORQUE_SLIP_FACTOR * proto.max_torque_nm:
            ratio = abs(row.torque_nm) / proto.max_torque_nm
            hint = ": N·mm? (write N·m)" if ratio > 300 else ""
            problems.append(f"line {row.line}: torque_nm {row.torque_nm:g} N·m is {ratio:.3g} times the "
                            f"protocol's max_torque_nm {proto.max_torque_nm:g} N·m{hint}")
    return problems


def check_session_numbers(config, manifest, *, config_path=None) -> None:
    """Check the session's numbers for unit slips (see the module docstring).

    Parameters
    ----------
    config : SessionConfig
        The validated session.toml.
    manifest : Manifest
        The validated manifest.
    config_path : path, optional
        For the configuration's messages.

    Raises
    ------
    SessionError
        The rig or protocol numbers are physically implausible (every one listed,
        by key, with its unit and the likely slip).
    ManifestError
        Manifest masses that are not a whole number of pieces or more than the
        protocol loads, or measured torques far beyond the protocol's maximum
        (every one listed, by CSV line).
    """
    check_config_numbers(config, source=config_path)
    problems = _row_problems(config, manifest)
    if problems:
        raise ManifestError(f"{manifest.path}: {len(problems)} problem(s) (line numbers are CSV lines, "
                            "the header is line 1)\n  " + "\n  ".join(problems))
