"""Plan a test session: session.toml, the manifest of every image, a capture sheet.

The protocol
------------
Per orientation (default the paper's six: 0°, 60°, ..., 300°):

1. **reference**: one image with no weight on any pan (zero torque), taken before
   anything is loaded at this orientation. All angles of the orientation are
   measured against it.
2. **pre-load** (not photographed): add one step mass at a time to each positive
   pan up to +Tmax. The state reached this way is not on the hysteresis loop yet,
   so it is not measured, except its end point (step 0 below).
3. ``cycles`` times the paper's four phases, each in N steps of one step mass per
   pan: **positive_unloading** (+Tmax → 0), **negative_loading** (0 → −Tmax),
   **negative_unloading** (−Tmax → 0), **positive_loading** (0 → +Tmax).

Every load state is photographed once: step k of a phase is the state after the
k-th weight change of that phase, so a phase's starting state is the last image of
the phase before it. The only step 0 is the start of the first positive_unloading of
an orientation (+Tmax right after the pre-load). An orientation thus has
``1 + 1 + 4 N cycles`` images.

Tmax is snapped **down** to a whole number N of step masses per pan
(``N = floor(max_torque_nm / (2 g r step_mass_kg))``) so the requested maximum is
never exceeded; the capture sheet and the returned plan say when it was not exact.

Lost-motion levels (``rated_torque_nm``)
----------------------------------------
With a rated torque T_R, the plan names load levels at ±3 % (GB/T 35089) and ±4 %
(harmonic-drive catalogues) of T_R; lost motion at level x is the loop's mid-point
at +x minus its mid-point at −x. A level is realised by the nearest whole number k
of step masses per pan. Because every phase steps one piece at a time through 0..N
pieces, the state of k pieces is already photographed in every phase of every cycle
(+x in positive_unloading and positive_loading, −x in negative_loading and
negative_unloading): the levels are steps of the existing phases, so the manifest,
the analysis and the mass checks are unchanged. A level that rounds to 0 pieces,
misses by more than :data:`LOST_MOTION_TOLERANCE` of itself, needs more pieces than
the protocol loads, or shares its pieces with the other level is refused, naming a
step mass that realises it (a finer piece means a finer step mass for the whole
protocol: the manifest has one piece size). T_R is recorded in session.toml as
``[gear] rated_torque_nm`` (what the analysis reads for lost motion) and stated in
``plan``'s output and on the capture sheets.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

from ..errors import SessionError, TargetError
from ..fileio import atomic_write_text, check_replaceable
from ..images import IMAGE_SUFFIXES
from ..measurements import CYCLE_PHASES, PHASES, couple_torque_nm
from ..targets import Target, load_target
from ..validate import check_number
from .config import CONFIG_NAME, DEFAULT_ORIENTATIONS_DEG, SessionConfig, config_from_dict, config_to_dict, write_config
from .manifest import MANIFEST_NAME, MAX_MANIFEST_ROWS, REQUIRED_COLUMNS, manifest_text
from .plausibility import check_config_numbers
from .torque import couple_torque

__all__ = ["SessionPlan", "LostMotionLevel", "plan_config", "plan_session", "plan_rows", "lost_motion_levels",
           "CAPTURE_SHEET_NAME", "LOST_MOTION_FRACTIONS", "LOST_MOTION_TOLERANCE", "HEADER_KEYS", "MAX_PLAN_IMAGES"]

logger = logging.getLogger(__name__)

CAPTURE_SHEET_NAME = "capture_sheet.md"
#: The test's identity given to the planner: header key -> (session.toml table, key).
HEADER_KEYS = {"gear": ("gear", "name"), "serial": ("gear", "serial"), "operator": ("test", "operator"),
               "date": ("test", "date"), "notes": ("test", "notes")}

#: Most images a plan may have, checked before anything is written (a manifest row,
#: a capture-sheet line and a photograph each; ~10 MB of files at this size).
MAX_PLAN_IMAGES = MAX_MANIFEST_ROWS  # what process may read
#: Lost-motion levels as fractions of the rated torque: ±3 % (GB/T 35089) and ±4 %
#: (harmonic-drive catalogues).
LOST_MOTION_FRACTIONS = (0.03, 0.04)
#: A level is refused when the nearest whole number of pieces misses it by more than
#: this fraction of the level.
LOST_MOTION_TOLERANCE = 0.25


@dataclass(frozen=True)
class LostMotionLevel:
    """One lost-motion level: ±`fraction` of the rated torque, as planned.

    Attributes
    ----------
    fraction : float
        The level asked for, as a fraction of the rated torque (0.03).
    requested_torque_nm : float
        ``fraction * rated_torque_nm`` (N·m).
    pieces : int
        Step masses per pan that realise it (the nearest whole number).
    torque_nm : float
        The torque those pieces make, ``2 pieces step g r`` (N·m).
    achieved_fraction : float
        ``torque_nm / rated_torque_nm``.
    """

    fraction: float
    requested_torque_nm: float
    pieces: int
    torque_nm: float
    achieved_fraction: float

    @property
    def label(self) -> str:
        """"±3 %" for the sheet."""
        return f"±{_num(self.fraction * 100)} %"


def lost_motion_levels(rated_torque_nm: float, *, step_mass_kg: float, torque_per_step_nm: float,
                       steps_per_phase: int, fractions=LOST_MOTION_FRACTIONS,
                       tolerance: float = LOST_MOTION_TOLERANCE) -> tuple[LostMotionLevel, ...]:
    """The lost-motion levels of a rated torque with the rig's weight pieces.

    Raises
    ------
    SessionError
        A rated torque that is not a number > 0; a level that rounds to 0 pieces,
        misses by more than `tolerance` of itself, needs more pieces than
        `steps_per_phase`, or is realised by the same pieces as another level. The
        message names the level and a step mass that realises the levels
        (1 % of the rated torque per piece realises ±3 % and ±4 % exactly).

    >>> [(lv.pieces, round(lv.torque_nm, 5)) for lv in lost_motion_levels(
    ...     6.0, step_mass_kg=0.02, torque_per_step_nm=0.01962, steps_per_phase=20)]
    [(9, 0.17658), (12, 0.23544)]
    """
    rated = check_number(rated_torque_nm, name="plan_session: rated_torque_nm", error=SessionError,
                         low=0, low_open=True, unit="N·m")
    # one piece per pan making 1 % of T_R realises 3 % and 4 % exactly
    one_percent_kg = step_mass_kg * (0.01 * rated) / torque_per_step_nm
    suggest = (f"a step mass of {one_percent_kg:.4g} kg ({one_percent_kg * 1000:.4g} g, 1 % of the rated "
               "torque per piece) realises ±3 % and ±4 % exactly")
    levels: list[LostMotionLevel] = []
    for fraction in fractions:
        wanted = fraction * rated
        name = (f"plan_session: lost-motion level ±{_num(fraction * 100)} % of the rated torque "
                f"{rated:g} N·m (±{wanted:.5g} N·m)")
        exact_pieces = wanted / torque_per_step_nm
        pieces = int(math.floor(exact_pieces + 0.5))
        if pieces == 0:
            raise SessionError(
                f"{name} is {exact_pieces:.3g} pieces of {step_mass_kg:g} kg per pan "
                f"({torque_per_step_nm:.5g} N·m per piece): it rounds to 0 pieces; {suggest}")
        achieved = pieces * torque_per_step_nm
        miss = abs(achieved - wanted) / wanted
        if miss > tolerance:
            raise SessionError(
                f"{name}: the nearest whole number, {pieces} piece(s) of {step_mass_kg:g} kg per pan, "
                f"gives ±{achieved:.5g} N·m = {100 * achieved / rated:.3g} % of the rated torque, "
                f"{100 * miss:.0f} % off the level (more than the {100 * tolerance:g} % allowed); {suggest}")
        if pieces > steps_per_phase:
            raise SessionError(
                f"{name} needs {pieces} pieces of {step_mass_kg:g} kg per pan, more than the "
                f"{steps_per_phase} the protocol loads (max torque "
                f"{steps_per_phase * torque_per_step_nm:.5g} N·m); raise the maximum torque or steps")
        for other in levels:
            if other.pieces == pieces:
                raise SessionError(
                    f"{name} is realised by the same {pieces} piece(s) of {step_mass_kg:g} kg per pan "
                    f"as the level {other.label}: the two cannot be told apart; {suggest}")
        levels.append(LostMotionLevel(fraction=fraction, requested_torque_nm=wanted, pieces=pieces,
                                      torque_nm=float(f"{achieved:.12g}"),
                                      achieved_fraction=achieved / rated))
    return tuple(levels)


@dataclass(frozen=True)
class SessionPlan:
    """What :func:`plan_session` wrote.

    Attributes
    ----------
    folder : pathlib.Path
    config : SessionConfig
    rows : tuple of dict
        The manifest rows (column name → text), in capture order.
    steps_per_phase : int
        N, the step masses per pan at full torque.
    requested_max_torque_nm, max_torque_nm : float
        The maximum asked for and the one planned (a whole number of steps).
    torque_per_step_nm : float
        ``2 m g r`` of one step mass per pan (N·m).
    preconditioning_cycles : int
        Full cycles to ±Tmax before each orientation's reference image, not
        photographed.
    closing : bool
        A ``closing`` image at zero torque ends each orientation.
    header : dict
        Test metadata for the capture sheet (gear, serial, operator, date).
    rated_torque_nm : float or None
        The rated torque T_R given (N·m), also written to session.toml's
        ``[gear] rated_torque_nm``.
    lost_motion_levels : tuple of LostMotionLevel
        The ±3 % and ±4 % levels of T_R (empty without a rated torque): steps of
        the existing phases, see the module docstring.
    """

    folder: Path
    config: SessionConfig
    rows: tuple[dict, ...]
    steps_per_phase: int
    requested_max_torque_nm: float
    max_torque_nm: float
    torque_per_step_nm: float = math.nan
    preconditioning_cycles: int = 0
    closing: bool = False
    header: dict = field(default_factory=dict)
    rated_torque_nm: float | None = None
    lost_motion_levels: tuple = ()

    def level_label(self, pieces: int, phase: str) -> str:
        """"+3 % T_R" when a row of `pieces` per pan in `phase` is a lost-motion level, else ""."""
        if phase not in CYCLE_PHASES:
            return ""
        sign = "+" if phase.startswith("positive") else "−"
        return " / ".join(f"{sign}{_num(lv.fraction * 100)} % T_R" for lv in self.lost_motion_levels
                          if lv.pieces == pieces)

    def lost_motion_text(self) -> str:
        """One sentence naming T_R and the levels as planned ("" without a rated torque)."""
        if self.rated_torque_nm is None:
            return ""
        step = self.config.rig.step_mass_kg
        parts = [f"{lv.label} → {lv.pieces} × {_num(step * 1000)} g per pan = ±{lv.torque_nm:.5f} N·m "
                 f"({100 * lv.achieved_fraction:.3g} % of T_R)" for lv in self.lost_motion_levels]
        return (f"Rated torque T_R = {self.rated_torque_nm:g} N·m (session.toml: [gear] rated_torque_nm). "
                "Lost-motion levels (lost motion = loop mid-point at +x minus at −x), photographed "
                "as steps of every phase: " + "; ".join(parts) + ".")

    @property
    def nearest_max_torques_nm(self) -> tuple[float, float]:
        """The achievable maxima (whole numbers of steps) at or below and above the
        requested one (N·m)."""
        n, step = self.steps_per_phase, self.torque_per_step_nm
        below = n * step
        above = below if self.exact else (n + 1) * step
        return float(f"{below:.12g}"), float(f"{above:.12g}")

    @property
    def exact(self) -> bool:
        """True when the requested maximum torque is a whole number of steps."""
        return math.isclose(self.max_torque_nm, self.requested_max_torque_nm,
                            rel_tol=1e-9)


def _num(value: float) -> str:
    """Short, exact-looking text for a planned number (0.06, not 0.060000000000000005)."""
    value = round(float(value), 10)
    return str(int(value)) if value.is_integer() else repr(value)


def _image_name(orientation: float, cycle: int, phase: str, step: int, *,
                cycle_width: int, step_width: int, suffix: str) -> str:
    o = f"{int(orientation):03d}" if float(orientation).is_integer() else \
        _num(orientation).replace(".", "p")
    return (f"images/o{o}_c{cycle:0{cycle_width}d}_{PHASES.index(phase) + 1:02d}_{phase}"
            f"_s{step:0{step_width}d}{suffix}")


def _phase_masses(phase: str, n: int, first: bool) -> list[tuple[int, int]]:
    """(step, pieces per pan) of a phase; `first` adds step 0 (+Tmax) to an unloading."""
    steps = range(0 if first else 1, n + 1)
    unloading = phase.endswith("unloading")
    return [(k, n - k if unloading else k) for k in steps]


def plan_rows(config: SessionConfig, steps_per_phase: int, *, suffix: str = ".png",
              closing: bool = False) -> list[dict]:
    """Manifest rows of the protocol described in the module docstring, in order.

    >>> from vision_torsion.session.config import config_from_dict
    >>> cfg = config_from_dict({"rig": {"arm_radius_m": 0.05, "mass_tolerance_kg": 0},
    ...     "protocol": {"orientations_deg": [0], "max_torque_nm": 0.04,
    ...                  "step_mass_kg": 0.02}})
    >>> [(r["phase"], r["step"], r["mass_kg"]) for r in plan_rows(cfg, 2)][:4]  # doctest: +NORMALIZE_WHITESPACE
    [('reference', '0', '0'), ('positive_unloading', '0', '0.04'), ('positive_unloading', '1', '0.02'),
     ('positive_unloading', '2', '0')]
    """
    proto = config.protocol
    widths = dict(cycle_width=len(str(proto.cycles)), step_width=max(2, len(str(steps_per_phase))), suffix=suffix)
    rows = []

    def add(orientation, cycle, phase, step, pieces):
        rows.append(
            {
                "image": _image_name(orientation, cycle, phase, step, **widths),
                "orientation_deg": _num(orientation),
                "cycle": str(cycle),
                "phase": phase,
                "step": str(step),
                "mass_kg": _num(pieces * config.rig.step_mass_kg),
            }
        )

    for orientation in proto.orientations_deg:
        add(orientation, 1, "reference", 0, 0)
        for cycle in range(1, proto.cycles + 1):
            for phase in CYCLE_PHASES:
                first = cycle == 1 and phase == "positive_unloading"
                for step, pieces in _phase_masses(phase, steps_per_phase, first):
                    add(orientation, cycle, phase, step, pieces)
        if closing:  # unloaded to zero (not photographed), then one image
            add(orientation, proto.cycles, "closing", 0, 0)
    return rows


def _pan_text(pieces: int, step_mass_kg: float) -> str:
    if pieces == 0:
        return "empty"
    return f"{_num(pieces * step_mass_kg * 1000)} g ({pieces} × {_num(step_mass_kg * 1000)} g)"


def _capture_sheet(plan: SessionPlan) -> str:
    cfg, n = plan.config, plan.steps_per_phase
    rig = cfg.rig
    step, per_step = rig.step_mass_kg, rig.step_torque_nm
    lines = [
        "# Capture sheet",
        "",
        f"Arm radius r = {_num(rig.arm_radius_m)} m, g = {_num(rig.gravity_m_per_s2)} m/s², "
        f"step mass {_num(step * 1000)} g per pan = {per_step:.5f} N·m per step "
        "(τ = 2·m·g·r).",
        f"Maximum torque {plan.max_torque_nm:.5f} N·m = {n} steps"
        + (
            "."
            if plan.exact
            else f" (requested {plan.requested_max_torque_nm:g} N·m is not a whole number of "
            "steps; snapped down; the nearest achievable maxima are "
            f"{plan.nearest_max_torques_nm[0]:.5f} and {plan.nearest_max_torques_nm[1]:.5f} N·m)."
        ),
        "",
        *([plan.lost_motion_text(), ""] if plan.rated_torque_nm is not None else []),
        '"+ pans" are the two pans whose wires turn the disk in the positive direction, '
        '"− pans" the other two. Masses are per pan: both pans of a pair always carry '
        "the same mass. Wait for the disk to settle before each photograph, and save it "
        "under the file name given (relative to this folder).",
        "",
    ]
    if cfg.markers.pair == "distinct":
        lines += [
            "Target: two markers of clearly different radii (the smaller at most 0.85× the "
            "larger), so which marker is which is certain at any angle.",
            "",
        ]
    else:
        lines += [
            "Target: two equal markers. Which is which is tracked from image to image: keep "
            "the turn between consecutive photographs small (under 30°), or use a target "
            "with two markers of clearly different radii (`plan --target distinct`).",
            "",
        ]
    current = None
    number = 0
    for row in plan.rows:
        orientation = row["orientation_deg"]
        if orientation != current:
            current = orientation
            lines += [
                f"## Orientation {orientation}°",
                "",
                f"Rotate the flexspline to {orientation}° relative to the circular spline. Remove all weights.",
                "",
                "| # | cycle | phase | step | + pans (each) | − pans (each) | torque (N·m) | save as | done |",
                "|---|---|---|---|---|---|---|---|---|",
            ]
        pieces = round(float(row["mass_kg"]) / step)
        torque = couple_torque(float(row["mass_kg"]), row["phase"], rig).torque_nm
        plus = _pan_text(pieces if row["phase"].startswith("positive") else 0, step)
        minus = _pan_text(pieces if row["phase"].startswith("negative") else 0, step)
        number += 1
        level = plan.level_label(pieces, row["phase"])
        lines.append(
            f"| {number} | {row['cycle']} | {row['phase']} | {row['step']} | "
            f"{plus} | {minus} | {torque:+.5f}{f' ({level})' if level else ''} | `{row['image']}` | ☐ |"
        )
        if row["phase"] == "reference" and plan.preconditioning_cycles:
            lines.insert(
                len(lines) - 1,
                f"| | | *preconditioning, no photographs* | | load to "
                f"+{plan.max_torque_nm:.5f} and −{plan.max_torque_nm:.5f} N·m "
                f"{plan.preconditioning_cycles} time(s), then unload | | | | ☐ |",
            )
        if row["phase"] == "reference":
            lines.append(
                f"| | | *pre-load, no photographs* | | add {_num(step * 1000)} g "
                f"to each + pan {n} times | empty | → {plan.max_torque_nm:+.5f} | "
                "| ☐ |"
            )
    return "\n".join(lines) + "\n"


def _header(config: SessionConfig) -> dict:
    """The test's identity in `config` as :data:`HEADER_KEYS` keys (for the capture sheet)."""
    out = {}
    for key, (table, name) in HEADER_KEYS.items():
        value = getattr(getattr(config, table), name)
        if value is not None and str(value).strip():
            out[key] = str(value)
    return out


def _described_target(target) -> Target:
    """The N-marker target `target` names (a Target, a ready target's name, a file)."""
    try:
        return target if isinstance(target, Target) else load_target(target)
    except TargetError as exc:
        raise SessionError(f"plan_config: target must be 'equal', 'distinct' or a target description: {exc}",
                           reason=exc.reason) from exc


def _add_catalogue(doc: dict, catalogue, *, rated_torque_nm) -> None:
    """Copy the catalogue file's ``[gear]`` and ``[spec]`` entries into the session.toml
    document `doc`; a rated torque given besides must be the catalogue's."""
    from .config import load_catalogue

    cat_gear, cat_spec = load_catalogue(catalogue)
    if rated_torque_nm is not None and cat_gear.rated_torque_nm not in (None, float(rated_torque_nm)):
        raise SessionError(f"plan_config: rated_torque_nm {rated_torque_nm:g} differs from the catalogue file's "
                           f"{cat_gear.rated_torque_nm:g} ({catalogue}); give one")
    for table, entries in (("gear", cat_gear), ("spec", cat_spec)):
        given = {k: v for k, v in vars(entries).items() if v is not None}
        if given:
            doc.setdefault(table, {}).update(given)


def plan_config(
    *,
    max_torque_nm: float | None = None,
    steps: int | None = None,
    step_mass_kg: float,
    arm_radius_m: float,
    orientations_deg=DEFAULT_ORIENTATIONS_DEG,
    cycles: int = 1,
    gravity_m_per_s2: float = 9.81,
    mass_tolerance_kg: float = 1e-4,
    friction_torque_std_nm: float = 0.0,
    arm_radius_std_m: float = 0.0,
    gravity_std_m_per_s2: float = 0.0,
    polarity: str = "dark",
    radius_range=None,
    angle_sign: int = 1,
    target="equal",
    header: dict | None = None,
    rated_torque_nm: float | None = None,
    catalogue=None,
) -> SessionConfig:
    """The :class:`~vision_torsion.session.config.SessionConfig` of a new session
    from the planner's values (``vision-torsion plan``'s options), validated as
    session.toml is (:func:`~vision_torsion.session.config.config_from_dict`).

    Parameters
    ----------
    max_torque_nm : float, optional
        Largest torque magnitude (N·m); :func:`plan_session` snaps it down to whole
        step masses (and names the nearest achievable maxima below and above).
    steps : int, optional
        Steps per phase instead of `max_torque_nm` (give exactly one of the two):
        the maximum torque is `steps` step torques 2·m·g·r.
    step_mass_kg : float
        Mass added to or removed from each pan per step (kg).
    arm_radius_m : float
        Radius of the torque disk at the wires (m).
    orientations_deg : sequence of float
        Flexspline orientations (degrees), the paper's six by default.
    cycles : int
        Cycles of the four phases per orientation.
    gravity_m_per_s2, mass_tolerance_kg, friction_torque_std_nm, arm_radius_std_m,
    gravity_std_m_per_s2 :
        Rig constants written to ``[rig]`` (see :class:`~vision_torsion.measurements.TorqueRig`);
        `mass_tolerance_kg` is the ± bound of one weight piece (the paper's ±0.1 g
        by default).
    polarity, radius_range :
        Marker settings written to ``[markers]``.
    angle_sign : {1, -1}
        Written to ``angle_sign``.
    target : {"equal", "distinct"}, Target, str or os.PathLike
        Two equal markers (identity tracked between images), two markers of
        clearly different radii (``pair = "distinct"`` in ``[markers]``: identity
        certain at any angle, recommended), or an N-marker target (a
        :class:`~vision_torsion.targets.Target`, a ready target's name such as
        ``"ring16"``, or a target file), written to session.toml as ``[target]``.
    header : dict, optional
        The test's identity (keys ``gear``, ``serial``, ``operator``, ``date``,
        ``notes``, see :data:`HEADER_KEYS`): session.toml's ``[gear] name``/``serial``
        and ``[test] operator``/``date``/``notes``, from where the capture sheet,
        the report and summary.json take them.
    rated_torque_nm : float, optional
        The gear's rated torque T_R (N·m), ``[gear] rated_torque_nm``: the plan names
        the lost-motion levels at ±3 % and ±4 % of it (:func:`lost_motion_levels`).
    catalogue : path-like, optional
        The gear type's catalogue file (``[gear]`` ratio, rated torque, T1/T2 and
        ``[spec]`` limits, :func:`~vision_torsion.session.config.load_catalogue`),
        copied into ``[gear]`` and ``[spec]``; its rated torque is taken when
        `rated_torque_nm` is not given (a different one is refused).

    Returns
    -------
    SessionConfig

    Raises
    ------
    SessionError
        Invalid values (named as their session.toml keys), both or neither of
        `max_torque_nm` and `steps`, `steps` not a whole number >= 1, an unknown
        header key, a target that is neither ``equal``, ``distinct`` nor a readable
        target description (the reason of its :class:`TargetError` kept), a
        catalogue file that is invalid or whose rated torque differs.

    Examples
    --------
    >>> config = plan_config(steps=18, step_mass_kg=0.02, arm_radius_m=0.05)
    >>> round(config.protocol.max_torque_nm, 5), round(config.rig.step_torque_nm, 5)
    (0.35316, 0.01962)
    """
    if (max_torque_nm is None) == (steps is None):
        raise SessionError("plan_config: give either max_torque_nm or steps (steps per phase), not both or neither")
    if steps is not None:
        steps = check_number(steps, name="plan_config: steps", error=SessionError, low=1, whole=True)
        step_nm = couple_torque_nm(step_mass_kg, gravity_m_per_s2=gravity_m_per_s2, arm_radius_m=arm_radius_m)
        max_torque_nm = float(f"{steps * step_nm:.12g}")
    markers = {"polarity": polarity}
    described = None
    if isinstance(target, str) and target in ("equal", "distinct"):
        if target == "distinct":
            markers["pair"] = "distinct"
    else:
        described = _described_target(target)
    if radius_range is not None:
        markers["radius_range"] = list(radius_range)
    doc = {
        "angle_sign": angle_sign,
        "rig": {
            "arm_radius_m": arm_radius_m,
            "gravity_m_per_s2": gravity_m_per_s2,
            "mass_tolerance_kg": mass_tolerance_kg,
            "friction_torque_std_nm": friction_torque_std_nm,
            "arm_radius_std_m": arm_radius_std_m,
            "gravity_std_m_per_s2": gravity_std_m_per_s2,
        },
        "markers": markers,
        "protocol": {
            "orientations_deg": [float(o) for o in orientations_deg],
            "max_torque_nm": max_torque_nm,
            "step_mass_kg": step_mass_kg,
            "cycles": cycles,
        },
    }
    if catalogue is not None:
        _add_catalogue(doc, catalogue, rated_torque_nm=rated_torque_nm)
    if rated_torque_nm is not None:
        doc.setdefault("gear", {})["rated_torque_nm"] = rated_torque_nm
    header = {k: v for k, v in (header or {}).items() if v is not None and str(v).strip()}
    unknown = sorted(set(header) - set(HEADER_KEYS))
    if unknown:
        raise SessionError(f"plan_config: header key(s) {', '.join(map(repr, unknown))} unknown; "
                           f"expected some of {', '.join(HEADER_KEYS)}")
    for key, value in header.items():
        table, name = HEADER_KEYS[key]
        doc.setdefault(table, {})[name] = str(value)
    if described is not None:
        doc["target"] = {"name": described.name, **{k: v for k, v in described.spec if v is not None}}
    return config_from_dict(doc, source="plan_config")


def plan_session(
    config: SessionConfig,
    out_dir,
    *,
    image_suffix: str = ".png",
    overwrite: bool = False,
    preconditioning_cycles: int = 0,
    closing: bool = False,
    pdf: bool = False,
) -> SessionPlan:
    """Write a new session folder: session.toml, manifest.csv, capture sheets, images/.

    Parameters
    ----------
    config : SessionConfig
        The session to plan: rig, protocol, markers or target, the test's identity
        (``[gear]``, ``[test]``: printed on the capture sheet, blank fields to fill in
        by hand otherwise) and catalogue limits; from :func:`plan_config`, or any
        :class:`~vision_torsion.session.config.SessionConfig` (it is validated as
        session.toml is). The protocol's ``max_torque_nm`` is snapped down to whole
        step masses (the plan names the nearest achievable maxima below and above);
        with ``[gear] rated_torque_nm`` the plan names the lost-motion levels at ±3 %
        and ±4 % of it, realised by whole numbers of step masses (see
        :func:`lost_motion_levels`; refused when they cannot be).
    out_dir : str or os.PathLike
        The session folder to create (may exist if it holds no session yet).
    image_suffix : str
        File type of the images to save (".png", ".tif", ...).
    overwrite : bool
        Replace an existing session.toml / manifest.csv in `out_dir`.
    preconditioning_cycles : int
        Full cycles to +Tmax and −Tmax before each reference image, to settle the
        gear; on the capture sheet, not photographed.
    closing : bool
        End each orientation with a ``closing`` image at zero torque, after the last
        cycle is unloaded back to zero (not photographed on the way).
    pdf : bool
        Also print the capture sheet to ``capture_sheet.pdf`` with a headless
        Chromium, when one is installed (:mod:`.sheet`); ``capture_sheet.html`` is
        always written.

    Returns
    -------
    SessionPlan

    Raises
    ------
    SessionError
        An invalid configuration (named as its session.toml keys), a maximum torque
        below one step, or a folder that already holds a session; lost-motion levels
        the weight pieces cannot realise; numbers ``process`` would refuse as
        implausible (:func:`~vision_torsion.session.plausibility.check_config_numbers`:
        an arm radius in mm, g in cm/s², more than
        :data:`~vision_torsion.session.plausibility.MAX_STEPS_PER_PHASE` pieces per
        pan); more than :data:`MAX_PLAN_IMAGES` images. All checked before anything
        is written.

    Examples
    --------
    >>> import tempfile
    >>> config = plan_config(max_torque_nm=0.36, step_mass_kg=0.02, arm_radius_m=0.05)
    >>> plan = plan_session(config, tempfile.mkdtemp())
    >>> plan.steps_per_phase, round(plan.max_torque_nm, 5), plan.exact, len(plan.rows)
    (18, 0.35316, False, 444)
    """
    folder = Path(out_dir)
    if not isinstance(config, SessionConfig):
        raise SessionError(f"plan_session: config must be a SessionConfig (see plan_config), "
                           f"got {type(config).__name__}")
    config = config_from_dict(config_to_dict(config), source="plan_session")  # checked as session.toml is
    preconditioning_cycles = check_number(preconditioning_cycles, name="plan_session: preconditioning_cycles",
                                          error=SessionError, low=0, whole=True)
    check_config_numbers(config, source="plan_session")  # what process would refuse, refused now
    if image_suffix.lower() not in IMAGE_SUFFIXES:
        raise SessionError(
            f"plan_session: image_suffix {image_suffix!r} is not an image "
            f"type; expected one of {', '.join(IMAGE_SUFFIXES)}"
        )
    per_step = config.rig.step_torque_nm
    max_torque_nm = config.protocol.max_torque_nm
    n = math.floor(max_torque_nm / per_step + 1e-9)
    planned_max = float(f"{n * per_step:.12g}")  # no 0.35316000000000003 in the file
    if n < 1:
        raise SessionError(
            f"plan_session: max_torque_nm {max_torque_nm:g} is less than one "
            f"step (2·step_mass_kg·g·r = {per_step:.6g} N·m)"
        )
    images = len(config.protocol.orientations_deg) * (2 + 4 * n * config.protocol.cycles + bool(closing))
    if images > MAX_PLAN_IMAGES:
        raise SessionError(
            f"plan_session: {images} images ({len(config.protocol.orientations_deg)} orientation(s) × "
            f"(2 + 4 phases × {n} steps × {config.protocol.cycles} cycle(s))), more than the "
            f"{MAX_PLAN_IMAGES} a plan may have; fewer orientations, cycles or steps"
        )
    rated_torque_nm = config.gear.rated_torque_nm
    levels = () if rated_torque_nm is None else lost_motion_levels(
        rated_torque_nm, step_mass_kg=config.rig.step_mass_kg, torque_per_step_nm=per_step, steps_per_phase=n)
    existing = [name for name in (CONFIG_NAME, MANIFEST_NAME) if (folder / name).exists()]
    if existing and not overwrite:
        raise SessionError(
            f"{folder}: already holds a session ({', '.join(existing)}); choose another folder or overwrite"
        )
    from .sheet import CAPTURE_SHEET_HTML, CAPTURE_SHEET_PDF

    check_replaceable(folder / name for name in (CONFIG_NAME, MANIFEST_NAME, CAPTURE_SHEET_NAME,
                                                 CAPTURE_SHEET_HTML, CAPTURE_SHEET_PDF))
    planned = replace(config, protocol=replace(config.protocol, max_torque_nm=planned_max))
    plan = SessionPlan(
        folder=folder,
        config=planned,
        rows=tuple(plan_rows(planned, n, suffix=image_suffix, closing=closing)),
        steps_per_phase=n,
        requested_max_torque_nm=float(max_torque_nm),
        max_torque_nm=planned_max,
        torque_per_step_nm=per_step,
        preconditioning_cycles=int(preconditioning_cycles),
        closing=bool(closing),
        header=_header(config),
        rated_torque_nm=None if rated_torque_nm is None else float(rated_torque_nm),
        lost_motion_levels=levels,
    )
    if not plan.exact:
        below, above = plan.nearest_max_torques_nm
        logger.warning(
            "maximum torque %.6g N·m is not a whole number of %.6g kg steps; "
            "planned %d steps = %.6g N·m (the nearest achievable maxima are %.6g N·m "
            "with %d steps and %.6g N·m with %d; or give --steps)",
            max_torque_nm,
            config.rig.step_mass_kg,
            n,
            plan.max_torque_nm,
            below,
            n,
            above,
            n + 1,
        )
    (folder / "images").mkdir(parents=True, exist_ok=True)
    write_config(
        folder / CONFIG_NAME,
        planned,
        header="vision-torsion session (written by `vision-torsion plan`).\n"
        "Units are in the key names; see docs/sessions.md for the format.",
    )
    atomic_write_text(folder / MANIFEST_NAME, manifest_text(REQUIRED_COLUMNS, plan.rows))
    atomic_write_text(folder / CAPTURE_SHEET_NAME, _capture_sheet(plan))
    from .sheet import write_capture_sheet

    write_capture_sheet(plan, pdf=pdf)
    return plan
