"""Bind a camera's files to the manifest rows: ``vision-torsion bind``.

The camera's photographs (:mod:`.camera`: in capture order, copies and non-images
set aside) are assigned to the manifest rows in protocol (file) order, the first
photograph to the first row. Rows the user says were not photographed
(``missing``, CSV line numbers) get no file; files the user says are extra shots
(``skip``) get no row. The result is written to ``SESSION_DIR/binding.json``
(:mod:`.binding`); nothing is renamed, copied or written in the camera folder.

A count that matches is not enough: one extra shot and one missed shot cancel in
the count and mislabel every row between them. So every photograph is measured
(sharing ``process``'s cache) and the angle steps are checked against the plan
(:func:`~vision_torsion.session.steps.check_steps`). When a step does not fit,
the fixes that could explain it are tried on the whole session: a step without
movement (or in the wrong direction) may be an extra shot, so the file is left
out; a step twice as large as its neighbours (or in the wrong direction) may be a
missed shot, so the row is marked as not photographed. A fix is proposed, naming
the file and the row, with the command line that applies it, when it removes that
misfit and leaves fewer misfits in the whole session; then the next misfit, and so
on. Two photographs taken the other way round are found the same way (exchanging
them, ``swap``, makes their steps fit). A photograph of a wrong load (a weight
piece forgotten on a pan: its step half as large as expected, the next making up
for it) is left out with its row marked as not photographed (``drop``: both at
once, so that no other file moves). Of the fixes that leave as few misfits, the
one whose steps are the loop's own elsewhere (:func:`~.steps.step_misfit`; a step
off by 2× weighs as one misfit) is proposed. Misfits no re-binding explains are
listed with the file and the row.

Besides the steps, what the photographs themselves show is diagnosed, one line
each: an ``angle_sign`` inverted (the first loaded image of most orientations
turned against its torque: said once, and the steps are checked with the right
sign, so no good photograph is proposed for skipping), a photograph that could
not be measured (a half-written file keeps its row: nothing after it shifts), a
saturated or blurred one (the rule ``watch`` applies,
:func:`~vision_torsion.session.shots.image_warnings`), and a bumped camera or a
loosened target (:mod:`.axis`).
"""

from __future__ import annotations

import logging
import math
import shlex
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

from ..errors import SessionError
from ..fileio import check_output_dir, check_replaceable, same_folder
from ..measurements import output_folder
from .binding import BINDING_NAME, Binding, write_binding
from .camera import list_camera_files
from .load import Session, load_session
from .steps import StepPoint, check_steps, gear_kinks, step_misfit

__all__ = ["BindResult", "Fix", "bind_session", "row_text", "step_warnings"]

logger = logging.getLogger(__name__)
_MAX_FIXES = 8


@dataclass(frozen=True)
class Fix:
    """A proposed change to the binding.

    Attributes
    ----------
    kind : str
        "skip" (leave the camera file out: an extra shot), "missing" (the row was
        not photographed: a missed shot), "drop" (both: a photograph of a wrong
        load, a weight piece forgotten) or "swap" (this file and the next one were
        taken the other way round).
    file : str
        The camera file (the extra shot, or the first file after the gap).
    line : int
        The manifest CSV line concerned.
    message : str
        The proposal in words.
    """

    kind: str
    file: str
    line: int
    message: str


@dataclass(frozen=True)
class BindResult:
    """What :func:`bind_session` found and wrote.

    Attributes
    ----------
    binding : Binding
        The binding written (the files as ordered, with the user's skip/missing).
    binding_path : pathlib.Path or None
        Where it was written (None with ``write=False``).
    n_files, n_rows : int
        Photographs found (after copies and non-images) and manifest rows.
    leftovers : tuple of str
        Camera files left over after the last row.
    unphotographed : tuple of (int, str)
        (CSV line, image) of rows with no file.
    ignored : tuple of (str, str)
        Camera files set aside, with why.
    warnings : tuple of str
        Steps of the binding as written that do not fit the plan, each naming the
        file and the row.
    fixes : tuple of Fix
        Proposed changes, in capture order.
    remaining : tuple of str
        Misfits still there after the proposed fixes (not explained by binding; the
        same as `warnings` when no fix is proposed).
    command : str or None
        The ``vision-torsion bind`` command line applying the fixes.
    diagnoses : tuple of str
        What the photographs themselves show, one line each, naming file and row:
        an inverted ``angle_sign`` (one line; the steps are then checked with the
        right sign, so it proposes no fix), photographs not measured (a stalled,
        half-written file keeps its row), saturated or blurred ones, and the first
        camera or target move of each orientation.
    """

    binding: Binding
    binding_path: Path | None
    n_files: int
    n_rows: int
    leftovers: tuple[str, ...]
    unphotographed: tuple[tuple[int, str], ...]
    ignored: tuple[tuple[str, str], ...]
    warnings: tuple[str, ...]
    fixes: tuple[Fix, ...]
    remaining: tuple[str, ...]
    command: str | None
    diagnoses: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """Every row has a file (or was declared missing), every file a row, every
        step fits the plan and no photograph needs a look (`diagnoses`). Files set
        aside (copies, non-images) are listed but do not count."""
        declared = set(self.binding.missing)
        return not (self.leftovers or self.warnings or self.diagnoses
                    or any(line not in declared for line, _ in self.unphotographed))


def row_text(row) -> str:
    """How messages name a manifest row: its CSV line and place in the protocol."""
    return (f"line {row.line}: orientation {row.orientation_deg:g}, cycle {row.cycle}, "
            f"{row.phase}, step {row.step}")


def _assign(rows, files, skip, missing, swaps=()):
    """[(row, file or None)] in row order, and the files left over."""
    order = [f for f in files if f.name not in skip]
    names = [f.name for f in order]
    for a, b in swaps:
        if a not in names or b not in names:  # one of them skipped: nothing to exchange
            continue
        i, j = names.index(a), names.index(b)
        order[i], order[j] = order[j], order[i]
        names[i], names[j] = names[j], names[i]
    usable = iter(order)
    out = []
    for row in rows:
        out.append((row, None if row.line in missing else next(usable, None)))
    return out, list(usable)


def _sequences(session: Session, bound, pairs, sign):
    """Per orientation: (positions in `bound` from its reference on, their StepPoints)."""
    from ..angle import sequence_angles

    groups = defaultdict(list)
    for pos, (row, shot) in enumerate(bound):
        if shot is not None and pairs.get(shot) is not None:
            groups[row.orientation_deg].append(pos)
    out = []
    for positions in groups.values():
        ref = next((p for p in positions if bound[p][0].phase == "reference"), positions[0])
        seq = [p for p in positions if p >= ref]  # images taken before the reference: not checked
        angles = sequence_angles(pairs[bound[ref][1]], [pairs[bound[p][1]] for p in seq])
        points = [StepPoint(session.torque(bound[p][0]).torque_nm,
                            None if a is None else sign * a.angle_deg,
                            0.0 if a is None else a.angle_std_deg) for p, a in zip(seq, angles)]
        out.append((seq, points))
    return out


def _step_torque(session: Session) -> float:
    return session.config.rig.step_torque_nm


def step_warnings(session: Session, bound, pairs, *, sign=None) -> list[tuple[int, object]]:
    """Step warnings of a bound session: [(position in `bound`, StepWarning)].

    Parameters
    ----------
    session : Session
    bound : sequence of (ManifestRow, object or None)
        Rows in manifest order with what was photographed for them (None: nothing).
    pairs : mapping
        What was photographed -> its PairMeasurement (or None when it failed).
    sign : {1, -1}, optional
        The angle sign to check with (the session's ``angle_sign`` by default).
    """
    sign = session.config.angle_sign if sign is None else sign
    found, loops = [], []  # each orientation's steps also against the same steps of the ones before
    for seq, points in _sequences(session, bound, pairs, sign):
        found += [(seq[w.index], w) for w in check_steps(points, step_torque_nm=_step_torque(session),
                                                         earlier=loops)]
        loops.append(points)
    kinks = gear_kinks([w for _, w in found])  # the gear's own, seen twice: not mistakes
    return sorted((x for n, x in enumerate(found) if n not in kinks), key=lambda t: t[0])


def _sign_diagnosis(session: Session, bound, pairs):
    """(the sign to check with, the one-line diagnosis or None): the session's
    ``angle_sign`` is inverted when the first loaded image of its first orientation
    turned against its torque (:func:`~.steps.first_load_inverted`; the diagnosis
    counts the orientations where it did). The first orientation decides: its
    reference and first load are the session's first photographs, bound to their
    rows, while a missed or extra shot before a later orientation binds that one's
    files a row off, its reference to another orientation's load."""
    from .steps import first_load_inverted

    sign = session.config.angle_sign
    verdicts = []
    for seq, points in _sequences(session, bound, pairs, sign):
        i = first_load_inverted(points)
        loaded = any(p.torque_nm != 0 and p.angle_deg is not None for p in points[1:])
        if loaded:
            verdicts.append(None if i is None else (seq[i], points[i]))
    against = [v for v in verdicts if v is not None]
    if not verdicts or verdicts[0] is None:
        return sign, None
    pos, point = against[0]
    row, f = bound[pos]
    return -sign, (f"angle_sign is inverted: the first loaded image turned against the torque in "
                   f"{len(against)} of {len(verdicts)} orientation(s) ({f.name}, {row_text(row)}: "
                   f"{point.angle_deg:+.4f}° under {point.torque_nm:+.5f} N·m); set angle_sign = "
                   f"{-sign:+d} in {session.folder / 'session.toml'} (the steps are checked with it)")


def _image_diagnoses(bound, pairs, saturated, failed) -> list[str]:
    """Per photograph: not measured, saturated, blurred (:func:`~.shots.image_warnings`,
    the rule ``watch`` applies), and the first camera or target move of each
    orientation (:func:`~.axis.check_axis`)."""
    from .axis import check_axis
    from .shots import image_warnings

    out = []
    refs = {}
    for row, f in bound:
        if f is not None and row.phase == "reference":
            refs.setdefault(row.orientation_deg, f)
    sequences = defaultdict(list)
    for row, f in bound:
        if f is None:
            continue
        where = f"{f.name} ({row_text(row)})"
        if f.name in failed:
            out.append(f"{where}: not measured: {failed[f.name]}")
        ref = refs.get(row.orientation_deg)
        reference = pairs.get(ref) if ref is not None and ref is not f else None
        out += [f"{where}: {w}" for w in image_warnings(pairs.get(f), reference, saturated.get(f, math.nan))]
        if ref is not None:
            sequences[row.orientation_deg].append((row, f))
    for seq in sequences.values():
        for w in check_axis([pairs.get(f) for _, f in seq]):
            row, f = seq[w.index]
            out.append(f"{f.name} ({row_text(row)}): {w.message}")
    return out


def _one_branch(session: Session, bound, lo: int, hi: int) -> bool:
    """The rows at positions `lo` - 1 ... `hi` of `bound` are of one orientation and
    their planned torques move one way (no reversal between them): photographs
    taken the other way round there show as steps out of line."""
    if lo < 1 or hi >= len(bound):
        return False
    rows = [bound[p][0] for p in range(lo - 1, hi + 1)]
    if len({row.orientation_deg for row in rows}) != 1:
        return False
    torques = [session.torque(row).torque_nm for row in rows]
    steps = [b - a for a, b in zip(torques, torques[1:])]
    return all(x > 0 for x in steps) or all(x < 0 for x in steps)


def _describe(bound, warns) -> list[str]:
    return [f"{bound[pos][1].name} ({row_text(bound[pos][0])}): {w.message}" for pos, w in warns]


def bind_session(session_dir, camera_dir, *, by: str = "time", skip=(), missing=(), swap=(),
                 write: bool = True, out_dir=None) -> BindResult:
    """Bind the camera's photographs to the manifest rows (see the module docstring).

    Parameters
    ----------
    session_dir : str or os.PathLike
        The session folder (session.toml, manifest.csv).
    camera_dir : str or os.PathLike
        The camera's folder; read only. Naming it is what allows the session's
        images to live outside the session folder.
    by : {"time", "name"}
        Capture order by EXIF time (then file time), or natural name order.
    skip : iterable of str
        Camera file names to leave out (extra shots).
    missing : iterable of int
        Manifest CSV lines that were not photographed (missed shots).
    swap : iterable of (str, str)
        Pairs of camera files taken the other way round: each takes the other's
        place in the capture order.
    write : bool
        Write ``binding.json`` (False: only check and propose).
    out_dir : path-like, optional
        The output folder whose cache is shared with ``process``
        (``SESSION_DIR/results`` by default).

    Returns
    -------
    BindResult

    Raises
    ------
    SessionError
        The session or camera folder is unusable (the camera folder is the output
        folder, which would put the cache among the photographs), `by` is unknown, a `skip` name is
        not a photograph of the camera folder (or is skipped), or a `missing` line
        is not a row.
    ManifestError
        manifest.csv is invalid.
    OutputError
        The output folder (its cache) or, with `write`, the session folder cannot
        be written: said before anything is measured.
    """
    from .shots import ShotMeasurer

    session = load_session(session_dir, check_files=False)
    if write:  # another program's binding.json is refused before anything is measured
        check_replaceable([session.folder / BINDING_NAME])
    camera = Path(camera_dir).absolute()
    listing = list_camera_files(camera, by=by)
    files = listing.files
    rows = session.manifest.rows
    names = {f.name for f in files}
    skip, missing = tuple(skip), tuple(int(x) for x in missing)
    for name in skip:
        if name not in names:
            raise SessionError(f"skip: {name!r} is not a photograph in {camera}")
    swap = tuple((str(a), str(b)) for a, b in swap)
    for pair in swap:
        for name in pair:
            if name not in names or name in skip:
                raise SessionError(f"swap: {name!r} is not a photograph in {camera}"
                                   + (" (it is skipped)" if name in skip else ""))
    lines = {row.line for row in rows}
    for line in missing:
        if line not in lines:
            raise SessionError(f"missing: line {line} is not a row of {session.manifest.path}")
    out = output_folder(session.folder, out_dir)
    if same_folder(camera, out):  # the camera folder is only read; the cache goes to `out`
        raise SessionError(f"{camera}: the camera folder cannot be the output folder")
    # before measuring: a bind must not measure everything and then fail to write
    check_output_dir(out)  # the cache shared with process
    if write:
        check_output_dir(session.folder)  # binding.json
    pairs, saturated, failed = {}, {}, {}
    with ShotMeasurer(session, out) as measurer:
        for f in files:
            shot = measurer.measure(f.path)
            pairs[f] = shot.pair
            saturated[f] = shot.saturated_fraction
            if shot.pair is None:
                failed[f.name] = shot.message + (" (a half-written file? it keeps its row)"
                                                 if shot.undecodable else "")
    sign, sign_note = _sign_diagnosis(session, _assign(rows, files, set(skip), set(missing), swap)[0], pairs)

    def evaluate(sk, mi, sw):
        bound, left = _assign(rows, files, set(sk), set(mi), sw)
        return bound, left, step_warnings(session, bound, pairs, sign=sign)

    def misfit(bound):  # of two fixes that leave as few misfits, the one whose steps fit best
        loops = [points for _, points in _sequences(session, bound, pairs, sign)]
        return sum(step_misfit(points, step_torque_nm=_step_torque(session), earlier=loops[:n])
                   for n, points in enumerate(loops))

    bound, leftovers, warns = evaluate(skip, missing, swap)
    fixes, cur_skip, cur_missing, cur_swap = [], list(skip), list(missing), list(swap)
    cur = (bound, warns)
    unexplained: set[str] = set()  # files whose misfit no re-binding explains
    for _ in range(_MAX_FIXES):
        b, w = cur
        todo = [(pos, warning) for pos, warning in w if b[pos][1].name not in unexplained]
        if not todo:
            break
        candidates = []
        swapped = {name for pair in cur_swap for name in pair}
        for pos, warning in todo[:3]:  # the fix that explains most, of the first misfits
            row, f = b[pos]
            if warning.kind in ("no_movement", "wrong_direction") and f.name not in swapped:
                candidates.append(("skip", f, row, None, warning))  # an extra shot: the same load again
            if warning.kind in ("large_step", "wrong_direction"):
                candidates.append(("missing", f, row, None, warning))  # a missed shot: two steps in one
                # or missed earlier in the branch, where the gear's own kinks hid the
                # double step: every file since is a row early, and the turn of the
                # load comes a row too soon
                for d in range(1, len(b)):
                    if not _one_branch(session, b, pos - d, pos) or b[pos - d][1] is None:
                        break
                    candidates.append(("missing", b[pos - d][1], b[pos - d][0], b[pos], warning))
            if warning.kind == "small_step" and warning.decided:  # a piece forgotten: its load is wrong
                candidates.append(("drop", f, row, None, warning))
            for d in (1, -1, 2, -2, 3, -3):  # two photographs taken the other way round
                other = b[pos + d] if 0 <= pos + d < len(b) else None
                if (warning.kind in ("large_step", "wrong_direction") and other is not None
                        and other[1] is not None and f.name not in swapped and other[1].name not in swapped
                        and _one_branch(session, b, min(pos, pos + d), max(pos, pos + d))):
                    candidates.append(("swap", f, row, other, warning))
        best = None
        for kind, file, r, other, warning in candidates:
            sk = cur_skip + [file.name] if kind in ("skip", "drop") else cur_skip
            mi = cur_missing + [r.line] if kind in ("missing", "drop") else cur_missing
            sw = cur_swap + [(file.name, other[1].name)] if kind == "swap" else cur_swap
            nb, _, nw = evaluate(sk, mi, sw)
            still = any(nb[p][1] is file for p, _ in nw)
            score = len(nw) + misfit(nb) / math.log(2)  # a step off by 2× weighs as a misfit
            if len(nw) < len(w) and not still and (best is None or score < best[10]):
                best = (kind, file, r, nw, nb, sk, mi, sw, other, warning, score)
        if best is None:
            unexplained.add(b[todo[0][0]][1].name)
            continue
        kind, file, r, nw, nb, cur_skip, cur_missing, cur_swap, other, first, _ = best
        if kind == "swap":
            a, b2 = sorted([(r, file), other], key=lambda t: t[0].line)
            msg = (f"{a[1].name} and {b2[1].name} look swapped: {a[1].name} shows the load of line "
                   f"{b2[0].line} and {b2[1].name} that of line {a[0].line} (their angle steps fit the "
                   f"plan the other way round); exchange them (--swap {a[1].name} {b2[1].name})")
        elif kind == "drop":
            msg = (f"{file.name} ({row_text(r)}) shows {first.message}; leave it out and the row "
                   f"without a photograph (--skip {file.name} --missing {r.line}): its load cannot be "
                   "set again without leaving the loop's path")
        elif kind == "skip":
            msg = (f"{file.name} looks like an extra shot: bound to {row_text(r)}, it shows "
                   f"{first.message}; leave it out (--skip {file.name})")
        else:
            nxt = next((x for x, y in nb if y is file), None)
            shows = (f"{file.name}, bound to it, shows {first.message}" if other is None else
                     f"the files from {file.name} on show the load of the row after theirs (the gear's own "
                     f"change of stiffness hid the double step; {other[1].name} shows {first.message})")
            msg = (f"{row_text(r)} looks missed: {shows}; mark the row as not photographed "
                   f"(--missing {r.line}) so that {file.name} binds to line {nxt.line if nxt else '?'}")
        fixes.append(Fix(kind, file.name, r.line, msg))
        cur = (nb, nw)
    command = None
    if fixes:
        parts = ["vision-torsion", "bind", str(session_dir), str(camera_dir), "--by", by]
        for name in cur_skip:
            parts += ["--skip", name]
        for line in cur_missing:
            parts += ["--missing", str(line)]
        for a, b2 in cur_swap:
            parts += ["--swap", a, b2]
        command = shlex.join(parts)
    binding = Binding(camera_dir=camera, by=by, skipped=skip, missing=missing,
                      images={row.image: f.name for row, f in bound if f is not None})
    path = write_binding(session.folder, binding) if write else None
    return BindResult(
        binding=binding, binding_path=path, n_files=len(files), n_rows=len(rows),
        leftovers=tuple(f.name for f in leftovers),
        unphotographed=tuple((row.line, row.image) for row, f in bound if f is None),
        ignored=listing.ignored, warnings=tuple(_describe(bound, warns)), fixes=tuple(fixes),
        remaining=tuple(_describe(cur[0], cur[1])), command=command,
        diagnoses=tuple(([sign_note] if sign_note else []) + _image_diagnoses(bound, pairs, saturated, failed)))
