"""Is the centre's σ of a JPEG's markers honest, small markers included? (issue 31)

    python benchmarks/bench_jpeg_sigma.py [--renders 30] [--radii 8,12,20,30,60] [--qualities 0,75,85,95]
        [--blur 1] [--noise 2]

(from the repository root; ``PYTHONPATH=.`` when the installed ``vision_torsion`` is another checkout)

Each render is a 1-marker-wide ring of dark markers (8 of radius r px, 4 when r > 40;
contrast 160 DN, blur 1 px, read noise 2 DN) on a square image, turned by a random
angle so that the markers sit at random sub-pixel places and phases of the 8x8
grid; it is encoded at the JPEG quality q (0: none, the lossless case) with
``cv2.imencode``, decoded, and measured with :func:`vision_torsion.find_markers`
twice: as the JPEG it is (``jpeg_block_px`` 8: the covariance from the blocks) and
as if lossless (``jpeg_block_px`` 0: σ²(JᵀJ)⁻¹, white noise). Per (r, q) the table
gives the ratio RMS(centre error) / RMS(stated σ) over both coordinates of every
``ok`` marker for each: 1 is honest, above 1 the σ is too small. The target: 0.9-1.15
with the blocks; lossless rows are the same both ways. The ratio of n centre
coordinates scatters by about 1/√(2n) (the last column).

Prints the table and writes ``benchmarks/results/jpeg_sigma.json``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from common import one_core, write_result  # noqa: E402

from vision_torsion.images import GreyImage  # noqa: E402
from vision_torsion.markers import find_markers  # noqa: E402
from vision_torsion.synthetic import Scene, render  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results" / "jpeg_sigma.json"


def ring_scene(radius: float, *, blur_px: float = 1.0, noise_dn: float = 2.0) -> Scene:
    """8 dark markers of `radius` px (4 when over 40 px) on a ring, gaps of over a
    radius between them, on a square image with 40 px to spare; blur σ `blur_px`,
    read noise `noise_dn` (DN)."""
    n = 8 if radius <= 40 else 4
    distance = max(3.2 * radius * n / (2 * np.pi), 3 * radius + 40)
    side = int(2 * (distance + radius + 40))
    return Scene().replace(
        image={"width": side, "height": side},
        disk={"center_x": side / 2 - 0.37, "center_y": side / 2 + 0.21, "background_level": 200.0},
        markers={"radius_px": radius, "distance_px": distance, "positions_deg": tuple(np.arange(n) * 360.0 / n)},
        optics={"blur_sigma_px": blur_px}, noise={"read_noise_dn": noise_dn},
    )


def _errors(image, block_px: int, centres: np.ndarray):
    """(errors, σ) of the ``ok`` markers' centre coordinates, each (2k,), against the true `centres`."""
    table = find_markers(GreyImage(image, "render", 8, jpeg_block_px=block_px), polarity="dark")
    ok = table[table["status"] == "ok"]
    xy = ok[["x_px", "y_px"]].to_numpy()
    if not len(xy):
        return np.zeros(0), np.zeros(0)
    d = np.hypot(xy[:, None, 0] - centres[:, 0], xy[:, None, 1] - centres[:, 1])
    truth = centres[d.argmin(axis=1)]
    close = d.min(axis=1) < 2.0
    err = (xy - truth)[close].ravel()
    std = ok[["x_std_px", "y_std_px"]].to_numpy()[close].ravel()
    return err, std


def coverage(radius: float, quality: int, renders: int, seed: int, **scene) -> dict:
    """The row of (`radius`, `quality`) over `renders` renders from `seed` (`scene`:
    :func:`ring_scene`'s options)."""
    scene = ring_scene(radius, **scene)
    rng = np.random.default_rng(seed)
    found = {"blocks": ([], []), "white": ([], [])}
    for _ in range(renders):
        rendered = render(scene, float(rng.uniform(0.0, 360.0)), seed=rng)
        image = rendered.image
        if quality:
            image = cv2.imdecode(cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])[1],
                                 cv2.IMREAD_UNCHANGED)
        for name, block in (("blocks", 8 if quality else 0), ("white", 0)):
            err, std = _errors(image, block, rendered.centres)
            found[name][0].append(err)
            found[name][1].append(std)
    row = {"radius_px": radius, "quality": quality}
    for name, (errs, stds) in found.items():
        err, std = np.concatenate(errs), np.concatenate(stds)
        row[f"n_{name}"] = int(err.size)
        row[f"ratio_{name}"] = float(np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(std**2))) if err.size else None
    row["ratio_scatter"] = 1.0 / np.sqrt(2.0 * max(row["n_blocks"], 1))
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--renders", type=int, default=30, help="renders per (radius, quality) (default 30)")
    parser.add_argument("--radii", default="8,12,20,30,60", help="marker radii, px (default 8,12,20,30,60)")
    parser.add_argument("--qualities", default="0,75,85,95", help="JPEG qualities, 0 = none (default 0,75,85,95)")
    parser.add_argument("--blur", type=float, default=1.0, help="blur σ, px (default 1)")
    parser.add_argument("--noise", type=float, default=2.0, help="read noise, DN (default 2)")
    parser.add_argument("--seed", type=int, default=31)
    args = parser.parse_args(argv)
    one_core()
    radii = [float(v) for v in args.radii.split(",")]
    qualities = [int(v) for v in args.qualities.split(",")]
    rows = []
    print("RMS(error)/RMS(σ) of the centres' coordinates; target 0.9-1.15 with the blocks")
    print(f"{'r px':>5} {'q':>4} {'n':>5} {'blocks':>7} {'white':>7} {'±':>6}")
    for k, radius in enumerate(radii):
        for j, quality in enumerate(qualities):
            row = coverage(radius, quality, args.renders if radius <= 40 else max(args.renders // 2, 4),
                           args.seed + 100 * k + j, blur_px=args.blur, noise_dn=args.noise)
            rows.append(row)
            print(f"{radius:5.0f} {quality or 'png':>4} {row['n_blocks']:5d} {row['ratio_blocks']:7.2f} "
                  f"{row['ratio_white']:7.2f} {row['ratio_scatter']:6.2f}", flush=True)
    write_result(RESULTS, {"renders": args.renders, "seed": args.seed, "blur_px": args.blur,
                           "read_noise_dn": args.noise, "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
