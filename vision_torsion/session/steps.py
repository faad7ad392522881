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
- **out of line**: the step is not what the gear does there. What the gear does
  is known from the **same step elsewhere in the loop** (the same planned torque
  magnitudes, moving away from zero or back towards it alike: the other side of
  the loop, an earlier cycle) when that one fitted: out of line beyond 8 % of it.
  Before the loop has shown it (the first half-loop), the previous step of the
  branch is the reference, carried on by the branch's trend (e = its compliance ×
  the ratio of the last two steps' when that is within 2×, else 1, × Δτ; a step
  over a row without a photograph is no reference): out of line below 0.87 e or
  between 1.6 e and 2.6 e (for the last step of a closed sequence, which no next
  step decides, below 0.6 e: a gear drifts along a branch by less).

An out-of-line step is decided with the step after it, by which explains both:

- the gear's own change of stiffness (the switch, a kink: the paper's bilinear
  compliance jumps by k_u/k_l ≈ 15 where the load passes zero and back at ±τ_c,
  and a jump inside a step gives any ratio between): no warning, and the new
  compliance is taken;
- a weight piece forgotten (one piece short while loading, one too many while
  unloading: half a step): the step falls short and the next makes up for it
  (against the same steps elsewhere: the next step's excess is this one's
  shortfall within 30 %; against the previous step: the next step's compliance ≥
  1.8× this one's, a dip no single kink makes). At the end of a branch the first
  step back tells: it starts half a step early. On the first step after a kink
  (a jump beyond 4×, where nothing in the loop has shown the steps yet) the half
  step is taken for the kink and the one and a half for the gear: the step after
  them tells, going on at their mean (within 8 %) while they are 3× apart
  (within 20 %): said then, on the step it happened at;
- a missed shot (two planned steps in one: every later file shows the load of the
  row after its own): the step's excess over the same step elsewhere in the loop
  is the next planned step there (within 30 %), and the next photograph shows the
  step after that one (within 20 %; against the
  previous step: ≈ 2 e then ≈ e, the next ≤ 0.7× this one, and, when the previous
  step is the first after a kink (a jump beyond 4×), which may hold the switch
  anywhere in it, the next going on like it within 15 %). Before a turning load the next photograph already
  turns back, by as much as the first step back from a turning load elsewhere in
  the loop (unlike this branch's step reversed: two photographs taken the other way
  round, which ``watch`` and ``bind`` find by exchanging them), and only where the
  plan's load does turn back after the next row (``plan_after``).

A mistake's signature (0.5, 2 or 0 of a step) is far from the gear's by many times
the scatter of a step ratio (σ_Δ/Δθ ≈ 0.3 % for 0.25° steps at 0.0005° noise), and
a gear's compliance along a branch rises to one peak (where the felt torque passes
zero) and falls after it: it has no dip, and no single step that its neighbours'
sum explains. After an extra or a missed shot is decided, the steps after it are
checked as bound with its fix (the files a row late or early), so one mistake gives
one warning, on the image where it happened; a flagged step, and the step after it,
are not used as a reference. A live sequence's newest step has no next step yet:
``watch`` waits for the next image (``open_end``), and judges from the images so
far only (``hindsight=False``), so that a verdict once said stays. A closed
sequence (``bind``) compares each step with the same step anywhere in the loop,
later ones included. Only the last step of a closed sequence cannot be decided: it
is warned about, undecided, and it is the gear's when the same step elsewhere (in
another orientation) shows it too (:func:`gear_kinks`). Checked only across one or
two planned weight steps (not across the unphotographed pre-load or the return to
zero before a closing image) and only between images of one orientation; a step
this orientation's loop has not shown yet is compared with the same step of the
loops photographed before it (``earlier``: the earlier orientations, the gear's
own stiffness at that torque already seen), so a later orientation's first
half-loop is judged as its second half is, and a kink seen there is expected, not
a mistake. In the first half-loop of the session's first orientation nothing has
shown the steps yet: a mistake where the gear's stiffness changes by more than the
mistake's signature (a missed shot inside a soft zone or at the switch, a piece
forgotten on the step of the switch) looks like the gear there, and cannot be told from it
until the load reverses (the load turning back a row early, which ``watch`` names
with the rows that fit; against the same step in the second half, in ``bind``).
These are warnings for the person at the rig, not a
statistical test; the false-alarm rate on the paper's loops is tested
(tests/test_rig_bind_inputs.py), and the kinked gears of
:mod:`vision_torsion.synthetic.gears` in tests/test_rig_mistakes.py and
benchmarks/bench_capture.py; ``bind`` tries fixes against them (:mod:`.bind`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

__all__ = ["StepPoint", "StepWarning", "check_steps", "step_misfit", "first_load_inverted", "gear_kinks",
           "WARNING_KINDS"]

#: Kinds of step warning.
WARNING_KINDS = ("no_movement", "wrong_direction", "small_step", "large_step")
_STILL_SIGMAS = 5.0
_SMALL = 0.87
_ALONE = 0.6
_TREND = 2.0
_LARGE = (1.6, 2.6)
_RECOVERY = 1.8
_GOES_ON = 0.7
_SAME_TOL = 1.4
_SAME_FIT = 1.08
_FORGOTTEN = 1 / _SAME_FIT
_MADE_UP = 0.3
_SUM_TOL = 1.2
_EARLY = 1.15
_KINK = 4.0


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
    awaiting_next : bool
        An open sequence's newest step (not decided: the next photograph decides
        it) that is already a missed shot's signature: against the same steps
        elsewhere in the loop (or in an earlier loop) it is off by the next planned
        step's angle and equals the two planned steps together. Said at once,
        because the next photograph may never come (the plan's last row) or be
        another orientation's reference.
    """

    index: int
    kind: str
    delta_angle_deg: float
    delta_torque_nm: float
    ratio: float
    message: str
    decided: bool = True
    torque_span_nm: tuple = ()
    awaiting_next: bool = False


def check_steps(points, *, step_torque_nm: float, open_end: bool = False,
                hindsight: bool | None = None, earlier=(), plan_after=None) -> list[StepWarning]:
    """Warnings for the steps of one orientation's image sequence (module docstring).

    Parameters
    ----------
    points : sequence of StepPoint
        The orientation's images in capture order, the reference (zero torque) first.
    step_torque_nm : float
        Torque of one planned weight step, ``2 m g r`` (N·m).
    open_end : bool
        The sequence goes on (a live one): an out-of-line newest step, which only
        the next step can decide, is not reported yet (``watch`` reports it at the
        next image, or never when the next shows the gear's own change of
        stiffness: an expected change of stiffness is not a mistake). False: it is
        reported, saying the next step would tell.
    hindsight : bool, optional
        Compare each step with the same step elsewhere in the loop, later images
        included (a closed sequence, ``bind``: the default when not `open_end`).
        False: only with the images before it and the next one, so that each
        verdict stays as it was said as the sequence grows (``watch``).
    earlier : sequence of sequences of StepPoint
        The session's loops photographed before this one (the earlier
        orientations' complete sequences, in capture order). A step that this
        sequence has not shown yet is compared with the same step of the latest of
        them that shows it (the gear's own stiffness at that torque, already
        seen), so the first half-loop of a later orientation is judged as its
        second half is, and a kink seen there is expected, not a mistake.
    plan_after : sequence of float, optional
        The planned torques (N·m) of the orientation's rows after the last
        point's, in plan order (empty: the last point is the orientation's last
        row; None: not known). A photograph turning back a row before the load
        does is a missed shot only where the plan turns back after the next row
        (else it is two photographs taken the other way round, or another
        mistake); inside the sequence the next point tells.

    Returns
    -------
    list of StepWarning
        In sequence order; at most one per image. An out-of-line step is decided
        with the step after it (module docstring): a forgotten piece when the next
        step makes up for it, a missed shot when the two planned steps fit it,
        else the gear's own change of stiffness (no warning; the new compliance is
        taken). Only the last step of a closed sequence cannot be decided: it is
        warned about, undecided (:attr:`StepWarning.decided`).
    """
    hindsight = not open_end if hindsight is None else hindsight
    after = None if plan_after is None else tuple(float(t) for t in plan_after)
    return _checked(points, step_torque_nm, open_end, hindsight, _known(earlier, step_torque_nm), after)[0]


def _known(earlier, step_torque_nm) -> dict:
    """Place in the loop -> compliance of the steps that fitted in the loops
    `earlier`, from the latest loop that shows it."""
    known: dict = {}
    for loop in earlier:
        known.update({place: c[max(c)] for place, c in _checked(loop, step_torque_nm, False, True, {})[1].items()})
    return known


def _checked(points, step_torque_nm, open_end, hindsight, known, plan_after=None):
    """check_steps: the warnings, and the compliance by place in the loop of the
    steps that fitted, the sequence bound with the fixes of its mistakes."""
    points, origin = list(points), list(range(len(points)))
    out: list[StepWarning] = []
    done = 0  # warnings before this position of `points` are said already
    while True:
        found, seen = _scan(points, step_torque_nm, open_end, None if hindsight else {}, known, plan_after)
        found = [w for w in found if w.index >= done]
        shift = next((w for w in found if w.kind in ("no_movement", "large_step") and w.decided), None)
        out += [dataclasses.replace(w, index=origin[w.index]) for w in found
                if shift is None or w.index <= shift.index]
        if shift is None:
            return out, seen
        # the files after it are a row late (an extra shot) or a row early (a missed
        # shot): the rest is checked as bound with the fix, one mistake, one warning
        i, n = shift.index, len(points)
        if shift.kind == "no_movement":  # the last point's row is now the one after the new last
            plan_after = None if plan_after is None else (points[-1].torque_nm, *plan_after)
            points = points[:i] + [StepPoint(points[j - 1].torque_nm, points[j].angle_deg, points[j].angle_std_deg)
                                   for j in range(i + 1, n)]
            origin, done = origin[:i] + origin[i + 1:], i
        else:  # the last file shows the load of a row after the last: left out
            points = points[:i] + [StepPoint(points[j + 1].torque_nm, points[j].angle_deg, points[j].angle_std_deg)
                                   for j in range(i, n - 1)]
            origin, done = origin[:n - 1], i + 1


def _scan(points, step_torque_nm, open_end, prior=None, known=None, plan_after=None):
    """check_steps on `points` as bound (no re-binding after a mistake): the
    warnings, and the compliance of the steps that fitted by place in the loop.
    A closed sequence is looked at twice: the second time every step has the same
    step elsewhere in the loop, later ones included, to compare with. `known`:
    place -> compliance of earlier loops, for the steps this one has not shown.
    `plan_after`: as for check_steps."""
    steps = _steps(points)
    if prior is None:
        prior = _scan(points, step_torque_nm, open_end, prior={}, known=known, plan_after=plan_after)[1]
    state = _State(step_torque_nm, prior, known)
    out: list[StepWarning] = []
    for k, s in enumerate(steps):
        if not state.single(s.d_tau):
            state.new_branch(None)  # the pre-load, a return to zero
            continue
        direction = 1.0 if s.d_tau > 0 else -1.0
        if state.direction != direction:
            state.new_branch(direction)  # the load reversed: a new branch
        nxt = steps[k + 1] if k + 1 < len(steps) and state.single(steps[k + 1].d_tau) else None
        forgot = None if state.after_warning else _forgotten_after_kink(s, state)
        if forgot is not None:  # said on the step it happened at; the step making up for it is no reference
            out.append(forgot)
            state.flagged.update({forgot.index, state.run[-1][0].index})
            state.accept(s)
            state.before = None
            continue
        if k + 1 == len(steps) and open_end and state.out_of_line(s):
            # a missed shot's signature already: said now, undecided (not on the step after a
            # warning, which makes up for that mistake)
            early = None if state.after_warning else _two_in_one(s, state)
            state.after_warning = False
            if early is not None:
                out.append(early)
                state.flagged.add(s.index)
            continue  # undecided until the next image: not a reference
        warn = _judge(s, nxt, state, last=k + 1 == len(steps), turns=_turns(steps, k, plan_after))
        if warn is None:
            state.accept(s)
        else:
            out.append(warn)
            state.run = []
            state.after_warning = True
            state.flagged.add(s.index)
            state.shifted = state.shifted or (warn.decided and warn.kind in ("no_movement", "large_step"))
            if not warn.decided and not state.shifted:  # the last step: the gear, maybe; the second look decides it
                state.seen.setdefault(state.place(s.span), {})[s.index] = s.compliance
    return out, state.seen


def _steps(points) -> list:
    """The steps between consecutive images with an angle (:class:`_Step`)."""
    steps, prev = [], None
    for i, p in enumerate(points):
        if p.angle_deg is None or not math.isfinite(p.angle_deg):
            continue
        if prev is not None:
            q = points[prev]
            steps.append(_Step(i, p.torque_nm - q.torque_nm, p.angle_deg - q.angle_deg,
                               math.hypot(p.angle_std_deg, q.angle_std_deg), (q.torque_nm, p.torque_nm)))
        prev = i
    return steps


@dataclass(frozen=True)
class _Step:
    index: int
    d_tau: float
    d_theta: float
    sigma: float
    span: tuple

    @property
    def compliance(self) -> float:
        return self.d_theta / self.d_tau


class _State:
    """What the steps so far say of the gear: the compliance of the last step that
    fitted in this branch (local), and of every step that fitted, by its place in
    the loop (:func:`_place`: the same step elsewhere in the loop)."""

    def __init__(self, step_torque_nm, prior=None, known=None):
        self.step = step_torque_nm
        self.known = known or {}  # place in the loop -> compliance in an earlier loop of the session
        self.local = None  # compliance (deg/N·m) of the last step of this branch that fitted
        self.before = None  # and of the one that fitted before it (the branch's trend)
        self.direction = None
        self.seen: dict = {}  # place in the loop -> {step's image index: compliance} of steps that fitted
        self.prior = prior or {}  # the same, from a first look at a closed sequence
        self.flagged: set = set()  # image indices of the steps warned about
        self.shifted = False  # an extra or missed shot decided: the later files are bound a row off
        self.after_warning = False  # the step after a mistake makes up for it: no reference
        # the steps of this branch that fitted one after another, each with whether the same
        # step elsewhere in the loop (or an earlier loop) was known to compare it with
        self.run: list = []

    def single(self, d_tau) -> bool:
        return 0.5 < abs(d_tau) / self.step < 2.5

    def new_branch(self, direction) -> None:
        self.local, self.before, self.direction, self.after_warning = None, None, direction, False
        self.run = []

    def place(self, span):
        a, b = (round(abs(t) / self.step, 3) for t in span)
        return min(a, b), max(a, b), b > a

    def at(self, place, index):
        """Compliance of the step at `place` in the loop nearest before image `index`
        that fitted (in a closed sequence, else the nearest after it), else in an
        earlier loop of the session, or None."""
        found = dict(self.prior.get(place, {}))
        found.update(self.seen.get(place, {}))
        found = {i: c for i, c in found.items() if i != index and i not in self.flagged}
        before = [i for i in found if i < index]
        pick = max(before) if before else min(found, default=None)
        return self.known.get(place) if pick is None else found[pick]

    def same_step(self, s, span=None):
        """The expected angle step of `s` (or of the step over `span`, N·m, after
        it) from the same step elsewhere in the loop, the sum of the same single
        steps over a gap of two (None when not seen)."""
        a, b = span or s.span
        n = round(abs(b - a) / self.step)
        if n not in (1, 2):
            return None
        d = (b - a) / n
        cs = [self.at(self.place((a + j * d, a + (j + 1) * d)), s.index) for j in range(n)]
        return None if None in cs else sum(cs) * d

    def here(self, s) -> bool:
        """Whether this loop has shown the same step as `s` (not only an earlier loop)."""
        known, self.known = self.known, {}
        try:
            return self.same_step(s) is not None
        finally:
            self.known = known

    def expected(self, s):
        """(expected angle step, from the same step elsewhere?) or (None, False)."""
        e = self.same_step(s)
        if e is not None:
            return e, True
        if self.local is None:
            return None, False
        # the branch's trend goes on (a gear stiffening or softening along it by less than 2× a
        # step); after a kink (a jump beyond that) the new compliance holds
        trend = 1.0 if self.before is None else self.local / self.before
        trend = trend if 1 / _TREND <= trend <= _TREND else 1.0
        return self.local * trend * s.d_tau, False

    def out_of_line(self, s) -> bool:
        e, same = self.expected(s)
        if e is None or abs(s.d_theta) < _STILL_SIGMAS * s.sigma or s.d_theta * s.d_tau < 0:
            return False
        r = s.d_theta / e
        return abs(math.log(r)) > math.log(_SAME_FIT) if same else (r < _SMALL or _LARGE[0] < r < _LARGE[1])

    def kinked(self) -> bool:
        """Whether the reference step (:attr:`local`) came with a jump of the
        compliance beyond 4× from the step before it: a switch inside the step
        (the paper's is 15×; a gear stiffening by segments changes by their
        ratio, 2.5× for the three-segment gear, over a step or two)."""
        return (self.local is not None and self.before is not None
                and not 1 / _KINK <= self.local / self.before <= _KINK)

    def accept(self, s) -> None:
        if not self.after_warning and round(abs(s.d_tau) / self.step) != 1:
            self.before = self.local = None  # across a gap (a row without a photograph): no reference
            self.run = []
        elif not self.after_warning:
            self.run.append((s, self.same_step(s) is not None))
            self.before, self.local = self.local, s.compliance
            if not self.shifted:  # (check_steps looks at the rest again, bound with the fix)
                self.seen.setdefault(self.place(s.span), {})[s.index] = s.compliance
        else:
            self.run = []
        self.after_warning = False


def _turns(steps, k, plan_after) -> bool | None:
    """Whether the plan's load turns back after the row of step ``k + 1``'s
    image (None: not known): from the next image's row inside the sequence, from
    `plan_after` at its end."""
    if k + 1 >= len(steps):
        return None
    here, way = steps[k + 1].span[1], steps[k + 1].d_tau
    if k + 2 < len(steps):
        later = [steps[k + 2].span[1]]
    elif plan_after is None:
        return None
    else:
        later = list(plan_after)
    nxt = next((t for t in later if t != here), None)
    return nxt is not None and (nxt - here) * way < 0


def _judge(s, nxt, state, *, last, turns=None) -> StepWarning | None:
    """The warning of step `s` (None: it fits), decided with the step after it
    (`turns`: whether the plan's load turns back after its image's row, None when
    not known)."""
    if abs(s.d_theta) < _STILL_SIGMAS * s.sigma:
        return _warning(s, "no_movement", math.nan,
                        f"no movement: Δangle {s.d_theta:+.4f}° for a planned torque step of "
                        f"{s.d_tau:+.5f} N·m (an extra shot of the same load, or no weight changed?)")
    if s.d_theta * s.d_tau < 0:
        return _warning(s, "wrong_direction", math.nan,
                        f"wrong direction: Δangle {s.d_theta:+.4f}° for a planned torque step of "
                        f"{s.d_tau:+.5f} N·m (the wrong pans loaded, files out of order, or a "
                        "wrong angle_sign?)")
    if state.after_warning:
        return None
    e, same = state.expected(s)
    if e is not None and nxt is not None and turns is not False and _row_early(s, nxt, state, e, same):
        return _warning(s, "large_step", s.d_theta / e,
                        f"step out of line: Δangle {s.d_theta:+.4f}° is {s.d_theta / e:.2f}× the expected "
                        f"{e:+.4f}° and the next photograph already turns back as the load does one row "
                        "later: a missed shot (this photograph shows the next row's load)")
    if not state.out_of_line(s):
        return None
    ratio = s.d_theta / e
    what = ("the previous step's" if not same else "the same step elsewhere in the loop" if state.here(s)
            else "the same step in an earlier orientation")
    said = f"step out of line: Δangle {s.d_theta:+.4f}° is {ratio:.2f}× {what} {e:+.4f}°"
    if nxt is None and last:  # the end of the sequence: nothing can tell
        if not same and _ALONE <= ratio <= _LARGE[0]:  # a gear's drift along a branch looks the same
            return None
        small = ratio < 1
        return _warning(s, "small_step" if small else "large_step", ratio, said + (
            " (a weight piece forgotten on a pan? or the gear stiffening: the next step will tell)" if small
            else " (a missed shot, or an extra weight piece? or the gear softening: the next step will tell)"),
            decided=False)
    kind = _decide(s, nxt, state, e, same)
    if kind == "small_step":
        return _warning(s, kind, ratio, said + " and the next step makes up for it: a weight piece "
                                               "forgotten on a pan (or taken off too early)")
    if kind == "large_step":
        return _warning(s, kind, ratio, said + ", two planned steps in one: a missed shot (this "
                                               "photograph shows the next row's load)")
    return None


def _decide(s, nxt, state, e, same) -> str | None:
    """"small_step" (a forgotten piece), "large_step" (a missed shot) or None (the
    gear's own change of stiffness) for the out-of-line step `s`, from `nxt`."""
    if nxt is None:  # across the pre-load or a return to zero: nothing can tell
        return None
    ratio = s.d_theta / e
    if nxt.d_tau * s.d_tau < 0:  # the end of a branch: the first step back tells
        back = state.same_step(nxt)
        if back is None or ratio > 1 or nxt.d_theta * nxt.d_tau <= 0:
            return None
        # a piece forgotten at the turning load: the way back starts half a step early
        return "small_step" if nxt.d_theta / back < 1 / _SAME_TOL else None
    if nxt.d_theta * nxt.d_tau <= 0 or abs(nxt.d_theta) < _STILL_SIGMAS * nxt.sigma:
        return None  # no movement or back: an extra shot or a swap there, which tells nothing of this step
    e_next = state.same_step(nxt) if same else None
    if e_next is not None:  # which explains both steps: a piece forgotten, a missed shot, or the gear
        sign = 1.0 if s.d_tau > 0 else -1.0
        short = sign * (e - s.d_theta)  # the angle this step fell short of the same step elsewhere
        if ratio < _FORGOTTEN:  # a forgotten piece: the next step makes up for what this one lacks
            made_up = sign * (nxt.d_theta - e_next)
            return "small_step" if abs(made_up - short) < _MADE_UP * short else None
        # a missed shot: this step holds the next planned one too, and the next photograph
        # shows the load of the row after its own
        after = state.same_step(s, (nxt.span[1], nxt.span[1] + nxt.d_tau))
        if after is None or abs(math.log(nxt.d_theta / after)) > math.log(_SUM_TOL):
            return None
        return "large_step" if abs(-short - sign * e_next) < _MADE_UP * -short else None
    follow = nxt.compliance / s.compliance
    if ratio < _SMALL:
        return "small_step" if follow >= _RECOVERY else None
    if state.kinked() and abs(math.log(nxt.compliance / state.local)) > math.log(_EARLY):
        # the reference is the first step after a kink: the gear's switch may lie inside it (any
        # fraction of the new compliance); only the next step going on like it confirms it
        return None
    return "large_step" if _LARGE[0] < ratio < _LARGE[1] and follow <= _GOES_ON else None


def _row_early(s, nxt, state, e, same) -> bool:
    """Step `s` larger than expected and the next photograph turning back while the
    plan goes on: both a row early (a missed shot before the turning load), when
    the turn back is as large as the first step back from a turning load seen
    elsewhere in the loop, and unlike this branch's own step reversed (two
    photographs taken the other way round). Larger than expected: by 8 % against
    the same step elsewhere (`same`), else by 15 % against the branch's trend."""
    if not (nxt.d_tau * s.d_tau > 0 and nxt.d_theta * nxt.d_tau < 0
            and abs(nxt.d_theta) >= _STILL_SIGMAS * nxt.sigma and s.d_theta / e > (_SAME_FIT if same else _EARLY)):
        return False
    turn = nxt.span[1]
    back = state.at(state.place((turn, turn - nxt.d_tau)), nxt.index)
    if back is None:
        return False
    missed = abs(math.log(nxt.d_theta / (back * -nxt.d_tau)))
    swap_e, _ = state.expected(nxt)
    swapped = abs(math.log(-nxt.d_theta / swap_e)) if swap_e is not None and swap_e != 0 else math.inf
    return missed < math.log(_SAME_TOL) and missed < swapped


def _forgotten_after_kink(s, state) -> StepWarning | None:
    """A weight piece forgotten on the first step after a kink, decided at the
    step after the one that made up for it (`s`), where nothing in the loop has
    shown these steps yet: the forgotten step (``a``: half a step, the first
    after a compliance jump beyond 4×) and the next (``b``: one and a half) are
    3× apart within 20 %, and `s` goes on at their mean within 8 % (the zone's
    own compliance: the two steps are two of it, split a half step early). A
    switch inside ``a`` gives ``b`` the zone's compliance and ``a`` a part of
    it, whose mean with ``b`` is less than ``b``, not 3× ``a`` (a gear whose
    compliance peaks at ``b`` falls further after it). The warning of ``a``, or
    None."""
    if len(state.run) < 3 or state.expected(s)[1]:
        return None
    (p, _), (a, a_same), (b, b_same) = state.run[-3:]
    if a_same or b_same or not (p.index < a.index < b.index < s.index) or not state.single(a.d_tau):
        return None
    ca, cb = a.compliance, b.compliance
    if 1 / _KINK <= ca / p.compliance <= _KINK or cb / ca <= 0:
        return None
    zone = (ca + cb) / 2
    if (s.compliance / zone <= 0 or abs(math.log(cb / ca / 3)) > math.log(_SUM_TOL)
            or abs(math.log(s.compliance / zone)) > math.log(_SAME_FIT)):
        return None
    return _warning(a, "small_step", ca / zone,
                    f"step out of line: Δangle {a.d_theta:+.4f}° is {ca / zone:.2f}× the steps after it "
                    f"({zone * a.d_tau:+.4f}° each: the step after the next shows it) and the next step makes up "
                    "for it: a weight piece forgotten on a pan (or taken off too early)")


def _two_in_one(s, state) -> StepWarning | None:
    """The newest step `s` of an open sequence, not decided yet, when it is a
    missed shot's signature on its own: against the same step elsewhere in the
    loop (or an earlier loop) it is more than 8 % larger, and within 8 % of the
    same two planned steps together (this one and the next the plan makes in the
    same direction), nearer to them than to the one. A gear that repeats its loop
    gives the same step again within 8 %; one that changes its stiffness between
    loops changes a step by a factor, not by exactly its neighbour's angle. Else
    None."""
    e, same = state.expected(s)
    if not same or s.d_theta / e < _SAME_FIT:
        return None
    two = state.same_step(s, (s.span[0], s.span[1] + s.d_tau))
    if two is None or s.d_theta * two <= 0:
        return None
    off = abs(math.log(s.d_theta / two))
    if off > math.log(_SAME_FIT) or off > abs(math.log(s.d_theta / e)) / 2:
        return None
    what = "the same step elsewhere in the loop" if state.here(s) else "the same step in an earlier orientation"
    return dataclasses.replace(_warning(
        s, "large_step", s.d_theta / e,
        f"step out of line: Δangle {s.d_theta:+.4f}° is {s.d_theta / e:.2f}× {what} {e:+.4f}° and "
        f"{s.d_theta / two:.2f}× the next two planned steps together {two:+.4f}°: a missed shot? (this "
        "photograph would show the next row's load; or it and the next were taken the other way round: the "
        "next photograph will tell)", decided=False),
        awaiting_next=True)


def _warning(s, kind, ratio, message, *, decided=True) -> StepWarning:
    return StepWarning(s.index, kind, s.d_theta, s.d_tau, ratio, message, decided=decided, torque_span_nm=s.span)


def step_misfit(points, *, step_torque_nm: float, earlier=()) -> float:
    """How far a closed sequence's steps are from the same steps elsewhere in its loop.

    Two bindings of one session that leave no step warning each (a missed shot
    marked at either of two rows of a soft zone, say) are told apart by this: the
    right one puts every photograph at its own load, so each step is what the gear
    does there elsewhere in the loop.

    Parameters
    ----------
    points : sequence of StepPoint
        The images of one orientation in capture order (as for :func:`check_steps`).
    step_torque_nm : float
        Torque of one planned weight step (N·m).
    earlier : sequence of sequences of StepPoint
        The loops photographed before (as for :func:`check_steps`): a step this
        loop shows nowhere else is compared with the same step there.

    Returns
    -------
    float
        The sum over the steps (of one or two planned weight steps) with a same
        step elsewhere of ``|ln(Δθ / expected Δθ)|`` (0 for a perfectly
        repeating loop; dimensionless).
    """
    known = _known(earlier, step_torque_nm)
    seen = _scan(points, step_torque_nm, False, prior={}, known=known)[1]
    state = _State(step_torque_nm, seen, known)
    total = 0.0
    for s in _steps(points):
        e = state.same_step(s) if state.single(s.d_tau) else None
        if e and s.d_theta * e > 0:
            total += abs(math.log(s.d_theta / e))
    return total


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
        if (not w.decided and not w.awaiting_next and len(w.torque_span_nm) == 2
                and w.kind in ("small_step", "large_step")):
            groups.setdefault(key(w), []).append(n)
    out: set[int] = set()
    for members in groups.values():
        for n in members:
            r = warnings[n].ratio
            if any(m != n and 1 / 1.5 <= warnings[m].ratio / r <= 1.5 for m in members):
                out.add(n)
    return out
