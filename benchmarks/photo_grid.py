"""The grid of a dot-target photograph without ground truth: reference dots and row triples.

Shared by ``bench_photos.py`` and the photo tests (no side effects at import). See
``bench_photos.py`` for why these are the reference and the precision measure.
Coordinates: image pixels (x, y), origin at the centre of the top-left pixel.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

__all__ = [
    "reference_dots",
    "whole_in",
    "grid_triples",
    "off_line",
    "grid_lines",
    "off_curve",
    "SYMMETRY",
    "CURVE_ORDER",
]

#: A triple's outer dots must be symmetric about the middle one within this fraction
#: of their spacing to count as grid neighbours on one row.
SYMMETRY = 0.2


def reference_dots(img: np.ndarray) -> np.ndarray:
    """Grid dots (rows of x, y, r in px) of OpenCV's SimpleBlobDetector (see the
    docstring of bench_photos.py for its settings and the grid-dot rule)."""
    g8 = img if img.dtype == np.uint8 else cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX, dtype=cv2.CV_8U)
    h, w = g8.shape
    p = cv2.SimpleBlobDetector_Params()
    p.minThreshold, p.maxThreshold, p.thresholdStep = 10, 250, 10
    p.filterByColor, p.blobColor = True, 0
    p.filterByArea, p.minArea, p.maxArea = True, np.pi * 2.0**2, np.pi * (min(h, w) / 5) ** 2
    p.filterByCircularity, p.minCircularity = True, 0.7
    p.filterByConvexity, p.minConvexity = True, 0.85
    p.filterByInertia, p.minInertiaRatio = True, 0.3
    kps = cv2.SimpleBlobDetector_create(p).detect(g8)
    if not kps:
        return np.zeros((0, 3))
    dots = np.array([(k.pt[0], k.pt[1], k.size / 2) for k in kps])
    med = np.median(dots[:, 2])
    keep = (dots[:, 2] > 0.6 * med) & (dots[:, 2] < 1.6 * med)
    keep &= whole_in(dots, h, w)
    return dots[keep]


def whole_in(dots: np.ndarray, rows: int, cols: int, *, top: int = 0, left: int = 0) -> np.ndarray:
    """Flags of the dots (rows of x, y, r in px) whose disc, 2 px wider, lies inside
    the window of `rows` x `cols` pixels whose top-left pixel is (`top`, `left`)
    (pixels span -0.5 .. size - 0.5): a whole dot of an image that size. A dot cut
    by the border is reported ``border`` by us, and has no whole edge to fit for anyone."""
    x, y, r = dots[:, 0] - left, dots[:, 1] - top, dots[:, 2] + 2.0
    return (x - r >= -0.5) & (y - r >= -0.5) & (x + r <= cols - 0.5) & (y + r <= rows - 0.5)


def grid_triples(xy: np.ndarray) -> np.ndarray:
    """(k, 3) indices (a, p, b): p's two grid neighbours a and b on one row or column."""
    if len(xy) < 3:
        return np.zeros((0, 3), int)
    tree = cKDTree(xy)
    _, nn = tree.query(xy, k=min(7, len(xy)))
    out = set()
    for p, cand in enumerate(nn):
        cand = cand[1:]
        spacing = np.linalg.norm(xy[cand[0]] - xy[p])
        for i, a in enumerate(cand):
            va = xy[a] - xy[p]
            if np.linalg.norm(va) > 1.5 * spacing:
                continue
            for b in cand[i + 1:]:
                vb = xy[b] - xy[p]
                if np.linalg.norm(va + vb) < SYMMETRY * np.linalg.norm(va):
                    out.add((min(a, b), p, max(a, b)))
    return np.array(sorted(out), int).reshape(-1, 3)


def off_line(c: np.ndarray, triples: np.ndarray) -> np.ndarray:
    """Distance (px) of each triple's middle centre from the line through its outer two."""
    a, p, b = c[triples[:, 0]], c[triples[:, 1]], c[triples[:, 2]]
    ab = b - a
    cross = ab[:, 0] * (p - a)[:, 1] - ab[:, 1] * (p - a)[:, 0]
    return np.abs(cross) / np.linalg.norm(ab, axis=1)




#: Order of the curve fitted to each grid line's centres by :func:`off_curve`.
CURVE_ORDER = 2


def grid_lines(triples: np.ndarray) -> list[np.ndarray]:
    """The grid's lines (rows, columns, diagonals) as arrays of dot indices: triples
    that share a pair of neighbouring dots lie on one line, so lines are the
    connected groups of neighbour pairs linked by triples."""
    parent: dict = {}

    def root(e):
        parent.setdefault(e, e)
        while parent[e] != e:
            parent[e] = parent[parent[e]]
            e = parent[e]
        return e

    for a, p, b in triples:
        e1, e2 = (min(a, p), max(a, p)), (min(p, b), max(p, b))
        parent[root(e1)] = root(e2)
    groups: dict = {}
    for e in parent:
        groups.setdefault(root(e), set()).update(e)
    return [np.array(sorted(g), int) for g in groups.values()]


def off_curve(c: np.ndarray, lines: list[np.ndarray], order: int = CURVE_ORDER) -> tuple[float, int]:
    """Centre scatter about a smooth curve per grid line (px) and its degrees of freedom.

    Each line with more than ``order + 1`` dots: the dots' offsets across the line
    (from the straight line through its end dots) fitted by a polynomial of `order`
    in their position along it; returns the pooled RMS residual, sqrt(Σ res² / Σ (n -
    order - 1)), which estimates the per-coordinate centre error σ with the lens's
    smooth bending of the line (to that order) taken out, and Σ (n - order - 1).
    """
    ss, dof = 0.0, 0
    for line in lines:
        if line.size <= order + 1:
            continue
        pts = c[line]
        d = pts[-1] - pts[0]
        # ordered along the line by projection (the indices are not in line order)
        u = d / np.linalg.norm(d)
        t = (pts - pts[0]) @ u
        pts, t = pts[np.argsort(t)], np.sort(t)
        u = (pts[-1] - pts[0]) / np.linalg.norm(pts[-1] - pts[0])
        v = (pts - pts[0]) @ np.array([-u[1], u[0]])
        t = (pts - pts[0]) @ u
        tn = (t - t.mean()) / (np.ptp(t) or 1.0)
        design = np.vander(tn, order + 1)
        coef, *_ = np.linalg.lstsq(design, v, rcond=None)
        ss += float(np.sum((v - design @ coef) ** 2))
        dof += line.size - order - 1
    return (float(np.sqrt(ss / dof)) if dof else float("nan")), dof
