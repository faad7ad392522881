"""The rows of ``measurements.csv`` for a session of an N-marker target.

A session whose session.toml has a ``[target]`` table (``plan --target ring16``) is
processed as the two-marker one is (:mod:`.process`: the same reading threads, cache
and pending rows), with two differences, both here:

1. Each image's measurement is every marker found (:func:`measure_target_markers`,
   the markers' centres, radii and their covariances), not a pair; the cache key
   holds the target (:func:`target_settings_key`), so the same images planned with
   another target, or with two markers, are measured apart.
2. Per orientation, in manifest order, each image is compared with the
   orientation's reference image by :func:`vision_torsion.rigid.target_angles`: the
   markers are named after the target's dots in every image (never tracked, so no
   identity can be lost between images), and the angle is the weighted rigid fit of
   all of them, with its σ. Then :func:`vision_torsion.rigid.axis_motion` follows the
   shaft axis along the orientation: its motion since the reference (the target's
   eccentricity removed) fills the columns
   :data:`vision_torsion.measurements.TARGET_RESULT_COLUMNS`, and an image where it
   jumped (a bump) is flagged.

Per-image status (``status`` column) and its reason (``message``):

- ``ok``: every dot found and used; a dot the rigid fit dropped (occluded, dirty)
  is named in the message with its residual.
- ``marker_missing``: a dot with no marker (named); the angle is measured from the
  others and given, but the row is not ``ok``.
- ``ambiguous``: the markers fit the layout in several ways, or the index mark is
  not seen; ``layout_mismatch``: too few dots agree with the layout. The angle is
  withheld: never a wrong identity.
- ``suspect``: the axis jumped in this image with no rotation (``bump`` = 1), or the
  image is saturated or blurred (the rules of :func:`.shots.image_warnings`, the
  blur from the mean edge width of all its markers); the angle is given but not
  used by the analysis.
- ``failed`` (no markers, unreadable image, its reference failed) and ``pending``
  as for two markers.

When the reference image's own identity is not certain, every row of its
orientation gets the reference's status and reason.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from ..errors import MarkerError, TargetError
from ..images import grey_array_and_blocks
from ..markers import find_candidates, find_marker_list
from ..measurements import TARGET_RESULT_COLUMNS
from ..quality import SUSPECT
from ..settings import MeasureSettings

__all__ = ["FoundMarkers", "measure_target_markers", "valid_target_entry", "target_settings_key", "target_rows",
           "target_pair", "pair_dots", "TargetRow", "TARGET_MARKER_FIELDS"]

#: What is kept of each ``ok`` marker found (only those can be a dot).
TARGET_MARKER_FIELDS = ("x_px", "y_px", "radius_px", "x_std_px", "y_std_px", "xy_cov_px2", "edge_width_px",
                        "contrast_dn", "residual_rms_px")
#: What is kept of each candidate not fitted: enough to say why a dot has no marker.
_REJECTED_FIELDS = ("x_px", "y_px", "status", "message")


@dataclass(frozen=True)
class FoundMarkers:
    """The ``ok`` markers found in one image, as the cache keeps them.

    Attributes
    ----------
    columns : dict of str to tuple of float
        One tuple per field of :data:`TARGET_MARKER_FIELDS` (px; NaN kept as NaN),
        the markers in the order :func:`~vision_torsion.markers.find_marker_list`
        gives them (largest first).
    n_candidates : int
        Candidates looked at, ``ok`` or not.
    rejected : tuple of tuple
        (x_px, y_px, status, message) of every candidate not fitted (``border``,
        ``not_round``, ...): where a dot has no marker, the reason it was not fitted.
    """

    columns: dict
    n_candidates: int = 0
    rejected: tuple = ()

    def to_dict(self) -> dict:
        """JSON-safe dict (NaN written as None)."""
        clean = {k: [None if not math.isfinite(v) else v for v in vals] for k, vals in self.columns.items()}
        rejected = [[None if isinstance(v, float) and not math.isfinite(v) else v for v in r] for r in self.rejected]
        return {"markers": clean, "n_candidates": self.n_candidates, "rejected": rejected}

    @classmethod
    def from_dict(cls, d: dict) -> "FoundMarkers":
        """Rebuild from :meth:`to_dict` output.

        Raises
        ------
        KeyError, TypeError, ValueError
            `d` is not such a dict (a field missing, columns of unequal length).
        """
        cols = {k: tuple(math.nan if v is None else float(v) for v in d["markers"][k]) for k in TARGET_MARKER_FIELDS}
        if len({len(v) for v in cols.values()}) != 1:
            raise ValueError("marker columns of unequal length")
        rejected = tuple((math.nan if x is None else float(x), math.nan if y is None else float(y), str(st), str(msg))
                         for x, y, st, msg in d.get("rejected", ()))
        return cls(cols, int(d.get("n_candidates", 0)), rejected)

    def table(self, correction=None):
        """The markers as a :func:`~vision_torsion.markers.find_markers`-like table
        (the ``ok`` rows, then the candidates not fitted with their status and
        message), with the plane correction applied when given: centres and their
        covariances on the disk plane, radii scaled by the local scale √|det J| so
        the dots' sizes still compare with the layout's."""
        import pandas as pd

        frame = pd.DataFrame({k: np.asarray(v, dtype=np.float64) for k, v in self.columns.items()})
        frame["status"], frame["message"] = "ok", ""
        if self.rejected:
            frame = pd.concat([frame, pd.DataFrame(list(self.rejected), columns=list(_REJECTED_FIELDS))],
                              ignore_index=True)
        if correction is not None and len(frame):
            cov = np.zeros((len(frame), 2, 2))
            cov[:, 0, 0] = frame["x_std_px"] ** 2
            cov[:, 1, 1] = frame["y_std_px"] ** 2
            cov[:, 0, 1] = cov[:, 1, 0] = np.nan_to_num(frame["xy_cov_px2"].to_numpy())  # unknown: uncorrelated
            J, _, _ = correction.jacobian(frame["x_px"].to_numpy(), frame["y_px"].to_numpy())
            X, Y, C = correction.apply(frame["x_px"].to_numpy(), frame["y_px"].to_numpy(), cov)
            frame["x_px"], frame["y_px"] = X, Y
            frame["x_std_px"], frame["y_std_px"] = np.sqrt(C[:, 0, 0]), np.sqrt(C[:, 1, 1])
            frame["xy_cov_px2"] = C[:, 0, 1]
            frame["radius_px"] = frame["radius_px"] * np.sqrt(np.abs(np.linalg.det(J)))
        return frame


def measure_target_markers(image, *, settings: MeasureSettings | None = None, name: str | None = None,
                           candidates=None) -> FoundMarkers:
    """Find and fit every marker of one image of an N-marker target session.

    The measuring function of ``process`` (and ``watch``, ``bind``) for such a
    session, in place of :func:`~vision_torsion.pair.measure_pair`; the session's
    reading threads find the candidates (its ``find_candidates`` attribute says how).

    Parameters
    ----------
    image : GreyImage, array_like or path
        The image.
    settings : MeasureSettings, optional
        Polarity, radius range, fit.
    name : str, optional
        What to call the image in messages.
    candidates : list of Blob, optional
        :func:`~vision_torsion.markers.find_candidates` of the image, when found.

    Returns
    -------
    FoundMarkers

    Raises
    ------
    ImageReadError
        The image cannot be read.
    MarkerError
        No marker is found (reason ``no_markers``).
    """
    settings = settings or MeasureSettings()
    img, block_px = grey_array_and_blocks(image, keep_integers=True)
    found = find_marker_list(img, settings, candidates=candidates, block_px=block_px)
    ok = [m for m in found if m.status == "ok"]
    if not ok:
        raise MarkerError(f"{name or 'image'}: no marker found ({len(found)} candidate(s), none fitted)",
                          reason="no_markers")
    rejected = tuple((float(m.x_px), float(m.y_px), m.status, m.message) for m in found if m.status != "ok")
    return FoundMarkers({k: tuple(float(getattr(m, k)) for m in ok) for k in TARGET_MARKER_FIELDS}, len(found),
                        rejected)


#: What the session's reading threads find ahead of it (:func:`~.worker.prepare_task`):
#: every candidate, where :func:`~vision_torsion.pair.measure_pair` needs only the largest.
measure_target_markers.find_candidates = find_candidates


def valid_target_entry(entry: dict) -> bool:
    """The cache's schema check for a target session's entries: a failure carries
    its message, a result rebuilds as :class:`FoundMarkers`."""
    if entry.get("status") == "failed":
        return isinstance(entry.get("message"), str)
    try:
        FoundMarkers.from_dict(entry["pair"])
    except (KeyError, TypeError, ValueError, AttributeError):
        return False
    return True


def target_settings_key(settings_key: str, target) -> str:
    """The cache key's settings part for a target session: the two-marker key and the
    target's layout, so images measured for another target are not reused."""
    layout = {"name": target.name, "x_mm": list(target.x_mm), "y_mm": list(target.y_mm),
              "diameter_mm": list(target.diameter_mm), "index": list(target.index)}
    return json.dumps({"measure": settings_key, "target": layout}, sort_keys=True)


def pair_dots(target) -> tuple[int, int]:
    """The two dots ``watch`` and ``bind`` follow: the index dot (dot 0 when none) and
    the dot farthest from it."""
    first = target.index[0] if target.index else 0
    c = target.centres_mm
    return first, int(np.argmax(np.hypot(*(c - c[first]).T)))


def target_pair(found: FoundMarkers, target, *, name: str):
    """Two dots of an N-marker target as a marker pair, for ``watch`` and ``bind``.

    Their checks (the step from one image to the next, blur, a moved camera) work
    on a pair; the pair is :func:`pair_dots`, named from the whole layout
    (:func:`vision_torsion.rigid.identify_markers`), so their identity is as
    certain as the target's. The angles ``process`` writes rest on every dot.

    Returns
    -------
    (PairMeasurement or None, str)
        The pair and "", or None and why: the identity's reason (``ambiguous``,
        ``layout_mismatch``), or a dot of the pair with no marker.
    """
    from ..markers import Marker
    from ..pair import PairMeasurement
    from ..rigid import identify_markers

    table = found.table()
    ident = identify_markers(table, target, name=name)
    dots = pair_dots(target)
    if not ident.certain:
        return None, f"{ident.status}: {ident.message}"
    missing = [k for k in dots if ident.rows[k] < 0]
    if missing:
        return None, (f"marker_missing: {name}: no marker at dot(s) {', '.join(map(str, missing))} of the target "
                      f"{target.name!r}, which watch and bind follow")
    first, second = (Marker(**{f: float(table.loc[ident.rows[k], f]) for f in TARGET_MARKER_FIELDS}) for k in dots)
    return PairMeasurement(first, second, found.n_candidates), ""


@dataclass(frozen=True)
class TargetRow:
    """One row's results: angle (deg, ``angle_sign`` applied) and 1σ, status,
    message, and the values of :data:`~vision_torsion.measurements.TARGET_RESULT_COLUMNS`."""

    angle_deg: float
    angle_std_deg: float
    message: str
    status: str
    extra: dict

    @classmethod
    def blank(cls, message: str, status: str) -> "TargetRow":
        """A row with no angle."""
        return cls(math.nan, math.nan, message, status, dict.fromkeys(TARGET_RESULT_COLUMNS, math.nan))


def _jump_note(name, jump, sigma, kind) -> str:
    back = "and moved back in the next image" if kind == "spike" else "and stayed there"
    return (f"{name}: the shaft axis jumped by ({jump[0]:.3f}, {jump[1]:.3f}) px ({sigma:.0f}σ) with no rotation "
            f"{back}: a bumped camera or a loose fixture; the angle excludes the shift, but check the rig")


def _orientation_rows(session, idx, entries, correction, settings) -> dict:
    """Rows of one orientation: {row index: TargetRow}."""
    from ..rigid import axis_motion, target_angles
    from .shots import blur_warning, image_warnings

    rows = session.manifest.rows
    ref = next((i for i in idx if rows[i].phase == "reference"), idx[0])
    orientation = rows[ref].orientation_deg
    if entries[ref]["status"] == "pending":
        why = (f"waiting for the reference image {rows[ref].image} (line {rows[ref].line}) of orientation "
               f"{orientation:g}: no angle can be measured without it")
        return {i: TargetRow.blank(entries[i]["message"] if entries[i]["status"] == "pending" else why, "pending")
                for i in idx}
    out = {}
    for i in idx:
        if entries[i]["status"] == "pending":
            out[i] = TargetRow.blank(entries[i]["message"], "pending")
        elif entries[i]["status"] != "ok":
            out[i] = TargetRow.blank(entries[i].get("message", ""), "failed")
    if entries[ref]["status"] != "ok":
        why = (f"reference image {rows[ref].image} (line {rows[ref].line}) of orientation {orientation:g} "
               "failed, so no angle can be measured")
        return {i: out[i] if i in out and (out[i].status == "pending" or out[i].message)
                else TargetRow.blank(why, "failed") for i in idx}
    measured = [i for i in idx if entries[i]["status"] == "ok"]
    tables = {i: FoundMarkers.from_dict(entries[i]["pair"]).table(correction) for i in measured}
    try:
        results = target_angles(tables[ref], [tables[i] for i in measured], target=session.config.target,
                                settings=settings, bump_sigma=math.inf, names=[rows[i].image for i in measured])
    except TargetError as exc:  # the reference's own identity is not certain
        why = f"reference image {rows[ref].image} (line {rows[ref].line}): {str(exc).removeprefix('reference: ')}"
        out.update({i: TargetRow.blank(why, exc.reason) for i in measured})
        return out
    motion = axis_motion(results)
    widths = {i: float(np.nanmean(t["edge_width_px"])) if t["edge_width_px"].notna().any() else math.nan
              for i, t in tables.items()}
    jumps = dict(motion.jumps)
    sign = session.config.angle_sign
    for j, (i, res) in enumerate(zip(measured, results)):
        if not res.usable:
            out[i] = TargetRow.blank(res.message, res.status)
            continue
        notes = [res.message] if res.message else []
        status = res.status
        flags = image_warnings(None, None, entries[i].get("saturated_fraction", math.nan))
        if i != ref and (blur := blur_warning(widths[i], widths[ref])):
            flags.append(blur)
        bump = j in jumps
        if bump:
            notes.append(_jump_note(rows[i].image, motion.jump_px[j], motion.jump_sigma[j], jumps[j]))
        if bump or flags:
            status = SUSPECT
        extra = {"markers_used": res.n_used, "centre_shift_x_px": motion.shifts_px[j, 0],
                 "centre_shift_y_px": motion.shifts_px[j, 1], "centre_shift_x_std_px": motion.shift_std_px[j, 0],
                 "centre_shift_y_std_px": motion.shift_std_px[j, 1], "bump": int(bump)}
        out[i] = TargetRow(sign * res.angle_deg + 0.0, res.angle_std_deg, "; ".join(flags + notes), status, extra)
    return out


def target_rows(session, entries: list[dict], correction=None) -> list[TargetRow]:
    """Per manifest row of a target session, its :class:`TargetRow`.

    Parameters
    ----------
    session : Session
        A loaded session whose ``config.target`` is set.
    entries : list of dict
        Per row, its cache entry (``status`` ok with ``pair`` a
        :meth:`FoundMarkers.to_dict`, failed with ``message``, or pending).
    correction : PlaneCorrection, optional
        Applied to the centres before the rigid fits.

    Returns
    -------
    list of TargetRow
        In manifest order; the statuses and reasons of the module docstring.
    """
    rows = session.manifest.rows
    groups: dict[float, list[int]] = defaultdict(list)
    for i, row in enumerate(rows):
        groups[row.orientation_deg].append(i)
    out: dict[int, TargetRow] = {}
    for idx in groups.values():
        out.update(_orientation_rows(session, idx, entries, correction, session.settings))
    return [out[i] for i in range(len(rows))]
