"""N-marker targets on rendered scenes (issue 31): angle noise against the CRLB, the gain
over the two-marker target, and a camera bump told from a rotation.

    python benchmarks/bench_targets.py [--pairs N] [--pairs-two N]   # about 5 minutes

Every target sits on the standard scene's disk and exposure (synthetic/standard.toml:
1400x1000 px, 8 bit, dark dots, contrast 160 DN, blur 1 px, read noise 2 DN, the
rotation centre off the pixel grid). For each target, N image pairs (100 by default;
400 for the two-marker target, whose measurement takes milliseconds, so that the
gain is not limited by its scatter): a reference at
0° and a current image at an angle from every other one of the standard sweep's
(-70° to +65° in 15° steps, cycled),
each with fresh noise, so the errors are independent. Printed per target:

- RMS angle error (deg) against the true rotation, the RMS of the Cramér-Rao bound
  over the same pairs (all markers of both images, :func:`target_angle_bound_deg`;
  the two-marker target's is :func:`angle_bound_deg`), and their ratio;
- honesty: mean reported angle_std_deg over the empirical RMS;
- pairs whose identity was not ``ok``, and pairs falsely flagged as a bump.

Then the gain of the 16-dot ring over the two-marker target (RMS ratio), and a camera
bump: the same ring with the whole scene moved 1 px to the right (no rotation),
rendered with fresh noise per repeat: how often it is reported as a bump, and the
largest |angle| reported then.

Targets: the two-marker target of the standard scene (measured by the two-marker
pipeline, :func:`rotation_angle`), ``ring16`` (16 dots of r 36 px on the same 300 px
radius, index dot r 45 px) and ``grid5`` (5x5 dots, pitch 150 px, r 30 px, index r
41 px), measured by :func:`target_angle`.

Results also go to benchmarks/results/targets.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from common import git_commit, machine_info, one_core, write_result  # noqa: E402

from vision_torsion.angle import rotation_angle  # noqa: E402
from vision_torsion.markers import find_markers  # noqa: E402
from vision_torsion.rigid import target_angle  # noqa: E402
from vision_torsion.synthetic import load_scene, render, target_scene  # noqa: E402
from vision_torsion.synthetic.bounds import angle_bound_deg, target_angle_bound_deg  # noqa: E402
from vision_torsion.targets import load_target  # noqa: E402

#: (name, ready target or None for the standard two-marker target, px per mm)
TARGETS = (("two-marker", None, None), ("ring16", "ring16", 7.5), ("grid5", "grid5", 15.0))


def run_target(base, target, px_per_mm, pairs, seed0):
    angles = np.array(base.sweep.angles_deg[1::2], dtype=np.float64)  # 10 angles: one bound each
    scene = base if target is None else target_scene(target, px_per_mm=px_per_mm, base=base)
    bound_fn = angle_bound_deg if target is None else target_angle_bound_deg
    bounds = {a: bound_fn(scene, a) for a in np.unique(angles)}
    err, std, bnd, not_ok, bumps = [], [], [], 0, 0
    for k in range(pairs):
        a = float(angles[k % len(angles)])
        ref = render(scene, 0.0, seed=seed0 + 2 * k).image
        cur = render(scene, a, seed=seed0 + 2 * k + 1).image
        if target is None:
            res = rotation_angle(ref, cur)
        else:
            res = target_angle(find_markers(ref), find_markers(cur), target=target)
            if res.status != "ok":
                not_ok += 1
                continue
            bumps += bool(res.bump)
        err.append(res.angle_deg - a)
        std.append(res.angle_std_deg)
        bnd.append(bounds[a])
    err, std, bnd = np.array(err), np.array(std), np.array(bnd)
    rms = float(np.sqrt(np.mean(err**2)))
    crlb = float(np.sqrt(np.mean(bnd**2)))
    return {"pairs": int(pairs), "measured": int(err.size), "not_ok": not_ok, "false_bumps": bumps,
            "markers": len(scene.markers.positions_deg), "rms_deg": rms, "crlb_rms_deg": crlb,
            "rms_over_crlb": rms / crlb, "mean_error_deg": float(err.mean()),
            "std_over_rms": float(np.mean(std) / rms)}


def run_bump(base, repeats, seed0):
    scene = target_scene("ring16", px_per_mm=7.5, base=base)
    moved = scene.replace(disk=dataclasses.replace(scene.disk, center_x=scene.disk.center_x + 1.0))
    target = load_target("ring16")
    hits, worst, shifts = 0, 0.0, []
    for k in range(repeats):
        res = target_angle(render(scene, 0.0, seed=seed0 + 2 * k).image,
                           render(moved, 0.0, seed=seed0 + 2 * k + 1).image, target=target)
        hits += bool(res.bump and res.status == "ok")
        worst = max(worst, abs(res.angle_deg))
        shifts.append((res.shift_x_px, res.shift_y_px))
    s = np.array(shifts)
    return {"repeats": repeats, "reported_as_bump": hits, "largest_abs_angle_deg": worst,
            "mean_shift_px": [float(v) for v in s.mean(axis=0)], "shift_rms_px": [float(v) for v in s.std(axis=0)]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pairs", type=int, default=100, help="image pairs per target (default 100)")
    ap.add_argument("--pairs-two", type=int, default=400, help="image pairs of the two-marker target (default 400)")
    ap.add_argument("--bumps", type=int, default=20, help="renders of the 1 px bump (default 20)")
    args = ap.parse_args(argv)
    one_core()
    base = load_scene(ROOT / "vision_torsion" / "synthetic" / "scenes" / "standard.toml")
    t0 = time.time()
    rows = {}
    for i, (name, target, ppm) in enumerate(TARGETS):
        pairs = args.pairs if target is not None else args.pairs_two
        rows[name] = run_target(base, target, ppm, pairs, seed0=100000 * (i + 1))
    gain = rows["two-marker"]["rms_deg"] / rows["ring16"]["rms_deg"]
    bump = run_bump(base, args.bumps, seed0=9000)
    print(f"{'target':<11} {'dots':>4} {'pairs':>5} {'RMS deg':>10} {'CRLB deg':>10} {'RMS/CRLB':>8} "
          f"{'std/RMS':>7} {'not ok':>6} {'false bump':>10}")
    for name, r in rows.items():
        print(f"{name:<11} {r['markers']:>4} {r['measured']:>5} {r['rms_deg']:>10.6f} {r['crlb_rms_deg']:>10.6f} "
              f"{r['rms_over_crlb']:>8.3f} {r['std_over_rms']:>7.3f} {r['not_ok']:>6} {r['false_bumps']:>10}")
    print(f"gain of ring16 over the two-marker target (RMS ratio): {gain:.2f}x "
          f"(CRLB ratio {rows['two-marker']['crlb_rms_deg'] / rows['ring16']['crlb_rms_deg']:.2f}x)")
    print(f"1 px camera bump, no rotation: reported as a bump in {bump['reported_as_bump']}/{bump['repeats']} "
          f"images; mean shift ({bump['mean_shift_px'][0]:.4f}, {bump['mean_shift_px'][1]:.4f}) px; "
          f"largest |angle| {bump['largest_abs_angle_deg']:.6f} deg")
    print(f"({time.time() - t0:.0f} s)")
    out = ROOT / "benchmarks" / "results" / "targets.json"
    write_result(out, {"machine": machine_info(), "commit": git_commit(), "targets": rows,
                     "gain_ring16_over_two_marker": gain, "bump_1px": bump})
    print(f"wrote {out.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
