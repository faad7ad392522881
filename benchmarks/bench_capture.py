"""Capture mistakes caught at the rig: detections and false alarms of ``watch`` and
``bind`` over simulated sessions of different gears and both target types (issue 28).

    python benchmarks/bench_capture.py [--seeds N] [--steps K] [--targets ...] [--target-seeds M]
                                       [--orientations L] [--multi-seeds S] [--seed-base B]

Every session is one orientation of a gear photographed by the scripted camera
(:func:`vision_torsion.synthetic.scripted_camera.capture_script`, a 320×240 scene, 4 weight
steps per phase by default: 18 photographs), with one capture mistake at a row drawn
from the seed, or none. Gears: the paper's bilinear model at three switching torques,
a three-segment spring behind friction and a Masing gear
(:mod:`vision_torsion.synthetic.gears`). Mistakes: a missed shot, an extra shot, a
weight piece forgotten, two shots swapped, a camera bump of 1 px, one of 3 px and
0.05°, a blurred photograph, a wrong angle_sign; and clean sessions. Targets: two
markers, and the N-marker ring16 (session.toml ``[target]``) drawn in the same frame.
Besides, sessions of `L` orientations (two-marker target; the same gear in each)
with one step mistake (missed, extra, forgotten, swapped) in the first orientation's
loop or in the last one's, or none: a mistake in a later loop is judged against the
same step of the loops before it.

Each session is watched as its photographs arrive (``Watcher``, one tick per
photograph) and then bound (``bind_session``). Counted:

- watch found: a warning on the mistake's photograph or the one after it, said by
  the time the photograph after it is in, with the right diagnosis and its fix
  naming the right file and line (``--skip FILE``, ``--missing LINE``, ``--swap A B``,
  ``--skip FILE --missing LINE`` for a forgotten piece; shoot again for a bump or a
  blur; ``set angle_sign``);
- bind found: its fix or diagnosis says the same (the same patterns);
- watch later: a mistake not found so, said later with the right diagnosis and
  fix (on the mistake's photograph or the next: a forgotten piece decided by the
  step after the next), or a missed shot whose row ``watch`` names among those that
  fit when the load turns back a row early (the fix: ``bind`` after the
  orientation); that line is not counted as false;
- watch false: warnings on other photographs, plus warnings withdrawn; "standing":
  the photographs still warned about at the end; bind false: on clean sessions,
  anything bind says at all;
- photographs measured by watch and by bind, and whether ``process`` refuses the
  session (an N-marker target: ``target_not_processed``).

Results go to benchmarks/results/capture.json.
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from common import write_result  # noqa: E402 (the script's folder is on sys.path)

from vision_torsion.analysis.models import bilinear_response  # noqa: E402
from vision_torsion.errors import SessionError  # noqa: E402
from vision_torsion.measurements import couple_torque_nm  # noqa: E402
from vision_torsion.session.bind import bind_session  # noqa: E402
from vision_torsion.session.plan import plan_session  # noqa: E402
from vision_torsion.session.process import process_session  # noqa: E402
from vision_torsion.session.watch import Watcher  # noqa: E402
from vision_torsion.synthetic import Scene  # noqa: E402
from vision_torsion.synthetic.gears import masing_response, three_segment_response  # noqa: E402
from vision_torsion.synthetic.scene import DiskSpec, ImageSpec, MarkerSpec  # noqa: E402
from vision_torsion.synthetic.scripted_camera import ScriptedCamera, capture_script  # noqa: E402
from vision_torsion.synthetic.session import SessionSpec  # noqa: E402
from vision_torsion.synthetic.target_scenes import target_scene  # noqa: E402

SCENE = Scene(image=ImageSpec(320, 240),
              disk=DiskSpec(center_x=160.3, center_y=120.4, background_level=200.0),
              markers=MarkerSpec(radius_px=10.0, distance_px=90.0, positions_deg=(10.0, 190.0)),
              name="tiny")
STEP_NM = 2 * 0.02 * 9.81 * 0.05
#: The two target types: two markers (the scene above), and the N-marker ring16
#: (16 dots on an 80 mm circle, drawn at 2.4 px/mm in the same frame).
TWO = "two markers"
SCENES = {TWO: SCENE, "ring16": target_scene("ring16", px_per_mm=2.4, base=SCENE)}


def bilinear(tau_c):
    return lambda tau: bilinear_response(tau, k_u=4.4, k_l=0.3, tau_c=tau_c)


def three_segment(tau):
    """A spring stiffening at 0.02 and 0.05 N·m (1.0, 2.5, 6 N·m/rad) behind 0.004 N·m
    of friction (:func:`~vision_torsion.synthetic.gears.three_segment_response`)."""
    return three_segment_response(tau)


def masing(tau):
    """Masing's rule on a stiffening skeleton (0.8 N·m/rad at zero, 5 far from it,
    τ0 = 0.03 N·m; :func:`~vision_torsion.synthetic.gears.masing_response`)."""
    return masing_response(tau)


GEARS = {"bilinear τc=0.03": bilinear(0.03), "bilinear τc=0.05": bilinear(0.05),
         "bilinear τc=0.15": bilinear(0.15), "three-segment": three_segment, "Masing": masing}

# mistake -> (options(row) for capture_script, watch's diagnosis and fix, bind's): each
# a function of (row, the camera's file names, the capture position of the mistake's
# photograph) giving a pattern, so that the fix must name the right file and line
# (CSV line = row + 2)
def _file(names, at):
    return re.escape(names[at])


def _MOVED(r, n, at):
    return r"camera or the target moved.*shoot this orientation again"


def _DROPPED(r, n, at):
    return rf"a weight piece forgotten.*--skip {_file(n, at)} --missing {r + 2}\b"


MISTAKES = {
    "missed shot": (lambda r: {"missed": r},
                    lambda r, n, at: rf"a missed shot.*--missing {r + 2}\b",
                    lambda r, n, at: rf"--missing {r + 2}\b"),
    "extra shot": (lambda r: {"extra_after": r},
                   lambda r, n, at: rf"an extra shot.*--skip {_file(n, at)}",
                   lambda r, n, at: rf"--skip {_file(n, at)}"),
    "forgotten weight": (lambda r: {"forgotten": r}, _DROPPED, _DROPPED),
    "two shots swapped": (lambda r: {"swapped": r},
                          lambda r, n, at: rf"look swapped.*--swap {_file(n, at - 1)} {_file(n, at)}",
                          lambda r, n, at: rf"--swap {_file(n, at - 1)} {_file(n, at)}"),
    "bump 1 px": (lambda r: {"bumped": (r, 1.0, 0.0, 0.0)}, _MOVED, _MOVED),
    "bump 3 px + 0.05°": (lambda r: {"bumped": (r, 0.0, 3.0, 0.05)}, _MOVED, _MOVED),
    "blur": (lambda r: {"blurred": r}, lambda r, n, at: r"blurred.*shoot it again",
             lambda r, n, at: rf"{_file(n, at)} .*blurred.*shoot it again"),
    "wrong angle_sign": (lambda r: {}, lambda r, n, at: r"angle_sign is inverted.*set angle_sign = \+1",
                         lambda r, n, at: r"angle_sign is inverted.*set angle_sign = \+1"),
    "clean": (lambda r: {}, None, None),
}


#: The mistakes of the multi-loop sessions: those the step checks find.
MULTI = ("missed shot", "extra shot", "forgotten weight", "two shots swapped", "clean")


def mistake_row(kind: str, rng, torques, block=None) -> int:
    """A row for the mistake where the step checks can see it: inside a branch of
    the loop (the load changing the same way for the steps before and after it).
    The first image after a load reversal has no step of its branch to compare
    with (the gear's stiffness may switch there by 15×), so a shot missed there
    shows only as a row left without a photograph at the end. `block`: (first row,
    end) of the orientation to place it in (the whole plan by default)."""
    if kind == "wrong angle_sign":
        return 1
    d = np.sign(np.diff(torques))  # d[r - 1]: the step into row r
    after = 2 if kind == "two shots swapped" else 1
    first, end = block or (0, len(torques))
    inside = [r for r in range(first + 3, end - after)
              if all(d[r - 2 + j] == d[r - 1] for j in range(after + 2))]
    return int(rng.choice(inside))


def first_photo(kind: str, row: int, shots) -> int:
    """Capture position of the photograph the mistake is on (0-based)."""
    if kind == "missed shot":
        return next(k for k, s in enumerate(shots) if s.row > row)
    if kind == "extra shot":
        return next(k for k, s in enumerate(shots) if s.kind == "extra")
    return next(k for k, s in enumerate(shots) if s.row == row)


def one_session(gear: str, kind: str, seed: int, steps: int, target: str = TWO, *, orientations: int = 1,
                in_loop: int = 0) -> dict:
    """One session of `orientations` orientations, the mistake in orientation
    number `in_loop` (0-based), watched and bound: what each found."""
    rng = np.random.default_rng(seed)
    spec = SessionSpec(max_torque_nm=steps * STEP_NM,
                       orientations_deg=tuple(360.0 * k / max(orientations, 3) for k in range(orientations)))
    options, said, fixed = MISTAKES[kind]
    scene = SCENES[target]
    with tempfile.TemporaryDirectory() as tmp:
        session, camera = Path(tmp) / "s", Path(tmp) / "cam"
        plan, _ = capture_script(scene, spec, Path(tmp) / "plan", seed=seed)
        sign = {"ref": 0, "pos": 1, "neg": -1}
        torques = [sign[r["phase"][:3]] * couple_torque_nm(float(r["mass_kg"]), gravity_m_per_s2=spec.gravity_m_per_s2,
                                                          arm_radius_m=spec.arm_radius_m) for r in plan.rows]
        per = len(torques) // orientations
        row = mistake_row(kind, rng, torques, (in_loop * per, (in_loop + 1) * per))
        plan, shots = capture_script(scene, spec, session, seed=seed, response=GEARS[gear], **options(row))
        refused = None
        if target != TWO:  # the same plan, with the N-marker target in session.toml
            plan_session(spec.session_config(polarity=scene.markers.polarity, target=target), session,
                         overwrite=True)
            try:
                process_session(session, out_dir=Path(tmp) / "processed")
            except SessionError as exc:
                refused = exc.reason
        if kind == "wrong angle_sign":
            toml = session / "session.toml"
            toml.write_text(toml.read_text().replace("angle_sign = 1", "angle_sign = -1"))
        ScriptedCamera(camera, [s.png for s in shots]).run(chunk_delay_s=0, photo_delay_s=0)
        names = sorted(p.name for p in camera.iterdir())
        later = Path(tmp) / "later"
        later.mkdir()
        for name in names:
            (camera / name).rename(later / name)
        clock, events, last = [0.0], [], {}
        with Watcher(session, camera_dir=camera, page=False, clock=lambda: clock[0]) as w:
            for name in names:
                (later / name).rename(camera / name)
                clock[0] += 2.0
                for e in w.tick():
                    events.append(e)
                    last[id(e)] = name
        res = bind_session(session, camera, write=False)
    warned = [e for e in events if e.kind == "warning"]
    measured = sum(1 for e in events if e.kind == "shot" and "θ=—" not in e.message)
    unmeasured = [d.split(": not measured: ", 1)[1] for d in res.diagnoses if ": not measured: " in d]
    why = re.sub(r"^IMG_\d+\.png: ", "", unmeasured[0]) if unmeasured else None
    withdrawn = sum(e.kind == "retracted" for e in events)
    gone = {e.file for e in events if e.kind == "retracted"}
    bind_text = [f.message for f in res.fixes] + list(res.diagnoses) + list(res.remaining)
    if res.command:
        bind_text.append(res.command)
    out = {"gear": gear, "target": target, "mistake": kind, "seed": seed, "row": row, "withdrawn": withdrawn,
           "orientations": orientations, "loop": "first" if in_loop == 0 else "later",
           "photos": len(names), "watch_measured": measured, "bind_measured": res.n_files - len(unmeasured),
           "not_measured_because": why,
           "process_refused": refused,
           "watch_said": [e.message for e in warned], "bind_said": bind_text + list(res.warnings)}
    if said is None:
        out.update(watch_detected=None, bind_detected=None, watch_later=None, watch_false=len(warned) + withdrawn,
                   watch_standing=len({e.file for e in warned} - gone),
                   bind_false=len(bind_text) + len(res.warnings))
        return out
    at = first_photo(kind, row, shots)
    near = set(names[at:at + 2]) | ({names[at - 1]} if kind == "two shots swapped" else set())
    said, fixed = said(row, names, at), fixed(row, names, at)
    out["watch_detected"] = any(e.file in near and re.search(said, e.message)
                                and names.index(last[id(e)]) <= at + 1 for e in warned)
    out["bind_detected"] = any(re.search(fixed, t) for t in bind_text)
    # a missed shot's row named among those that fit where the load turned back a row early
    named = {id(e) for e in warned if kind == "missed shot"
             and re.search(rf"turned back a row early: .* at line (\d+ or )*{row + 2}( or \d+)* ", e.message)}
    out["watch_later"] = not out["watch_detected"] and (bool(named) or any(
        e.file in near and re.search(said, e.message) for e in warned))
    out["watch_false"] = sum(1 for e in warned if e.file not in near and id(e) not in named) + withdrawn
    out["watch_standing"] = len({e.file for e in warned if e.file not in near and id(e) not in named} - gone)
    out["bind_false"] = 0
    return out


def table(rows) -> None:
    """Per mistake (and, where the sessions hold several loops, per loop the
    mistake is in: the first orientation's or a later one's) the counts."""
    print(f"{'mistake':<34} {'sessions':>8} {'watch found':>11} {'watch later':>11} {'bind found':>10} "
          f"{'watch false':>11} {'standing':>8} {'bind false':>10}")
    split = any(r["orientations"] > 1 for r in rows)
    for kind in MISTAKES:
        for loop in ("first", "later"):
            sel = [r for r in rows if r["mistake"] == kind and r["loop"] == loop]
            if not sel:
                continue
            label = f"{kind} ({loop} loop)" if split and kind != "clean" else kind
            found_w = "—" if kind == "clean" else f"{sum(r['watch_detected'] for r in sel)}/{len(sel)}"
            found_b = "—" if kind == "clean" else f"{sum(r['bind_detected'] for r in sel)}/{len(sel)}"
            later = "—" if kind == "clean" else str(sum(r["watch_later"] for r in sel))
            print(f"{label:<34} {len(sel):>8} {found_w:>11} {later:>11} {found_b:>10} "
                  f"{sum(r['watch_false'] for r in sel):>11} "
                  f"{sum(r['watch_standing'] for r in sel):>8} {sum(r['bind_false'] for r in sel):>10}")
    photos = sum(r["photos"] for r in rows)
    refused = sorted({str(r["process_refused"]) for r in rows if r["process_refused"]})
    print(f"photographs measured: watch {sum(r['watch_measured'] for r in rows)}/{photos}, "
          f"bind {sum(r['bind_measured'] for r in rows)}/{photos}"
          + (f"; process refuses the session ({', '.join(refused)})" if refused else ""))
    if not any(r["watch_measured"] for r in rows):
        why = sorted({r["not_measured_because"] for r in rows if r["not_measured_because"]})
        print(f"  nothing measured by watch; bind: {'; '.join(why)}")
        return
    for r in rows:
        if r["mistake"] != "clean" and not (r["watch_detected"] and r["bind_detected"]):
            print(f"  not caught: {r['gear']}, {r['mistake']} at row {r['row']} ({r['loop']} loop, seed {r['seed']}): "
                  f"watch {r['watch_detected']}{' (said later)' if r['watch_later'] else ''}, "
                  f"bind {r['bind_detected']}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=1, help="sessions per gear and mistake")
    ap.add_argument("--steps", type=int, default=4, help="weight steps per phase")
    ap.add_argument("--targets", default=",".join(SCENES), help=f"target types, comma-separated ({', '.join(SCENES)})")
    ap.add_argument("--target-seeds", type=int, default=1, help="sessions per gear and mistake of the N-marker target")
    ap.add_argument("--orientations", type=int, default=2,
                    help="orientations of the multi-loop sessions (below 2: none are run)")
    ap.add_argument("--multi-seeds", type=int, default=1,
                    help="multi-loop sessions per gear, step mistake and loop it is in")
    ap.add_argument("--seed-base", type=int, default=0,
                    help="added to every session's seed (fresh sessions: the mistake's row, the noise)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = []
    targets = [t.strip() for t in args.targets.split(",") if t.strip()]
    for target in targets:
        seeds = args.seeds if target == TWO else args.target_seeds
        for g, gear in enumerate(GEARS):
            for j, kind in enumerate(MISTAKES):
                for s in range(seeds):
                    rows.append(one_session(gear, kind, args.seed_base + 1000 * s + 17 * j + 101 * g, args.steps,
                                            target))
    multi = []
    if args.orientations >= 2:
        for g, gear in enumerate(GEARS):
            for j, kind in enumerate(MULTI):
                for in_loop in ((0,) if kind == "clean" else (0, args.orientations - 1)):
                    for s in range(args.multi_seeds):
                        multi.append(one_session(gear, kind, args.seed_base + 1000 * s + 17 * j + 101 * g + 7 * in_loop,
                                                 args.steps, orientations=args.orientations, in_loop=in_loop))
    print(f"{len(rows)} sessions ({len(GEARS)} gears × {len(MISTAKES)} cases × seeds, targets: "
          f"{', '.join(targets)}), {2 + 4 * args.steps} photographs each; {len(multi)} sessions of "
          f"{args.orientations} orientations; {time.perf_counter() - t0:.0f} s")
    for target in targets:
        sel = [r for r in rows if r["target"] == target]
        print(f"\n{target}: {len(sel)} sessions")
        table(sel)
    if multi:
        print(f"\n{TWO}, {args.orientations} orientations: {len(multi)} sessions")
        table(multi)
    rows += multi
    kept = [{k: v for k, v in r.items() if not k.endswith("_said")} for r in rows]  # messages hold temp paths
    write_result(HERE / "results" / "capture.json", {"sessions": kept, "steps": args.steps, "seeds": args.seeds,
                                                      "target_seeds": args.target_seeds, "targets": targets,
                                                      "orientations": args.orientations,
                                                      "multi_seeds": args.multi_seeds, "seed_base": args.seed_base})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
