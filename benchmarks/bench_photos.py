"""Markers on real photographs: recall, row straightness and time, without ground truth.

Run (one command; about a minute on one core)::

    python benchmarks/bench_photos.py                  # the photos of tests/data/photos
    python benchmarks/bench_photos.py --extra DIR      # also every image in DIR: the full-size
                                                       # originals, which fetch_photos.py writes
                                                       # (tests/data/photos/README.md)

Each photo is a public photograph of a dot target (calibration plate or circle grid;
provenance and licence in ``tests/data/photos/README.md``). There is no ground truth,
so two properties that need none are measured:

- **recall**: dots found ``ok`` by :func:`vision_torsion.find_markers` at its default
  settings ÷ the grid dots of a reference detector. The reference is OpenCV's
  ``SimpleBlobDetector`` (the blob finder ``findCirclesGrid`` uses), run on the
  8-bit image with thresholds every 10 DN, area from a 2 px radius to a fifth of
  the image, circularity ≥ 0.7, convexity ≥ 0.85, inertia ratio ≥ 0.3; its blobs
  are then kept as *grid dots* when their radius is within 0.6-1.6x the median
  blob's (a grid's dots are alike: dust and the odd large fiducial are not dots of
  the grid) and their disc, 2 px wider, lies wholly inside the image (a dot cut by
  the border is reported ``border`` by us, and has no whole edge to fit for anyone).
  A reference dot counts as found when an ``ok`` marker lies within half its radius.
- **row straightness** (precision): the grid's rows and columns are straight lines on
  the target, and collinearity survives any camera homography, so the distance of a
  dot's centre from the line through its two grid neighbours (the dots on either side
  of it, found as nearest neighbours symmetric about it within 20 % of their spacing)
  is centre error, with no truth needed. Its RMS over all such triples is reported
  (px). With equal, independent centre errors σ per coordinate it is σ·√1.5; lens
  distortion adds a common curvature (the second difference of the distortion over
  one spacing, far below these numbers on a sharp lens), the same for every method.
  Every method is scored on the same triples: those whose three dots every method
  measured.
- **scatter about each line's curve** (px): the same lines' dots, each line with
  at least four of them, fitted by a quadratic across the line in the position
  along it (``photo_grid.off_curve``); the pooled residual RMS with the fitted
  parameters' degrees of freedom taken out (``dof`` in the table). A quadratic takes
  out the smooth bending of a line by lens distortion, which on these photos
  (discorpy 02, the UCL laparoscope) is most of the row straightness above and is the
  same for every method; what remains is centre error and the target's own dot
  placement. Scored on the same dots for every method. Both figures are given:
  neither is ours alone. Under the table: our row straightness minus the best
  peer's, with a 95 % interval from a paired bootstrap over the triples (the same
  resampled triples for both methods: the target's and the lens's share cancels).
- **time**: CPU time per photo on one core (OpenCV and BLAS single-threaded; CPU, not
  wall, time because the machine is shared; the least of ``--repeats`` runs, 5 by
  default, as other work only ever adds time; every method runs once per round, so
  the ML fit's time over ours is also given per round, both timed under the same
  load: the median and range of those ratios), two ways:

  - *fit only*: every method handed the same reference dots (centre and radius as
    the start, the neighbours' discs to leave out): ours is
    :func:`vision_torsion.markers.find_marker_list` with the reference dots as its
    candidates (every dot judged and fitted); a peer its fit of every dot;
  - *whole*: ours is ``find_markers`` on the image (detection, judging and fitting
    every candidate, grid dots or not); a peer is the reference detection plus its
    fit of every reference dot (so the peers are still handed the dots).

  The issue's speed target (>= 5x the ML blurred-disc fit) is judged on *fit only*,
  where both do the same work; *whole* is given as well.

Peers (:mod:`peers`, the same code as the rendered-scene benchmark, given each dot's
start and its neighbours' discs to leave out of its window, as a careful user would
on a dense grid): intensity moments, scikit-image Canny + ``CircleModel``, and the
maximum-likelihood blurred-disc fit.

Results: ``benchmarks/results/photos.json`` and ``photos.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from common import machine_info, one_core  # noqa: E402

one_core()

import numpy as np  # noqa: E402
import peers  # noqa: E402
from photo_grid import grid_lines, grid_triples, off_curve, off_line, reference_dots  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from vision_torsion.detect import Blob  # noqa: E402
from vision_torsion.images import load_image  # noqa: E402
from vision_torsion.markers import find_marker_list, find_markers  # noqa: E402
from vision_torsion.settings import MeasureSettings  # noqa: E402

PHOTO_DIR = HERE.parent / "tests" / "data" / "photos"
RESULTS = HERE / "results"


def _ours(img, dots):
    """Our ok centres matched to the reference dots (NaN: not found), the table, and
    the CPU time (s) of ``find_markers``."""
    t = time.process_time()
    table = find_markers(img)
    dt = time.process_time() - t
    ok = table[table["status"] == "ok"]
    c = np.full((len(dots), 2), np.nan)
    if len(ok):
        tree = cKDTree(ok[["x_px", "y_px"]].to_numpy())
        d, j = tree.query(dots[:, :2])
        hit = d < 0.5 * dots[:, 2]
        c[hit] = ok[["x_px", "y_px"]].to_numpy()[j[hit]]
    return (c, table), dt


def _ours_fit_only(img, dots):
    """CPU time (s) of our judging and fitting of the reference dots, handed to
    :func:`find_marker_list` as its candidates (as the peers are handed them)."""
    blobs = [Blob(x=x, y=y, radius=r, elongation=1.0, fill=1.0, touches_border=False) for x, y, r in dots]
    settings = MeasureSettings()
    t = time.process_time()
    find_marker_list(img, settings, candidates=blobs)
    return time.process_time() - t


def _peer(fn, img, dots):
    f = img.astype(np.float64)
    tree = cKDTree(dots[:, :2])
    c = np.full((len(dots), 2), np.nan)
    t = time.process_time()
    for k, (x, y, r) in enumerate(dots):
        near = [j for j in tree.query_ball_point((x, y), 2 * r + 20) if j != k]
        try:
            c[k] = fn(f, x, y, r, others=dots[near])[:2]
        except peers.PeerFailure:
            pass
    return c, time.process_time() - t


METHODS = (
    ("moments", "intensity moments", peers.moments_centre),
    ("canny", "Canny + CircleModel", peers.canny_centre),
    ("ml_disc", "ML blurred-disc fit", peers.ml_disc_centre),
)


def measure_photo(path: Path, repeats: int = 1) -> dict:
    grey = load_image(path, keep_integers=True)
    img = grey.data
    dots = reference_dots(img)
    # every method once per round, rounds repeated: each method's least CPU time
    # (other work only ever adds time), and the ML fit's time over ours per round
    # (both timed within moments of each other, under the same load)
    runs: dict = {}
    for _ in range(repeats):
        t = time.process_time()
        reference_dots(img)
        runs.setdefault("reference", []).append(time.process_time() - t)
        (c_ours, table), t_ours = _ours(img, dots)
        runs.setdefault("ours", []).append(t_ours)
        runs.setdefault("ours_fit", []).append(_ours_fit_only(img, dots))
        peer_centres = {}
        for name, _, fn in METHODS:
            peer_centres[name], t = _peer(fn, img, dots)
            runs.setdefault(name, []).append(t)
    t_ref = min(runs["reference"])
    centres = {"ours": c_ours, **peer_centres}
    times = {"ours": min(runs["ours"])}
    fit_times = {"ours": min(runs["ours_fit"])}
    for name, _, _ in METHODS:
        fit_times[name] = min(runs[name])
        times[name] = t_ref + fit_times[name]
    paired = {
        "fit_only": [ml / ours for ml, ours in zip(runs["ml_disc"], runs["ours_fit"])],
        "whole": [(ref + ml) / ours for ref, ml, ours in zip(runs["reference"], runs["ml_disc"], runs["ours"])],
    }
    triples = grid_triples(dots[:, :2])
    every = np.ones(len(triples), bool)
    for c in centres.values():
        every &= np.isfinite(c[triples]).all(axis=(1, 2))
    used = triples[every]
    lines = grid_lines(used)
    row = {
        "photo": path.name,
        "size": f"{img.shape[1]}x{img.shape[0]}",
        "bits": grey.bit_depth,
        "colour": bool(grey.was_colour),
        "reference_dots": int(len(dots)),
        "median_radius_px": float(np.median(dots[:, 2])) if len(dots) else float("nan"),
        "our_rows": {s: int(n) for s, n in table["status"].value_counts().items()},
        "triples": int(len(used)),
        "curve_dof": int(off_curve(dots[:, :2], lines)[1]),
        # the ML fit's CPU time over ours in each round (fit only; whole)
        "ml_over_ours_per_round": paired,
        "methods": {},
    }
    offs = {name: off_line(c, used) for name, c in centres.items()}
    for name in ("ours",) + tuple(m[0] for m in METHODS):
        c = centres[name]
        found = np.isfinite(c).all(axis=1)
        row["methods"][name] = {
            "found": int(found.sum()),
            "recall": float(found.mean()) if len(dots) else float("nan"),
            "row_straightness_rms_px": float(np.sqrt(np.mean(off_line(c, used) ** 2))) if len(used) else float("nan"),
            "line_curve_scatter_px": off_curve(c, lines)[0],
            # ours minus this method, with its 95 % paired-bootstrap interval
            "straightness_difference_px": difference_interval(offs["ours"], offs[name]),
            "fit_time_s": float(fit_times[name]),
            "time_s": float(times[name]),
        }
    return row


#: Bootstrap resamples of the triples for the interval of a straightness difference.
BOOTSTRAP = 2000


def difference_interval(off_a, off_b, seed=0) -> tuple[float, float, float]:
    """RMS(off_a) - RMS(off_b) (px) of two methods' off-line distances on the same
    triples, and its 95 % interval from a paired bootstrap over the triples (seeded).

    The triples share the target's and the lens's own deviations, which dominate
    row straightness on discorpy 02 and the UCL photo; resampled together, an
    interval that holds 0 says the photo cannot rank the two methods."""
    off_a, off_b = np.asarray(off_a), np.asarray(off_b)
    if not off_a.size:
        return float("nan"), float("nan"), float("nan")
    pick = np.random.default_rng(seed).integers(0, off_a.size, (BOOTSTRAP, off_a.size))
    d = np.sqrt(np.mean(off_a[pick] ** 2, axis=1)) - np.sqrt(np.mean(off_b[pick] ** 2, axis=1))
    lo, hi = np.percentile(d, [2.5, 97.5])
    return float(np.sqrt(np.mean(off_a**2)) - np.sqrt(np.mean(off_b**2))), float(lo), float(hi)


def markdown(rows, command, info) -> str:
    labels = {"ours": "vision-torsion (default)", **{m[0]: m[1] for m in METHODS}}
    lines = [
        f"Photos benchmark, `{command}`, {info['date']}, {info['cpu_model']} "
        f"(load {info['load_average_1_5_15min']}; CPU seconds on one core).",
        "",
        "| photo | px, bits | ref. dots (r px) | triples, dof | method | found ok | recall "
        "| row straightness RMS (px) | scatter about line curve (px) | CPU s fit only | CPU s whole |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        for k, (name, m) in enumerate(r["methods"].items()):
            head = (
                (
                    f"{r['photo']} | {r['size']}, {r['bits']}{' colour' if r['colour'] else ''} | "
                    f"{r['reference_dots']} ({r['median_radius_px']:.1f}) | {r['triples']}, {r['curve_dof']}"
                )
                if k == 0
                else " | | |"
            )
            lines.append(
                f"| {head} | {labels[name]} | {m['found']} | {m['recall']:.1%} | "
                f"{m['row_straightness_rms_px']:.4f} | {m['line_curve_scatter_px']:.4f} | "
                f"{m['fit_time_s']:.3f} | {m['time_s']:.3f} |"
            )
    lines += [
        "",
        "Row straightness, ours minus the best peer's, with its 95 % interval (paired bootstrap "
        "over the triples; an interval holding 0: the photo cannot rank the two):",
        "",
    ]
    for r in rows:
        peers_ = {k: v for k, v in r["methods"].items() if k != "ours"}
        best = min(peers_, key=lambda k: peers_[k]["row_straightness_rms_px"])
        d, lo, hi = peers_[best]["straightness_difference_px"]
        lines.append(f"- {r['photo']}: {d:+.4f} px ({lo:+.4f} to {hi:+.4f}) against {labels[best]}")
    lines += [
        "",
        "ML blurred-disc fit's CPU time over ours (the issue's target: >= 5x, judged on fit only): "
        "the median over the rounds of the two timed side by side, [lowest, highest round]:",
        "",
    ]
    for r in rows:
        p = r["ml_over_ours_per_round"]
        lines.append(
            f"- {r['photo']}: fit only {np.median(p['fit_only']):.1f}x "
            f"[{min(p['fit_only']):.1f}, {max(p['fit_only']):.1f}], "
            f"whole {np.median(p['whole']):.1f}x [{min(p['whole']):.1f}, {max(p['whole']):.1f}]"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--extra", metavar="DIR", help="also measure every image in DIR")
    ap.add_argument("--no-write", action="store_true", help="print only")
    ap.add_argument("--repeats", type=int, default=5,
                    help="timed runs per method; the least CPU time is kept (default 5)")
    args = ap.parse_args(argv)
    from vision_torsion.images import IMAGE_SUFFIXES

    paths = sorted(p for p in PHOTO_DIR.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if args.extra:
        extra = Path(args.extra)
        if extra.is_dir():
            paths += sorted(p for p in extra.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        else:
            print(f"--extra {extra}: no such folder, skipped")
    if paths:  # warm-up, untimed: imports and first-call costs of every method
        measure_photo(paths[0])
    rows = [measure_photo(p, max(args.repeats, 1)) for p in paths]
    info = machine_info()
    command = "python benchmarks/bench_photos.py" + (f" --extra {args.extra}" if args.extra else "")
    command += f" --repeats {args.repeats}" if args.repeats != 5 else ""
    md = markdown(rows, command, info)
    print(md)
    if not args.no_write:
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / "photos.json").write_text(
            json.dumps({"machine": info, "command": command, "photos": rows}, indent=1)
        )
        (RESULTS / "photos.md").write_text(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
