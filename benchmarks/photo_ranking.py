"""Ranking centre-finding methods by the row straightness of a dot-grid photo.

Shared by ``bench_photos.py`` and the photo tests (no side effects at import).
Inputs are each method's off-line distances on the same triples
(:func:`photo_grid.off_line`): the target's and the lens's own deviations are common
to every method, so methods are compared paired, triple by triple.
"""

from __future__ import annotations

import numpy as np
from photo_grid import whole_in

__all__ = ["difference_interval", "window_ranking", "BOOTSTRAP", "WINDOW_TRIPLES"]


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


#: Fewest triples a crop-sized window of a full frame needs to be scored.
WINDOW_TRIPLES = 10


def window_ranking(dots, used, offs, shape, crop) -> dict:
    """What a crop can tell about the ranking, from a full frame cut into crop-sized windows.

    Parameters
    ----------
    dots : numpy.ndarray
        (n, 3) reference dots of the full frame: x, y, r (px).
    used : numpy.ndarray
        (k, 3) triples of dot indices every method measured.
    offs : dict of str to numpy.ndarray
        Each method's off-line distance (px) per triple; ``"ours"`` among them.
    shape : tuple of int
        The full frame's (rows, cols).
    crop : fetch_photos.Crop
        The committed crop: its size sets the windows', its place the last one scored.

    Returns
    -------
    dict
        The frame cut into non-overlapping windows of the crop's size, each with at
        least :data:`WINDOW_TRIPLES` triples whose three dots lie whole inside it
        scored as a crop is: ours minus the best peer's row straightness there, with
        its paired 95 % interval (:func:`difference_interval`). Counted: the windows
        where each method is the lowest of all (what a crop's ranking says taken at
        face value: when the methods differ by less than a window's triples resolve,
        the best over the whole frame is lowest in few), and those where ours is above
        or below the best peer with an interval that excludes 0. The committed crop's
        own window of the full frame is scored the same way (``crop_window``).
    """

    def score(top, left):
        inside = whole_in(dots, crop.rows, crop.cols, top=top, left=left)
        pick = inside[used].all(axis=1) if len(used) else np.zeros(0, bool)
        if pick.sum() < WINDOW_TRIPLES:
            return None
        rms = {k: float(np.sqrt(np.mean(o[pick] ** 2))) for k, o in offs.items()}
        best = min((k for k in rms if k != "ours"), key=rms.get)
        d, lo, hi = difference_interval(offs["ours"][pick], offs[best][pick])
        return {
            "top": top,
            "left": left,
            "triples": int(pick.sum()),
            "lowest": min(rms, key=rms.get),
            "best_peer": best,
            "difference_px": [d, lo, hi],
        }

    h, w = shape
    tops, lefts = range(0, h - crop.rows + 1, crop.rows), range(0, w - crop.cols + 1, crop.cols)
    scored = [score(top, left) for top in tops for left in lefts]
    windows = [s for s in scored if s is not None]
    diffs = np.array([s["difference_px"] for s in windows]).reshape(-1, 3)
    return {
        "crop": crop.name,
        "size": [crop.cols, crop.rows],
        "windows": len(scored),
        "scored": len(windows),
        # each method's count of windows where it is the lowest of all: what a crop
        # ranks if it is taken at face value
        "lowest": {k: sum(s["lowest"] == k for s in windows) for k in offs},
        "ours_significantly_above": int(np.sum(diffs[:, 1] > 0)),
        "ours_significantly_below": int(np.sum(diffs[:, 2] < 0)),
        "difference_quantiles_px": np.percentile(diffs[:, 0], [5, 50, 95]).tolist() if len(diffs) else [],
        "crop_window": score(crop.top, crop.left),
        "per_window": windows,
    }
