"""The angle of an image from all the markers of an N-marker target.

Three steps, each a public function:

1. :func:`identify_markers` names the found markers after the target's dots
   (:mod:`vision_torsion.targets`): a similarity (scale, turn, shift) from the
   printed layout to the image is hypothesised from every pair of found markers near
   a few seeds and every pair of dots, and scored by how many dots then fall on a
   found marker of the right size. The identity is taken only when exactly one
   assignment scores best and the index mark is seen; otherwise the image is
   ``ambiguous``. Dots with no marker are named (``marker_missing``); too few dots
   agreeing with the layout is ``layout_mismatch``.
2. :func:`fit_rigid` fits the current centres to the reference centres by a
   weighted 2-D rigid motion (turn θ about the reference's shaft axis, then a shift
   t of that axis), errors in both images::

       q_i = o + R(θ)(p_i − o) + t,   C_i = C_q,i + R C_p,i Rᵀ,
       minimise Σ e_iᵀ C_i⁻¹ e_i,  e_i = q_i − o − R(θ)(p_i − o) − t

   by Gauss-Newton from the unweighted (Kabsch) solution; the covariance of
   (θ, t) is the inverse of the Gauss-Newton normal matrix (first order in the
   centres' covariances, which :func:`~vision_torsion.markers.find_markers`
   reports). Coordinates are taken about the reference axis o, so the normal matrix
   stays well conditioned at large pixel coordinates. A marker whose normalised
   residual √(e_iᵀC_i⁻¹e_i) exceeds `reject_sigma` (times the robust spread of the
   others, when that is above 1) is dropped with its reason, the worst first,
   while three or more remain.
3. The shift t is the motion of the shaft axis: a pure rotation about the axis has
   t = 0; a camera bump or a loose fixture moves the axis without turning the
   target, and is reported as ``bump`` (in a single image), never as a rotation.
   The axis o is the layout's origin mapped into the reference image, so this
   assumes the target centred on the shaft; an eccentricity e shows up as an
   apparent shift of about θ·e, which :func:`rotation_centre` measures from a
   sequence.

Image coordinates are (x, y) px, origin at the centre of the top-left pixel, y down;
angles in degrees, counter-clockwise as displayed.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from .errors import MarkerError, TargetError
from .settings import MeasureSettings

__all__ = [
    "Identification",
    "RigidFit",
    "MarkerResidual",
    "TargetAngle",
    "RotationCentre",
    "AxisMotion",
    "identify_markers",
    "fit_rigid",
    "target_angle",
    "target_angles",
    "rotation_centre",
    "axis_motion",
    "measure_target_folder",
    "IDENTITY_STATUSES",
    "TARGET_COLUMNS",
]

#: Per-image statuses of the identity: ``ok``, a dot with no marker
#: (``marker_missing``, the dots named), more than one assignment fitting equally
#: well or the index mark unseen (``ambiguous``), too few dots agreeing with the
#: layout (``layout_mismatch``).
IDENTITY_STATUSES = ("ok", "marker_missing", "ambiguous", "layout_mismatch")

#: Fraction of the smallest dot spacing within which a found marker sits on a dot.
POSITION_TOLERANCE = 0.25
#: Relative radius difference within which a found marker has the dot's size.
RADIUS_TOLERANCE = 0.06
#: Found markers tried as seeds of the layout hypotheses, and neighbours of each.
_SEEDS, _PARTNERS = 12, 3


@dataclass(frozen=True)
class Identification:
    """Which found marker is which dot of the target.

    Attributes
    ----------
    status : str
        One of :data:`IDENTITY_STATUSES`.
    message : str
        Why, when not ``ok`` (the dots named by their index).
    rows : tuple of int
        For each dot of the target, its row in the marker table, or -1.
    scale_px_per_mm : float
        Image scale of the layout (px per mm); NaN when no identity.
    turn_deg : float
        Turn of the layout in the image (deg, counter-clockwise as displayed).
    axis_x_px, axis_y_px : float
        The layout's origin (the shaft axis) in the image (px).
    missing : tuple of int
        Dots with no marker.
    mismatched : tuple of int
        Dots where a marker of the wrong size sits (dirt, a bolt head).
    """

    status: str
    message: str = ""
    rows: tuple = ()
    scale_px_per_mm: float = math.nan
    turn_deg: float = math.nan
    axis_x_px: float = math.nan
    axis_y_px: float = math.nan
    missing: tuple = ()
    mismatched: tuple = ()

    @property
    def certain(self) -> bool:
        """True when the identity can be used: ``ok``, or ``marker_missing`` with at
        least two dots named."""
        return self.status in ("ok", "marker_missing") and sum(r >= 0 for r in self.rows) >= 2


def _rot(theta):
    """Turn by `theta` (rad) counter-clockwise as displayed, in (x, y) with y down."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, s], [-s, c]])


def _fail_identity(status, message, n):
    return Identification(status=status, message=message, rows=(-1,) * n, missing=tuple(range(n)))


def _hypotheses(P, rd, target, radius_tolerance) -> dict:
    """Every assignment of markers to dots that a pair of found markers and a pair of
    dots of the right sizes imply (:func:`identify_markers`' Notes): assignment (a
    marker index or -1 per dot) -> (its score, the dots that agree)."""
    n_dots = target.n_markers
    L, rl = target.centres_mm, target.radii_mm
    # seeds spread from the middle of what was found outwards (distractors such as bolt
    # holes often sit together), each with its nearest neighbours
    med = np.median(P, axis=0)
    by_distance = np.argsort(np.hypot(*(P - med).T))
    seeds = by_distance[np.unique(np.linspace(0, len(P) - 1, min(_SEEDS, len(P))).round().astype(int))]
    dpp = np.hypot(*(P[:, None, :] - P[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(dpp, np.inf)
    ii, jj = np.nonzero(~np.eye(n_dots, dtype=bool))
    vl = L[jj] - L[ii]
    len_l = np.hypot(vl[:, 0], vl[:, 1])
    ang_l = np.arctan2(vl[:, 1], vl[:, 0])
    best = {}  # assignment (a marker index or -1 per dot) -> (score, the dots that agree)
    reach = POSITION_TOLERANCE * target.min_spacing_mm  # a property that compares every pair of dots: once
    for a in seeds:
        for b in np.argsort(dpp[a])[: min(_PARTNERS, len(P) - 1)]:
            vp = P[b] - P[a]
            s = math.hypot(*vp) / len_l
            keep = (np.abs(rd[a] - s * rl[ii]) <= radius_tolerance * s * rl[ii]) & (
                np.abs(rd[b] - s * rl[jj]) <= radius_tolerance * s * rl[jj])
            if not np.any(keep):
                continue
            sk, phi = s[keep], math.atan2(vp[1], vp[0]) - ang_l[keep]
            c, sn = np.cos(phi), np.sin(phi)
            d = L[None, :, :] - L[ii[keep]][:, None, :]
            mapped = P[a] + sk[:, None, None] * np.stack(
                [c[:, None] * d[..., 0] - sn[:, None] * d[..., 1], sn[:, None] * d[..., 0] + c[:, None] * d[..., 1]],
                axis=-1)
            dist = np.hypot(*(mapped[:, :, None, :] - P[None, None, :, :]).transpose(3, 0, 1, 2))
            near = dist.argmin(axis=2)
            near_d = np.take_along_axis(dist, near[..., None], axis=2)[..., 0]
            matched = near_d <= reach * sk[:, None]
            agrees = matched & (np.abs(rd[near] - sk[:, None] * rl) <= radius_tolerance * sk[:, None] * rl)
            score = agrees.sum(axis=1)
            for h in np.flatnonzero(score == score.max()):
                key = tuple(int(near[h, k]) if matched[h, k] else -1 for k in range(n_dots))
                if key not in best:
                    best[key] = (int(score[h]), tuple(int(k) for k in np.flatnonzero(agrees[h])))
    return best


def identify_markers(markers, target, *, name: str = "image",
                     radius_tolerance: float = RADIUS_TOLERANCE) -> Identification:
    """Name the found markers after the dots of `target`.

    Parameters
    ----------
    markers : pandas.DataFrame
        A :func:`~vision_torsion.markers.find_markers` table; rows whose status is
        not ``ok`` are ignored, as are markers that sit on no dot (bolt holes).
    target : Target
        The printed layout (:mod:`vision_torsion.targets`).
    name : str
        Name of the image, for the messages.
    radius_tolerance : float
        Relative difference of radius within which a marker has a dot's size.

    Returns
    -------
    Identification
        Never a guess: an identity that is not certain is ``ambiguous``.

    Notes
    -----
    Hypotheses: for up to 12 seed markers (spread evenly in distance from the
    markers' median centre, nearest to farthest) and each of their 3 nearest
    neighbours, every ordered pair of dots of the right sizes fixes a similarity;
    all dots are mapped with it, and a dot is *matched* when a marker lies within
    0.25 of the smallest dot spacing of it and *agrees* when that marker's radius is
    also within `radius_tolerance` of the dot's. The score is
    the number of dots that agree. The best assignment is taken when no other
    assignment of equal score names any dot differently, and every index dot
    agrees; a target that maps onto itself under a turn therefore always comes out
    ``ambiguous``. Fewer than max(2, half the dots) agreeing is ``layout_mismatch``.
    """
    n_dots = target.n_markers
    ok = markers[markers["status"] == "ok"]
    P = ok[["x_px", "y_px"]].to_numpy(dtype=np.float64)
    rd = ok["radius_px"].to_numpy(dtype=np.float64)
    rows_of = ok.index.to_numpy()
    if len(P) < 2:
        return _fail_identity("marker_missing", f"{name}: {len(P)} marker(s) found, the target "
                              f"{target.name!r} has {n_dots}; all dots missing", n_dots)
    L = target.centres_mm
    best = _hypotheses(P, rd, target, radius_tolerance)
    if not best:
        return _fail_identity("layout_mismatch", f"{name}: no two markers have the sizes and spacing of "
                              f"two dots of the target {target.name!r}", n_dots)
    top = max(v[0] for v in best.values())
    cands = [k for k, v in best.items() if v[0] == top]
    need = max(2, math.ceil(n_dots / 2))
    if top < need:
        return _fail_identity("layout_mismatch", f"{name}: at most {top} of the {n_dots} dots of the target "
                              f"{target.name!r} agree with the markers found (need {need})", n_dots)
    chosen = cands[0]
    for other in cands[1:]:
        # the same identity found from other seeds agrees on every dot both name
        if any(x != y and x >= 0 and y >= 0 for x, y in zip(chosen, other)):
            turns = sorted({_assignment_turn(P, L, k) for k in (chosen, other)})
            return _fail_identity("ambiguous", f"{name}: the markers fit the target {target.name!r} equally "
                                  f"well in {len(cands)} ways (the layout turned by "
                                  f"{' or '.join(f'{t:.1f}°' for t in turns)}, ...); give the target an index mark",
                                  n_dots)
    agreeing = set(best[chosen][1])
    unseen = [k for k in target.index if k not in agreeing]
    if unseen:
        return _fail_identity("ambiguous", f"{name}: the index mark (dot {', '.join(map(str, unseen))}) of the "
                              f"target {target.name!r} is not seen: which dot is which is not certain", n_dots)
    use = [k for k in range(n_dots) if k in agreeing]
    scale, turn, shift = _similarity(L[use], P[[chosen[k] for k in use]])
    axis = shift  # the layout origin maps to the shift
    mismatched = tuple(k for k in range(n_dots) if chosen[k] >= 0 and k not in agreeing)
    missing = tuple(k for k in range(n_dots) if chosen[k] < 0)
    rows = tuple(int(rows_of[chosen[k]]) if k in agreeing else -1 for k in range(n_dots))
    status, message = "ok", ""
    if missing or mismatched:
        status = "marker_missing"
        parts = []
        if missing:
            parts.append(f"no marker at dot(s) {', '.join(map(str, missing))}")
        if mismatched:
            parts.append(f"a marker of the wrong size at dot(s) {', '.join(map(str, mismatched))}")
        message = f"{name}: {'; '.join(parts)} of the target {target.name!r}"
        why = _unfitted_at(markers, L[list(missing)], missing, scale, turn, shift,
                           POSITION_TOLERANCE * target.min_spacing_mm)
        message += f" ({'; '.join(why)})" if why else ""
    return Identification(status=status, message=message, rows=rows, scale_px_per_mm=scale,
                          turn_deg=-math.degrees(turn), axis_x_px=float(axis[0]), axis_y_px=float(axis[1]),
                          missing=tuple(sorted(set(missing) | set(mismatched))), mismatched=mismatched)


def _unfitted_at(markers, dots_mm, dots, scale, phi, shift, reach_mm) -> list:
    """Why a candidate that was not fitted sits where each of `dots` should be: "dot k:
    a candidate there was not fitted (STATUS: MESSAGE)", for the dots that have one
    (the layout mapped by the similarity (`scale`, `phi`, `shift`) of the others)."""
    bad = markers[markers["status"] != "ok"]
    if not len(bad) or not len(dots):
        return []
    c, s = math.cos(phi), math.sin(phi)
    at = scale * np.column_stack([c * dots_mm[:, 0] - s * dots_mm[:, 1], s * dots_mm[:, 0] + c * dots_mm[:, 1]]) + shift
    xy = bad[["x_px", "y_px"]].to_numpy(dtype=np.float64)
    out = []
    for k, (x, y) in zip(dots, at):
        d = np.hypot(xy[:, 0] - x, xy[:, 1] - y)
        j = int(np.argmin(d))
        if d[j] <= reach_mm * scale:
            m = bad.iloc[j]
            detail = f"{m['status']}: {m['message']}" if "message" in bad.columns and m["message"] else m["status"]
            out.append(f"dot {k}: a candidate there was not fitted ({detail})")
    return out


def _similarity(src, dst):
    """Least-squares similarity dst ≈ s·R(φ)·src + t (Umeyama); R in (x, y) array axes."""
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - ms, dst - md
    phi = math.atan2(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]), np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]))
    c, s = math.cos(phi), math.sin(phi)
    ra = np.column_stack([c * a[:, 0] - s * a[:, 1], s * a[:, 0] + c * a[:, 1]])
    scale = float(np.sum(ra * b) / np.sum(a * a))
    rm = np.array([c * ms[0] - s * ms[1], s * ms[0] + c * ms[1]])
    return scale, phi, md - scale * rm


def _assignment_turn(P, L, key):
    use = [k for k, r in enumerate(key) if r >= 0]
    return round(-math.degrees(_similarity(L[use], P[[key[k] for k in use]])[1]) % 360.0, 1)


@dataclass(frozen=True)
class MarkerResidual:
    """One dot's part in a rigid fit.

    Attributes
    ----------
    dot : int
        The dot's index in the target.
    used : bool
        Whether the fit used it.
    residual_x_px, residual_y_px : float
        Current centre minus its fitted position (px); NaN when not measured.
    normalised : float
        √(eᵀC⁻¹e): the residual in units of its standard deviation.
    reason : str
        Why it was not used (empty when used).
    """

    dot: int
    used: bool
    residual_x_px: float = math.nan
    residual_y_px: float = math.nan
    normalised: float = math.nan
    reason: str = ""


@dataclass(frozen=True)
class RigidFit:
    """A weighted rigid motion of the centres from the reference to the current image.

    Attributes
    ----------
    angle_deg, angle_std_deg : float
        Turn θ (deg, counter-clockwise as displayed) and its 1σ.
    shift_x_px, shift_y_px : float
        Motion t of the reference axis (px).
    cov : numpy.ndarray
        3x3 covariance of (θ [rad], t_x [px], t_y [px]).
    chi2 : float
        Σ e_iᵀC_i⁻¹e_i of the markers used.
    dof : int
        2·(markers used) − 3.
    residuals : tuple of MarkerResidual
        Every marker given, used or dropped.
    """

    angle_deg: float
    angle_std_deg: float
    shift_x_px: float
    shift_y_px: float
    cov: np.ndarray = field(repr=False)
    chi2: float
    dof: int
    residuals: tuple = ()

    @property
    def chi2_red(self) -> float:
        """χ²/dof (NaN with no degrees of freedom)."""
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def shift_cov(self) -> np.ndarray:
        """2x2 covariance of the axis shift (px²)."""
        return self.cov[1:, 1:]


def _gauss_newton(p, cp, q, cq, origin, theta):
    t = np.zeros(2)
    a = p - origin
    for _ in range(8):
        R = _rot(theta)
        dR = np.array([[-math.sin(theta), math.cos(theta)], [-math.cos(theta), -math.sin(theta)]])
        C = cq + R @ cp @ R.T
        W = np.linalg.inv(C)
        e = q - origin - a @ R.T - t
        J = np.zeros((len(p), 2, 3))
        J[:, :, 0] = a @ dR.T
        J[:, 0, 1] = J[:, 1, 2] = 1.0
        N = np.einsum("nki,nkl,nlj->ij", J, W, J)
        g = np.einsum("nki,nkl,nl->i", J, W, e)
        step = np.linalg.solve(N, g)
        theta, t = theta + step[0], t + step[1:]
        if abs(step[0]) < 1e-13 and np.all(np.abs(step[1:]) < 1e-10):
            break
    R = _rot(theta)
    C = cq + R @ cp @ R.T
    W = np.linalg.inv(C)
    e = q - origin - a @ R.T - t
    d2 = np.einsum("nk,nkl,nl->n", e, W, e)
    return theta, t, np.linalg.inv(N), e, d2


def fit_rigid(reference_xy, reference_cov, current_xy, current_cov, *, origin=None,
              reject_sigma: float = 5.0, dots=None) -> RigidFit:
    """Weighted rigid motion of marker centres from a reference image to the current one.

    Parameters
    ----------
    reference_xy, current_xy : array_like
        (n, 2) centres (px), row k of both the same marker; NaN rows are left out.
    reference_cov, current_cov : array_like
        (n, 2, 2) covariances of the centres (px²).
    origin : array_like, optional
        The point (px, reference image) the turn is taken about, the shaft axis;
        the centres' mean by default. The shift is that point's motion.
    reject_sigma : float
        A marker is dropped when its normalised residual exceeds this (times the
        robust spread of all of them when that exceeds 1), the worst first, while
        three or more remain.
    dots : sequence of int, optional
        The dots' indices for the residual table (0..n-1 by default).

    Returns
    -------
    RigidFit

    Raises
    ------
    TargetError
        Fewer than two markers measured in both images (reason
        ``too_few_markers``), or shapes that do not agree (``bad_value``).

    Examples
    --------
    >>> import numpy as np
    >>> p = np.array([[100.0, 0.0], [0.0, 100.0], [-100.0, 0.0], [0.0, -100.0]])
    >>> a = np.radians(10.0)
    >>> q = p @ np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    >>> cov = np.tile(np.eye(2) * 1e-4, (4, 1, 1))
    >>> f = fit_rigid(p, cov, q, cov, origin=(0.0, 0.0))
    >>> round(f.angle_deg, 9), round(f.shift_x_px, 9) + 0.0, round(f.angle_std_deg, 5)
    (10.0, 0.0, 0.00405)
    """
    p, q = np.asarray(reference_xy, dtype=np.float64), np.asarray(current_xy, dtype=np.float64)
    cp, cq = np.asarray(reference_cov, dtype=np.float64), np.asarray(current_cov, dtype=np.float64)
    n = len(p)
    if p.shape != (n, 2) or q.shape != (n, 2) or cp.shape != (n, 2, 2) or cq.shape != (n, 2, 2):
        raise TargetError(f"fit_rigid: centres must be (n, 2) and covariances (n, 2, 2) for the same n, got "
                          f"{p.shape}, {q.shape}, {cp.shape}, {cq.shape}", reason="bad_value")
    dots = tuple(range(n)) if dots is None else tuple(dots)
    finite = np.all(np.isfinite(p), axis=1) & np.all(np.isfinite(q), axis=1) & \
        np.all(np.isfinite(cp), axis=(1, 2)) & np.all(np.isfinite(cq), axis=(1, 2))
    use = list(np.flatnonzero(finite))
    reasons = {k: "not measured in both images" for k in range(n) if not finite[k]}
    if len(use) < 2:
        raise TargetError(f"fit_rigid: {len(use)} marker(s) measured in both images; a rigid fit needs 2",
                          reason="too_few_markers")
    origin = p[use].mean(axis=0) if origin is None else np.asarray(origin, dtype=np.float64)
    while True:
        pu, qu = p[use], q[use]
        theta0 = -_similarity(pu, qu)[1]  # the unweighted turn (Kabsch) starts Gauss-Newton
        theta, t, cov, e, d2 = _gauss_newton(pu, cp[use], qu, cq[use], origin, theta0)
        if len(use) < 3:
            break
        d = np.sqrt(d2)
        spread = math.sqrt(float(np.median(d2)) / (2.0 * math.log(2.0)))  # median of χ²₂ is 2 ln 2
        worst = int(np.argmax(d))
        if d[worst] <= reject_sigma * max(1.0, spread):
            break
        k = use.pop(worst)
        reasons[k] = (f"disagrees with the other {len(use)} markers by {d[worst]:.1f}σ "
                      f"({math.hypot(*e[worst]):.3g} px): occluded, dirty or moved on the disk")
    R = _rot(theta)
    full_e = q - origin - (p - origin) @ R.T - t
    full_c = cq + np.einsum("ij,njk,lk->nil", R, cp, R)
    res = []
    for k in range(n):
        if finite[k]:
            ek = full_e[k]
            dk = float(math.sqrt(ek @ np.linalg.solve(full_c[k], ek)))
            res.append(MarkerResidual(dots[k], k in use, float(ek[0]), float(ek[1]), dk, reasons.get(k, "")))
        else:
            res.append(MarkerResidual(dots[k], False, reason=reasons[k]))
    return RigidFit(angle_deg=math.degrees(theta), angle_std_deg=math.degrees(math.sqrt(cov[0, 0])),
                    shift_x_px=float(t[0]), shift_y_px=float(t[1]), cov=cov, chi2=float(np.sum(d2)),
                    dof=2 * len(use) - 3, residuals=tuple(res))


@dataclass(frozen=True)
class TargetAngle:
    """The rotation of one image against the reference, from every marker of the target.

    Attributes
    ----------
    angle_deg, angle_std_deg : float
        Turn (deg, counter-clockwise as displayed) and its 1σ; NaN when the identity
        is not certain. The 1σ is inflated by √(χ²/dof) when the fit's lack of fit is
        significant (p < 0.001), and the message says so.
    status : str
        The current image's identity status (:data:`IDENTITY_STATUSES`).
    message : str
        Why, when not ``ok``; the bump, the inflated σ, the dropped markers.
    shift_x_px, shift_y_px : float
        Motion of the shaft axis since the reference (px).
    shift_cov : numpy.ndarray
        Its 2x2 covariance (px²).
    bump : bool
        The axis moved significantly (beyond `bump_sigma` and `bump_px`): a camera
        bump or a loose fixture, which the angle does not contain.
    chi2_red : float
        χ²/dof of the rigid fit.
    n_used : int
        Markers the angle rests on.
    residuals : tuple of MarkerResidual
        Per dot: used or dropped (with the reason), its normalised residual.
    """

    angle_deg: float
    angle_std_deg: float
    status: str = "ok"
    message: str = ""
    shift_x_px: float = math.nan
    shift_y_px: float = math.nan
    shift_cov: np.ndarray = field(default_factory=lambda: np.full((2, 2), np.nan), repr=False)
    bump: bool = False
    chi2_red: float = math.nan
    n_used: int = 0
    residuals: tuple = ()

    @property
    def usable(self) -> bool:
        """True when the angle is a measurement (identity certain, angle fitted)."""
        return self.status in ("ok", "marker_missing") and math.isfinite(self.angle_deg)


def _table(obj, settings, name):
    from .markers import find_markers, is_frame

    if is_frame(obj):
        return obj
    try:
        return find_markers(obj, settings=settings)
    except MarkerError as exc:
        raise type(exc)(f"{name}: {exc}", reason=exc.reason) from exc


def _centres(table, ident):
    """(n, 2) centres and (n, 2, 2) covariances (px, px²) of the target's dots, NaN for a dot with no marker."""
    rows = np.asarray(ident.rows, dtype=np.int64)
    have = rows >= 0
    m = table.loc[rows[have], ["x_px", "y_px", "x_std_px", "y_std_px", "xy_cov_px2"]].to_numpy(dtype=np.float64)
    xy = np.full((len(rows), 2), np.nan)
    cov = np.full((len(rows), 2, 2), np.nan)
    xy[have] = m[:, :2]
    cov[have, 0, 0], cov[have, 1, 1] = m[:, 2] ** 2, m[:, 3] ** 2
    cov[have, 0, 1] = cov[have, 1, 0] = m[:, 4]
    return xy, cov


def _reference(reference, target, settings):
    from .targets import load_target

    target = target if hasattr(target, "centres_mm") else load_target(target)
    table = _table(reference, settings, "reference")
    ident = identify_markers(table, target, name="reference")
    if not ident.certain:
        raise TargetError(ident.message, reason=ident.status)
    return target, table, ident


def _measure(ref_xy, ref_cov, origin, current, target, settings, name, reject_sigma, bump_sigma, bump_px):
    from scipy.stats import chi2 as chi2_dist

    table = _table(current, settings, name)
    ident = identify_markers(table, target, name=name)
    if not ident.certain:
        return TargetAngle(math.nan, math.nan, status=ident.status, message=ident.message)
    xy, cov = _centres(table, ident)
    try:
        fit = fit_rigid(ref_xy, ref_cov, xy, cov, origin=origin, reject_sigma=reject_sigma)
    except TargetError as exc:
        return TargetAngle(math.nan, math.nan, status="marker_missing", message=f"{name}: {exc}")
    notes = [ident.message] if ident.message else []
    std = fit.angle_std_deg
    if fit.dof > 0 and fit.chi2 > chi2_dist.ppf(0.999, fit.dof):
        std *= math.sqrt(fit.chi2_red)
        notes.append(f"{name}: lack of fit χ²/dof = {fit.chi2_red:.2f}; angle σ inflated by its square root")
    dropped = [r for r in fit.residuals if not r.used and r.reason != "not measured in both images"]
    notes += [f"{name}: dot {r.dot} dropped: {r.reason}" for r in dropped]
    shift = np.array([fit.shift_x_px, fit.shift_y_px])
    try:
        m2 = float(shift @ np.linalg.solve(fit.shift_cov, shift))
    except np.linalg.LinAlgError:
        m2 = math.inf
    bump = bool(m2 > bump_sigma**2 and math.hypot(*shift) > bump_px)
    if bump:
        notes.append(f"{name}: the shaft axis moved by ({shift[0]:.3f}, {shift[1]:.3f}) px "
                     f"({math.sqrt(m2):.0f}σ): a camera bump or a loose fixture, not a rotation")
    return TargetAngle(fit.angle_deg, std, status=ident.status, message="; ".join(notes),
                       shift_x_px=float(shift[0]), shift_y_px=float(shift[1]), shift_cov=fit.shift_cov,
                       bump=bump, chi2_red=fit.chi2_red, n_used=sum(r.used for r in fit.residuals),
                       residuals=fit.residuals)


def target_angle(reference, current, *, target, settings: MeasureSettings | None = None,
                 reject_sigma: float = 5.0, bump_sigma: float = 5.0, bump_px: float = 0.25) -> TargetAngle:
    """Rotation of the disk between two images, from every marker of an N-marker target.

    Parameters
    ----------
    reference, current : path, GreyImage, array_like or marker table
        Images (markers found with `settings`) or
        :func:`~vision_torsion.markers.find_markers` tables.
    target : Target, str or os.PathLike
        The printed target, a target file or a ready target's name
        (:func:`~vision_torsion.targets.load_target`).
    settings : MeasureSettings, optional
        How markers are found (polarity, radius range, fit).
    reject_sigma : float
        Normalised residual beyond which a marker is dropped (see :func:`fit_rigid`).
    bump_sigma, bump_px : float
        The axis shift is a ``bump`` when it exceeds both `bump_sigma` standard
        deviations and `bump_px` pixels (the floor keeps a target mounted slightly
        off the shaft, whose centre swings by about θ times the offset, from being
        called bumped).

    Returns
    -------
    TargetAngle
        With the current image's status: ``ambiguous``, ``layout_mismatch``
        (angle NaN), ``marker_missing`` (the angle from the other markers) or ``ok``.

    Raises
    ------
    TargetError
        The reference image's identity is not certain (reason ``ambiguous``,
        ``layout_mismatch``), or the target cannot be read.
    ImageReadError, MarkerError
        An image cannot be read, or no marker found at all.

    Examples
    --------
    >>> from vision_torsion.synthetic import render, target_scene
    >>> scene = target_scene("ring16", px_per_mm=7.5)
    >>> res = target_angle(render(scene, 0.0, seed=1).image, render(scene, 40.0, seed=2).image,
    ...                    target="ring16")
    >>> res.status, bool(abs(res.angle_deg - 40.0) < 0.002), res.bump, res.n_used
    ('ok', True, False, 16)
    """
    settings = settings or MeasureSettings()
    target, table, ident = _reference(reference, target, settings)
    ref_xy, ref_cov = _centres(table, ident)
    return _measure(ref_xy, ref_cov, (ident.axis_x_px, ident.axis_y_px), current, target, settings, "current",
                    reject_sigma, bump_sigma, bump_px)


def target_angles(reference, images, *, target, settings: MeasureSettings | None = None,
                  reject_sigma: float = 5.0, bump_sigma: float = 5.0, bump_px: float = 0.25,
                  names=None) -> list:
    """:func:`target_angle` for each of `images` against one reference, angles unwrapped.

    The identity comes from the layout in every image, so the angles need no
    tracking; they are unwrapped (continuous across ±180°) over the usable ones, in
    the order given. Parameters, Raises as :func:`target_angle`; an image that
    cannot be read raises. `names` (one per image) name the images in the messages
    (``image 0``, ``image 1``, ... by default).

    Returns
    -------
    list of TargetAngle
    """
    settings = settings or MeasureSettings()
    target, table, ident = _reference(reference, target, settings)
    ref_xy, ref_cov = _centres(table, ident)
    origin = (ident.axis_x_px, ident.axis_y_px)
    out, last = [], 0.0
    for k, img in enumerate(images):
        res = _measure(ref_xy, ref_cov, origin, img, target, settings, f"image {k}" if names is None else names[k],
                       reject_sigma, bump_sigma, bump_px)
        if res.usable:
            a = last + ((res.angle_deg - last + 180.0) % 360.0 - 180.0)
            res = dataclasses.replace(res, angle_deg=a)
            last = a
        out.append(res)
    return out


@dataclass(frozen=True)
class RotationCentre:
    """The shaft axis fitted from a sequence: where the target really turns about.

    Attributes
    ----------
    offset_x_px, offset_y_px : float
        The axis minus the target's centre in the reference image (px): the target's
        eccentricity on the shaft.
    cov : numpy.ndarray
        Its 2x2 covariance (px²).
    shifts_px : numpy.ndarray
        (n, 2) motion of the fitted axis in each image (px), NaN where not usable:
        what a bump or a loose fixture leaves once the eccentricity is accounted for.
    n_used : int
        Images the fit used.
    """

    offset_x_px: float
    offset_y_px: float
    cov: np.ndarray = field(repr=False)
    shifts_px: np.ndarray = field(repr=False)
    n_used: int


def rotation_centre(results, *, min_turn_deg: float = 1.0) -> RotationCentre:
    """The shaft axis from a sequence of :class:`TargetAngle`: weighted least squares of
    t_k = (I − R(θ_k))·a over the usable images turned by at least `min_turn_deg`.

    A target centred on the shaft gives a ≈ 0; an offset a makes every image's axis
    shift swing by (I − R(θ))·a, which the returned per-image shifts have removed.

    Raises
    ------
    TargetError
        Fewer than one usable image turned by `min_turn_deg` (reason
        ``too_few_turns``).
    """
    N, g, used = np.zeros((2, 2)), np.zeros(2), 0
    for r in results:
        if not r.usable or abs(r.angle_deg) < min_turn_deg:
            continue
        A = np.eye(2) - _rot(math.radians(r.angle_deg))
        W = np.linalg.inv(r.shift_cov)
        N += A.T @ W @ A
        g += A.T @ W @ np.array([r.shift_x_px, r.shift_y_px])
        used += 1
    if used < 1:
        raise TargetError(f"rotation_centre: no usable image turned by {min_turn_deg:g}° or more; the axis "
                          "cannot be told from the target's centre", reason="too_few_turns")
    cov = np.linalg.inv(N)
    a = cov @ g
    shifts = np.full((len(results), 2), np.nan)
    for k, r in enumerate(results):
        if r.usable:
            shifts[k] = np.array([r.shift_x_px, r.shift_y_px]) - (np.eye(2) - _rot(math.radians(r.angle_deg))) @ a
    return RotationCentre(float(a[0]), float(a[1]), cov, shifts, used)


@dataclass(frozen=True)
class AxisMotion:
    """How the shaft axis moved along a sequence, and where it jumped (:func:`axis_motion`).

    Attributes
    ----------
    offset_x_px, offset_y_px : float
        The target's eccentricity a (the axis minus the target's centre, px); 0 when
        the sequence turns too little to fit it.
    shifts_px : numpy.ndarray
        (n, 2) motion of the axis since the reference, eccentricity removed (px);
        NaN where the image is not usable.
    shift_std_px : numpy.ndarray
        (n, 2) its 1σ (px), the eccentricity's uncertainty included.
    jumps : tuple of (int, str)
        (image index, ``"spike"`` or ``"step"``) of every jump found: the axis moved
        in that image alone and came back (a spike), or moved and stayed (a step).
    jump_px : numpy.ndarray
        (n, 2) the fitted jump at each jump's image (px); NaN elsewhere.
    jump_sigma : numpy.ndarray
        (n,) its significance, √Δχ² of adding it (NaN elsewhere).
    """

    offset_x_px: float
    offset_y_px: float
    shifts_px: np.ndarray = field(repr=False)
    shift_std_px: np.ndarray = field(repr=False)
    jumps: tuple
    jump_px: np.ndarray = field(repr=False)
    jump_sigma: np.ndarray = field(repr=False)


def _axis_design(thetas, eccentric, jumps):
    """(2n, p) design of the axis shifts: the eccentricity's (I − R(θ_j)) columns,
    then a pair of columns per jump (image `k` alone for a spike, from `k` on for a step)."""
    n = len(thetas)
    cols = []
    if eccentric:
        A = np.stack([np.eye(2) - _rot(t) for t in thetas])  # (n, 2, 2)
        cols.append(A.reshape(2 * n, 2))
    for k, kind in jumps:
        on = (np.arange(n) == k) if kind == "spike" else (np.arange(n) >= k)
        cols.append(np.kron(on[:, None].astype(float), np.eye(2)))
    return np.hstack(cols) if cols else np.zeros((2 * n, 0))


def _axis_fit(thetas, white, y, eccentric, jumps):
    """Weighted least squares of the axis shifts: (coefficients, χ², unscaled covariance)."""
    X = np.einsum("nij,njk->nik", white, _axis_design(thetas, eccentric, jumps).reshape(len(thetas), 2, -1))
    X = X.reshape(2 * len(thetas), -1)
    if X.shape[1] == 0:
        return np.zeros(0), float(y @ y), np.zeros((0, 0))
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ beta
    return beta, float(r @ r), np.linalg.pinv(X.T @ X)


def axis_motion(results, *, bump_sigma: float = 5.0, bump_px: float = 0.25, min_turn_deg: float = 1.0,
                max_jumps: int = 3) -> AxisMotion:
    """Where the shaft axis jumped along a sequence of :class:`TargetAngle` (one orientation's images).

    Each usable image's axis shift t_j (its rigid fit against the reference) is
    modelled, weighted by its covariance, as

        t_j = (I − R(θ_j))·a + Σ_b d_b·[j in b],

    the eccentricity a of the target on the shaft (fitted when the usable images span
    at least `min_turn_deg`, else 0) plus jumps d_b: a *spike* (image k alone: a
    camera knocked and back, a bumped fixture springing back) or a *step* (image k
    and all after it: a camera moved for good). Jumps are added one at a time, the
    one lowering χ² most first, while the drop exceeds `bump_sigma`² (χ² scaled by
    χ²/dof of the model with the jump when that is above 1, so shifts noisier than
    their reported σ raise no false jumps) and the jump exceeds `bump_px` pixels,
    up to `max_jumps`.

    Parameters
    ----------
    results : sequence of TargetAngle
        In shooting order; the reference image (shift 0) first.
    bump_sigma, bump_px : float
        Significance (σ) and size (px) a jump must both exceed.
    min_turn_deg : float
        Turn range of the usable images needed to fit the eccentricity.
    max_jumps : int
        Most jumps reported.

    Returns
    -------
    AxisMotion
        Image indices are positions in `results`.

    Notes
    -----
    The images' shifts are taken as independent; their common part (the reference
    image's centres) is the same in every one and moves no jump. A jump at the
    image where the turn is largest is told from the eccentricity by the images
    turned the other way (a hysteresis loop turns both ways).

    Examples
    --------
    >>> import numpy as np
    >>> cov = np.eye(2) * 1e-4
    >>> seq = [TargetAngle(a, 1e-3, shift_x_px=dx, shift_y_px=0.0, shift_cov=cov)
    ...        for a, dx in [(0, 0.0), (2, 0.001), (1, 1.0), (-1, -0.002), (-2, 0.0)]]
    >>> m = axis_motion(seq)
    >>> m.jumps, round(float(m.jump_px[2, 0]), 2)
    (((2, 'spike'),), 1.0)
    """
    n_all = len(results)
    use = [k for k, r in enumerate(results)
           if r.usable and math.isfinite(r.shift_x_px) and np.all(np.isfinite(r.shift_cov))]
    shifts = np.full((n_all, 2), np.nan)
    stds = np.full((n_all, 2), np.nan)
    jump_px = np.full((n_all, 2), np.nan)
    jump_sigma = np.full(n_all, np.nan)
    if not use:
        return AxisMotion(0.0, 0.0, shifts, stds, (), jump_px, jump_sigma)
    thetas = np.radians([results[k].angle_deg for k in use])
    t = np.array([[results[k].shift_x_px, results[k].shift_y_px] for k in use])
    covs = np.array([results[k].shift_cov for k in use])
    white = np.linalg.inv(np.linalg.cholesky(covs))  # L⁻¹ with LLᵀ = C: whitened residuals
    y = np.einsum("nij,nj->ni", white, t).reshape(-1)
    eccentric = len(use) > 2 and float(np.ptp(np.degrees(thetas))) >= min_turn_deg
    jumps, gains = [], []
    beta, chi2, unscaled = _axis_fit(thetas, white, y, eccentric, jumps)
    for _ in range(max_jumps):
        best = None
        for pos in range(1, len(use)):
            for kind in ("spike", "step"):
                if any(p == pos for p, _ in jumps) or (kind == "step" and pos == len(use) - 1):
                    continue
                b, c2, cov = _axis_fit(thetas, white, y, eccentric, jumps + [(pos, kind)])
                dof = y.size - b.size
                gain = (chi2 - c2) / max(1.0, c2 / dof if dof > 0 else 1.0)
                if best is None or gain > best[0]:
                    best = (gain, (pos, kind), b, c2, cov)
        if best is None or best[0] <= bump_sigma**2 or math.hypot(*best[2][-2:]) <= bump_px:
            break
        gains.append(best[0])
        jumps.append(best[1])
        _, _, beta, chi2, unscaled = best
    dof = y.size - beta.size
    scale = max(1.0, chi2 / dof) if dof > 0 else 1.0
    a = beta[:2] if eccentric else np.zeros(2)
    cov_a = unscaled[:2, :2] * scale if eccentric else np.zeros((2, 2))
    for j, k in enumerate(use):
        A = np.eye(2) - _rot(thetas[j])
        shifts[k] = t[j] - A @ a
        stds[k] = np.sqrt(np.diag(covs[j] + A @ cov_a @ A.T))
    off = 2 if eccentric else 0
    for b, ((pos, kind), gain) in enumerate(zip(jumps, gains)):
        jump_px[use[pos]] = beta[off + 2 * b:off + 2 * b + 2]
        jump_sigma[use[pos]] = math.sqrt(gain)
    return AxisMotion(float(a[0]), float(a[1]), shifts, stds, tuple((use[p], kind) for p, kind in jumps),
                      jump_px, jump_sigma)


#: Columns of the angles.csv of an N-marker target (:func:`measure_target_folder`).
TARGET_COLUMNS = ["image", "angle_deg", "angle_std_deg", "status", "message", "n_used", "dropped_dots",
                  "shift_x_px", "shift_y_px", "shift_x_std_px", "shift_y_std_px", "bump", "chi2_red"]


def measure_target_folder(image_dir, *, reference, target, out_dir=None, settings: MeasureSettings | None = None,
                          progress: bool = False, reject_sigma: float = 5.0, bump_sigma: float = 5.0,
                          bump_px: float = 0.25):
    """Measure every image of a folder against a reference image, from all markers of a target.

    Parameters
    ----------
    image_dir : str or os.PathLike
        Folder of images, measured in natural name order (angles unwrapped along it).
    reference : str or os.PathLike
        The reference image (angle 0).
    target : Target, str or os.PathLike
        The printed target, a target file or a ready target's name.
    out_dir : str or os.PathLike, optional
        Where ``angles.csv`` goes; ``IMAGE_DIR/results`` by default (not the image
        folder itself).
    settings : MeasureSettings, optional
        How markers are found.
    progress : bool
        Show a progress bar.
    reject_sigma, bump_sigma, bump_px : float
        See :func:`target_angle`.

    Returns
    -------
    MeasureResult
        The table (:data:`TARGET_COLUMNS`): per image the angle (deg, counter-clockwise
        as displayed) and its 1σ, status (``ok``, ``marker_missing`` with the angle
        from the others, ``ambiguous``/``layout_mismatch`` with the angle withheld,
        ``failed`` for an image that cannot be read or has no markers), the dots
        dropped, the axis shift and whether it is a ``bump``. Every status but ``ok``
        counts in ``n_failed``.

    Raises
    ------
    ImageReadError, MarkerError
        The folder has no images, or the reference image cannot be read.
    TargetError
        The target cannot be read, or the reference's identity is not certain.
    OutputError
        The output folder is the image folder, or cannot be written.
    """
    import pandas as pd

    from .batch import measure_each
    from .errors import OutputError
    from .fileio import check_output_dir, same_folder, write_csv
    from .measure import MeasureResult, list_images, printable_name
    from .measurements import output_folder

    settings = settings or MeasureSettings()
    files = list_images(image_dir)
    out = output_folder(image_dir, out_dir)
    if same_folder(out, image_dir):
        raise OutputError(f"{out}: the output folder cannot be the image folder itself; use a "
                          "subfolder such as results/")
    check_output_dir(out)
    target, table, ident = _reference(reference, target, settings)
    ref_xy, ref_cov = _centres(table, ident)
    origin = (ident.axis_x_px, ident.axis_y_px)
    done = measure_each(lambda f: _measure(ref_xy, ref_cov, origin, f, target, settings, f.name, reject_sigma,
                                           bump_sigma, bump_px), files, names=[f.name for f in files],
                        progress=progress)
    rows, last = [], 0.0
    for f, d in zip(files, done):
        row = {"image": printable_name(f.name), "status": "failed", "message": d.message, "bump": False}
        res = d.value
        if res is not None:
            row.update(status=res.status, message=res.message)
            if res.usable:
                last = last + ((res.angle_deg - last + 180.0) % 360.0 - 180.0)
                row.update(angle_deg=last, angle_std_deg=res.angle_std_deg, n_used=res.n_used,
                           dropped_dots=" ".join(str(r.dot) for r in res.residuals if not r.used),
                           shift_x_px=res.shift_x_px, shift_y_px=res.shift_y_px,
                           shift_x_std_px=math.sqrt(res.shift_cov[0, 0]),
                           shift_y_std_px=math.sqrt(res.shift_cov[1, 1]), bump=res.bump, chi2_red=res.chi2_red)
        rows.append(row)
    frame = pd.DataFrame(rows, columns=TARGET_COLUMNS)
    write_csv(out / "angles.csv", frame)
    n_ok = int((frame["status"] == "ok").sum())
    return MeasureResult(table=frame, path=out / "angles.csv", n_ok=n_ok, n_failed=len(frame) - n_ok)
