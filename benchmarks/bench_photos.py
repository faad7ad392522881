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
- **ours against the ML fit**: on every reference dot that both measured, the
  distance between our ``ok`` centre and the maximum-likelihood blurred-disc fit's
  (largest, 99th percentile, and how many are more than 0.5 px apart): a dot
  fitted ``ok`` far from the best independent fit is a silent error.
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

- **what a crop can rank** (with ``--extra``, for each original a committed crop
  was cut from: ``fetch_photos.ORIGINALS``): the full frame cut into windows of the
  crop's size, each scored as a crop is (:func:`photo_ranking.window_ranking`): in
  how many windows each method is the lowest, in how many ours is significantly
  above or below the best peer there, and the crop's own window scored in the full
  frame (its pixels checked to be the crop's). On a crop's 15-25 triples the
  methods' differences (0.0001-0.03 px) are far below what the triples resolve, so
  whichever is lowest there is the luck of those triples: the full frame's row
  ranks them.

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
from fetch_photos import ORIGINALS  # noqa: E402
from photo_grid import grid_lines, grid_triples, off_curve, off_line, reference_dots  # noqa: E402
from photo_ranking import WINDOW_TRIPLES, difference_interval, window_ranking  # noqa: E402
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


def measure_photo(path: Path, repeats: int = 1, crop=None) -> dict:
    """Every method on the photo at `path`: recall, row straightness, line-curve
    scatter and CPU times (`repeats` rounds), as one row of the results; with the
    :class:`fetch_photos.Crop` taken from it (`crop`, a full frame), also
    :func:`window_ranking` under ``windows``, with :func:`crop_matches`."""
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
    # our ok centres against the ML fit's on the same dots (the issue's "no dot > 0.5 px
    # off with status ok"): every reference dot both measured, not only the triples'
    both = np.isfinite(c_ours).all(axis=1) & np.isfinite(peer_centres["ml_disc"]).all(axis=1)
    apart = np.hypot(*(c_ours[both] - peer_centres["ml_disc"][both]).T)
    row["ours_vs_ml"] = {
        "compared": int(both.sum()),
        "max_px": float(apart.max()) if apart.size else float("nan"),
        "p99_px": float(np.percentile(apart, 99)) if apart.size else float("nan"),
        "over_0_5_px": int((apart > 0.5).sum()),
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
    if crop is not None:
        row["windows"] = window_ranking(dots, used, offs, img.shape, crop)
        row["windows"]["crop_is_this_window"] = crop_matches(img, crop)
    return row


def crop_matches(full: np.ndarray, crop) -> bool | None:
    """True when the committed crop (:class:`fetch_photos.Crop`) holds exactly the
    pixels of its window of the original (`full`, as :func:`measure_photo` loaded
    it); None when the crop is not here."""
    path = PHOTO_DIR / crop.name
    if not path.is_file():
        return None
    part = load_image(path, keep_integers=True).data
    window = full[crop.top : crop.top + crop.rows, crop.left : crop.left + crop.cols]
    return bool(window.shape == part.shape and np.array_equal(window, part))


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
    lines += [
        "",
        "Our ok centres against the ML blurred-disc fit's on the same photo (every reference dot both "
        "measured; the issue's target: none more than 0.5 px apart):",
        "",
    ]
    for r in rows:
        v = r["ours_vs_ml"]
        lines.append(
            f"- {r['photo']}: {v['compared']} dots, largest {v['max_px']:.3f} px, 99th percentile "
            f"{v['p99_px']:.3f} px, {v['over_0_5_px']} more than 0.5 px apart"
        )
    framed = [r for r in rows if "windows" in r]
    if framed:
        lines += [
            "",
            "What a crop can rank: each full frame cut into non-overlapping windows of its committed "
            f"crop's size, each window with at least {WINDOW_TRIPLES} triples scored as a crop is (ours "
            "minus the best peer in that window, paired 95 % interval); and the committed crop's own "
            "window, scored in the full frame:",
            "",
            "| full frame | window | scored windows | lowest of the four in how many: "
            + " / ".join(labels[k] for k in labels)
            + " | ours above the best peer, interval excluding 0 | ours below it, interval excluding 0 "
            "| ours − best peer, 5 / 50 / 95 % of windows (px) "
            "| the crop's window: triples, ours − best peer (interval) | crop = its window's pixels |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in framed:
            w = r["windows"]
            q = " / ".join(f"{v:+.4f}" for v in w["difference_quantiles_px"]) or "–"
            c = w["crop_window"]
            own = (
                f"{c['triples']}, {c['difference_px'][0]:+.4f} ({c['difference_px'][1]:+.4f} to "
                f"{c['difference_px'][2]:+.4f}) vs {labels[c['best_peer']]}"
                if c
                else f"fewer than {WINDOW_TRIPLES} triples"
            )
            match = {True: "yes", False: "NO", None: "crop absent"}[w.get("crop_is_this_window")]
            lines.append(
                f"| {r['photo']} | {w['size'][0]}x{w['size'][1]} | {w['scored']} of {w['windows']} | "
                f"{' / '.join(str(w['lowest'][k]) for k in labels)} | {w['ours_significantly_above']} | "
                f"{w['ours_significantly_below']} | {q} | {own} | {match} |"
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
    crops = {o.name: o.crop for o in ORIGINALS}
    if paths:  # warm-up, untimed: imports and first-call costs of every method
        measure_photo(paths[0])
    rows = [measure_photo(p, max(args.repeats, 1), crops.get(p.name)) for p in paths]
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
