"""Markers on real photographs: recall, row straightness and time, without ground truth.

Run (one command; about a minute on 2 cores)::

    python benchmarks/bench_photos.py                  # the photos of tests/data/photos
    python benchmarks/bench_photos.py --extra DIR      # also every image in DIR (full-size
                                                       # originals, see tests/data/photos/README.md)

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
- **time**: CPU time per photo on one core (OpenCV and BLAS single-threaded; CPU, not
  wall, time because the machine is shared) of the whole job: ours is ``find_markers``
  on the image (detection and every fit); a peer
  is the reference detection plus its fit of every reference dot, started from the
  reference blob (so the peers are handed the dots; we find them ourselves).

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
from photo_grid import grid_triples, off_line, reference_dots  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from vision_torsion.images import load_image  # noqa: E402
from vision_torsion.markers import find_markers  # noqa: E402

PHOTO_DIR = HERE.parent / "tests" / "data" / "photos"
RESULTS = HERE / "results"


def _ours(img, dots):
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
    return c, dt, table


def _peer(fn, img, dots, t_ref):
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
    return c, t_ref + time.process_time() - t


METHODS = (
    ("moments", "intensity moments", peers.moments_centre),
    ("canny", "Canny + CircleModel", peers.canny_centre),
    ("ml_disc", "ML blurred-disc fit", peers.ml_disc_centre),
)


def measure_photo(path: Path) -> dict:
    grey = load_image(path, keep_integers=True)
    img = grey.data
    t = time.process_time()
    dots = reference_dots(img)
    t_ref = time.process_time() - t
    centres, times = {}, {}
    centres["ours"], times["ours"], table = _ours(img, dots)
    for name, _, fn in METHODS:
        centres[name], times[name] = _peer(fn, img, dots, t_ref)
    triples = grid_triples(dots[:, :2])
    every = np.ones(len(triples), bool)
    for c in centres.values():
        every &= np.isfinite(c[triples]).all(axis=(1, 2))
    used = triples[every]
    row = {
        "photo": path.name,
        "size": f"{img.shape[1]}x{img.shape[0]}",
        "bits": grey.bit_depth,
        "colour": bool(grey.was_colour),
        "reference_dots": int(len(dots)),
        "median_radius_px": float(np.median(dots[:, 2])) if len(dots) else float("nan"),
        "our_rows": {s: int(n) for s, n in table["status"].value_counts().items()},
        "triples": int(len(used)),
        "methods": {},
    }
    for name in ("ours",) + tuple(m[0] for m in METHODS):
        c = centres[name]
        found = np.isfinite(c).all(axis=1)
        row["methods"][name] = {
            "found": int(found.sum()),
            "recall": float(found.mean()) if len(dots) else float("nan"),
            "row_straightness_rms_px": float(np.sqrt(np.mean(off_line(c, used) ** 2))) if len(used) else float("nan"),
            "time_s": float(times[name]),
        }
    return row


def markdown(rows, command, info) -> str:
    labels = {"ours": "vision-torsion (default)", **{m[0]: m[1] for m in METHODS}}
    lines = [
        f"Photos benchmark, `{command}`, {info['date']}, {info['cpu_model']} "
        f"(load {info['load_average_1_5_15min']}; CPU seconds on one core).",
        "",
        "| photo | px, bits | ref. dots (r px) | triples | method | found ok | recall "
        "| row straightness RMS (px) | CPU s/photo |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        for k, (name, m) in enumerate(r["methods"].items()):
            head = (
                (
                    f"{r['photo']} | {r['size']}, {r['bits']}{' colour' if r['colour'] else ''} | "
                    f"{r['reference_dots']} ({r['median_radius_px']:.1f}) | {r['triples']}"
                )
                if k == 0
                else " | | |"
            )
            lines.append(
                f"| {head} | {labels[name]} | {m['found']} | {m['recall']:.1%} | "
                f"{m['row_straightness_rms_px']:.4f} | {m['time_s']:.3f} |"
            )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--extra", metavar="DIR", help="also measure every image in DIR")
    ap.add_argument("--no-write", action="store_true", help="print only")
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
    rows = [measure_photo(p) for p in paths]
    info = machine_info()
    command = "python benchmarks/bench_photos.py" + (f" --extra {args.extra}" if args.extra else "")
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
