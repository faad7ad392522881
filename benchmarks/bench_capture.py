"""Capture mistakes caught at the rig: detections and false alarms of ``watch`` and
``bind`` over simulated sessions of different gears (issue 28).

    python benchmarks/bench_capture.py [--seeds N] [--steps K]

Every session is one orientation of a gear photographed by the scripted camera
(:func:`vision_torsion.synthetic.scripted_camera.capture_script`, the 320×240 two-marker
scene of the rig tests, 4 weight steps per phase by default: 18 photographs), with
one capture mistake at a row drawn from the seed, or none. Gears: the paper's
bilinear model at three switching torques, a three-segment spring (stiffening
twice) with a friction offset between the loading directions, and a Masing gear
(a softening skeleton curve, every branch the skeleton doubled from its reversal).
Mistakes: a missed shot, an extra shot, a weight piece forgotten, two shots
swapped, a camera bump of 1 px, one of 3 px and 0.05°, a blurred photograph, a
wrong angle_sign; and clean sessions.

Each session is watched as its photographs arrive (``Watcher``, one tick per
photograph) and then bound (``bind_session``). Counted:

- watch detected: a warning names the mistake's photograph or the one after it,
  with the right diagnosis (a pattern of its message), by the time the
  photograph after it is in;
- bind detected: its fix or diagnosis names it (the same patterns);
- false alarms: warnings of watch on photographs other than the mistake's and
  the one after it, and warnings withdrawn (an undecided step at the end of a
  branch is withdrawn when the same step elsewhere in the loop shows the gear's
  own kink); "standing": those photographs still warned about at the end; on
  clean sessions, anything bind says at all.

Results go to benchmarks/results/capture.json.
"""

from __future__ import annotations

import argparse
import math
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
from vision_torsion.session.bind import bind_session  # noqa: E402
from vision_torsion.session.watch import Watcher  # noqa: E402
from vision_torsion.synthetic import Scene  # noqa: E402
from vision_torsion.synthetic.scene import DiskSpec, ImageSpec, MarkerSpec  # noqa: E402
from vision_torsion.synthetic.scripted_camera import ScriptedCamera, capture_script  # noqa: E402
from vision_torsion.synthetic.session import SessionSpec  # noqa: E402

SCENE = Scene(image=ImageSpec(320, 240),
              disk=DiskSpec(center_x=160.3, center_y=120.4, background_level=200.0),
              markers=MarkerSpec(radius_px=10.0, distance_px=90.0, positions_deg=(10.0, 190.0)),
              name="tiny")
STEP_NM = 2 * 0.02 * 9.81 * 0.05


def bilinear(tau_c):
    return lambda tau: bilinear_response(tau, k_u=4.4, k_l=0.3, tau_c=tau_c)


def three_segment(tau):
    """A spring stiffening at 0.02 and 0.05 N·m (1.0, 2.5, 6 N·m/rad) behind 0.004 N·m
    of friction: after a reversal the torque must move 2 × 0.004 N·m before the
    spring follows (a play operator on the torque)."""
    tau = np.asarray(tau, float)
    breaks, k, play = (0.02, 0.05), (1.0, 2.5, 6.0), 0.004

    def spring(t):
        a = abs(t)
        th = min(a, breaks[0]) / k[0] + max(min(a, breaks[1]) - breaks[0], 0) / k[1] + max(a - breaks[1], 0) / k[2]
        return math.copysign(th, t)

    out, felt = [], 0.0
    for t in tau:
        felt = min(max(felt, t - play), t + play)
        out.append(spring(felt))
    return np.asarray(out) - out[0]


def masing(tau):
    """Masing's rule on the skeleton θ = τ/k_hi + (τ0/k_lo − τ0/k_hi)·tanh(τ/τ0)
    (k_lo = 0.8 at zero, k_hi = 5 N·m/rad, τ0 = 0.03 N·m): each branch is the
    skeleton scaled by two from its reversal point."""
    tau = np.asarray(tau, float)
    k_lo, k_hi, t0 = 0.8, 5.0, 0.03

    def skeleton(t):
        return t / k_hi + (t0 / k_lo - t0 / k_hi) * math.tanh(t / t0)

    out = [0.0]
    rev_t, rev_th, direction = 0.0, 0.0, 0.0
    for i in range(1, len(tau)):
        d = np.sign(tau[i] - tau[i - 1])
        if d and d != direction:
            if direction:
                rev_t, rev_th = tau[i - 1], out[-1]
            direction = d
        scale = 1.0 if rev_t == 0.0 and rev_th == 0.0 else 2.0
        out.append(rev_th + scale * skeleton((tau[i] - rev_t) / scale))
    return np.asarray(out)


GEARS = {"bilinear τc=0.03": bilinear(0.03), "bilinear τc=0.05": bilinear(0.05),
         "bilinear τc=0.15": bilinear(0.15), "three-segment": three_segment, "Masing": masing}

# mistake -> (options(row) for capture_script, the rows of the photographs it is seen on
# (offsets into the capture order from the mistake's), watch's diagnosis, bind's)
MISTAKES = {
    "missed shot": (lambda r: {"missed": r}, r"a missed shot", r"--missing \d+"),
    "extra shot": (lambda r: {"extra_after": r}, r"no movement", r"--skip IMG_\d+\.png"),
    "forgotten weight": (lambda r: {"forgotten": r}, r"a weight piece forgotten", r"a weight piece forgotten"),
    "two shots swapped": (lambda r: {"swapped": r}, r"look swapped", r"--swap IMG_\d+\.png IMG_\d+\.png"),
    "bump 1 px": (lambda r: {"bumped": (r, 1.0, 0.0, 0.0)}, r"camera or the target moved",
                  r"camera or the target moved"),
    "bump 3 px + 0.05°": (lambda r: {"bumped": (r, 0.0, 3.0, 0.05)}, r"camera or the target moved",
                          r"camera or the target moved"),
    "blur": (lambda r: {"blurred": r}, r"blurred", r"blurred"),
    "wrong angle_sign": (lambda r: {}, r"angle_sign is inverted", r"angle_sign is inverted"),
    "clean": (lambda r: {}, None, None),
}


def mistake_row(kind: str, rng, torques) -> int:
    """A row for the mistake where the step checks can see it: inside a branch of
    the loop (the load changing the same way for the steps before and after it).
    The first image after a load reversal has no step of its branch to compare
    with (the gear's stiffness may switch there by 15×), so a shot missed there
    shows only as a row left without a photograph at the end."""
    if kind == "wrong angle_sign":
        return 1
    d = np.sign(np.diff(torques))  # d[r - 1]: the step into row r
    after = 2 if kind == "two shots swapped" else 1
    inside = [r for r in range(3, len(torques) - after)
              if all(d[r - 2 + j] == d[r - 1] for j in range(after + 2))]
    return int(rng.choice(inside))


def first_photo(kind: str, row: int, shots) -> int:
    """Capture position of the photograph the mistake is on (0-based)."""
    if kind == "missed shot":
        return next(k for k, s in enumerate(shots) if s.row > row)
    if kind == "extra shot":
        return next(k for k, s in enumerate(shots) if s.kind == "extra")
    return next(k for k, s in enumerate(shots) if s.row == row)


def one_session(gear: str, kind: str, seed: int, steps: int) -> dict:
    rng = np.random.default_rng(seed)
    spec = SessionSpec(max_torque_nm=steps * STEP_NM, orientations_deg=(0.0,))
    options, said, fixed = MISTAKES[kind]
    with tempfile.TemporaryDirectory() as tmp:
        session, camera = Path(tmp) / "s", Path(tmp) / "cam"
        plan, _ = capture_script(SCENE, spec, Path(tmp) / "plan", seed=seed)
        sign = {"ref": 0, "pos": 1, "neg": -1}
        torques = [sign[r["phase"][:3]] * 2 * float(r["mass_kg"]) * 9.81 * 0.05 for r in plan.rows]
        row = mistake_row(kind, rng, torques)
        plan, shots = capture_script(SCENE, spec, session, seed=seed, response=GEARS[gear], **options(row))
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
    withdrawn = sum(e.kind == "retracted" for e in events)
    gone = {e.file for e in events if e.kind == "retracted"}
    bind_text = [f.message for f in res.fixes] + list(res.diagnoses) + list(res.remaining)
    if res.command:
        bind_text.append(res.command)
    out = {"gear": gear, "mistake": kind, "seed": seed, "row": row, "withdrawn": withdrawn,
           "watch_said": [e.message for e in warned], "bind_said": bind_text + list(res.warnings)}
    if said is None:
        out.update(watch_detected=None, bind_detected=None, watch_false=len(warned) + withdrawn,
                   watch_standing=len({e.file for e in warned} - gone),
                   bind_false=len(bind_text) + len(res.warnings))
        return out
    at = first_photo(kind, row, shots)
    near = set(names[at:at + 2]) | ({names[at - 1]} if kind == "two shots swapped" else set())
    out["watch_detected"] = any(e.file in near and re.search(said, e.message)
                                and names.index(last[id(e)]) <= at + 1 for e in warned)
    out["bind_detected"] = any(re.search(fixed, t) for t in bind_text)
    out["watch_false"] = sum(1 for e in warned if e.file not in near) + withdrawn
    out["watch_standing"] = len({e.file for e in warned if e.file not in near} - gone)
    out["bind_false"] = 0
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=1, help="sessions per gear and mistake")
    ap.add_argument("--steps", type=int, default=4, help="weight steps per phase")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = []
    for gear in GEARS:
        for j, kind in enumerate(MISTAKES):
            for s in range(args.seeds):
                rows.append(one_session(gear, kind, 1000 * s + 17 * j + len(gear), args.steps))
    print(f"{len(rows)} sessions ({len(GEARS)} gears × {len(MISTAKES)} cases × {args.seeds}), "
          f"{2 + 4 * args.steps} photographs each, {time.perf_counter() - t0:.0f} s\n")
    print(f"{'mistake':<20} {'sessions':>8} {'watch found':>11} {'bind found':>10} "
          f"{'watch false':>11} {'standing':>8} {'bind false':>10}")
    for kind in MISTAKES:
        sel = [r for r in rows if r["mistake"] == kind]
        found_w = "—" if kind == "clean" else f"{sum(r['watch_detected'] for r in sel)}/{len(sel)}"
        found_b = "—" if kind == "clean" else f"{sum(r['bind_detected'] for r in sel)}/{len(sel)}"
        print(f"{kind:<20} {len(sel):>8} {found_w:>11} {found_b:>10} {sum(r['watch_false'] for r in sel):>11} "
              f"{sum(r['watch_standing'] for r in sel):>8} {sum(r['bind_false'] for r in sel):>10}")
    missed = [r for r in rows if r["mistake"] != "clean" and not (r["watch_detected"] and r["bind_detected"])]
    for r in missed:
        print(f"  not caught: {r['gear']}, {r['mistake']} at row {r['row']} (seed {r['seed']}): "
              f"watch {r['watch_detected']}, bind {r['bind_detected']}")
    kept = [{k: v for k, v in r.items() if not k.endswith("_said")} for r in rows]  # messages hold temp paths
    write_result(HERE / "results" / "capture.json", {"sessions": kept, "steps": args.steps, "seeds": args.seeds})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
