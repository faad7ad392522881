"""Uncertainty propagation: first-order (analytic) for fits and slopes, seeded Monte
Carlo for the model-free loop figures.

Error model (what the analysis assumes about ``measurements.csv``)
-------------------------------------------------------------------
- **Angles**: the ``angle_std_deg`` of each image is independent between images. All
  angles of an orientation are relative to one reference image, whose error is a
  common offset; every figure computed here is a difference or slope of angles of
  the same orientation, so that offset cancels and is not propagated.
- **Torques** are described by a *loading matrix* ``L`` (images × sources): the torque
  error of image ``i`` is ``δτ_i = Σ_j L_ij·ξ_j`` with independent standard normal
  sources ``ξ_j`` (:func:`torque_sources`), so ``cov(δτ) = L·Lᵀ``. Three models
  (``torque_correlation``):

  ``"pieces"`` (the rig is known; the default of :func:`.session.analyze_session`
  when a ``rig`` is given) follows the weight pieces. Each of the four pans (+A, +B
  for positive torque, −A, −B for negative) has its own set of pieces, each piece of
  mass ``m_step + δm`` with ``σ(δm) = mass_std_kg``, drawn once for the session and
  reused; a pan with ``n`` pieces carries pieces ``1..n`` (``n = mass_kg /
  step_mass_kg``, a partial piece counted as a whole one). So the torque of an image with ``n`` pieces per pan and sign
  ``s`` (from the phase) is

  ``τ = s·g·r·Σ_{k≤n} (m_A,k + m_B,k)·(1 + ε) + δτ_f``,

  ``δτ = s·g·r·Σ_{k≤n} e_s,k + τ·ε + δτ_f`` with ``e_s,k = δm_A,k + δm_B,k``
  (σ = √2·mass_std_kg): one source per sign and piece index (a **random walk** in
  the step number, shared by the two phases of one sign and by every orientation
  and cycle of the session), one common scale source ``ε`` with
  ``σ(ε) = sqrt((u_g/g)² + (u_r/r)²)``, and an independent friction term ``δτ_f`` per
  image (``friction_torque_std_nm``). The marginal 1σ is
  ``sqrt((g·r)²·2n·mass_std² + (τ·σ(ε))² + u_f²)``, the ``torque_std_nm`` that
  :func:`vision_torsion.session.torque.couple_torque` writes.

  ``"level"`` (no rig known): images with the **same nominal torque** (same signed
  value, to 1e-9 N·m) share **one** torque error with the ``torque_std_nm`` given;
  different torque levels are independent. It misses the random-walk correlation
  between levels, which is what moves a slope: on the demo rig (0.0196 N·m steps,
  ±0.1 g pieces) it under-reports the torque part of k_u, k_l, τ_c and the loop
  energy by a factor of about 3–10.

  ``"independent"``: every image's torque error is its own.
- The **angle part** of an uncertainty is independent between loops (orientations,
  cycles); the **torque part** is shared by all loops of a session (the same
  weights, or the same levels). :mod:`.summary` uses this split.

Every figure therefore carries ``std_angle`` and ``std_torque`` (1σ), and
``std = sqrt(std_angle² + std_torque²)``; expanded uncertainties are
``u95 = 2·std`` (coverage factor k = 2, ≈95 % for a normal distribution).

First order (fits and slopes)
-----------------------------
A weighted least-squares estimate ``p̂`` of a model ``θ = f(τ; p)`` with weights
``W`` moves, to first order, by ``δp = G·(δθ − J_τ·δτ)``, ``G = (JᵀWJ)⁻¹JᵀW``
(``J = ∂f/∂p``, ``J_τ = ∂f/∂τ``). With ``δτ = L·ξ`` the torque part of the covariance
is the sandwich ``cov_τ = (G·J_τ·L)·(G·J_τ·L)ᵀ`` — the full torque covariance
``L·Lᵀ``, correlations between levels included. ``J_τ·L`` is computed column by
column as a directional central difference of the model along ``L_j``
(:func:`torque_source_jacobian`). The weights stay the angle weights: the torque
error is shared by all loops of a session, so weighting by it cannot average it
down; the sandwich is valid for any weights.

Monte Carlo
-----------
Model-free figures (hysteresis, lost motion, loop energy, ...) are non-linear in the
data (maxima, interpolation), so they are propagated by drawing ``n_draws`` (default
400: the std is then known to ≈ 1/sqrt(2·400) ≈ 3.5 %) perturbed copies of a loop,
once with angle errors only and once with torque errors only (``δτ = L·ξ``,
vectorised: one ``(n_draws, m)`` normal draw times ``Lᵀ``), from
``numpy.random.default_rng(seed)``; every figure is evaluated on all draws at once,
so a loop costs milliseconds. The std of a figure is the standard deviation over
draws where it is finite.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..errors import AnalysisError, RigError
from ..measurements import PHASE_SIGN, TorqueRig, pieces_per_pan

__all__ = [
    "COVERAGE_FACTOR",
    "TORQUE_MODELS",
    "RIG_KEYS",
    "check_rig",
    "torque_groups",
    "torque_sources",
    "pieces_per_pan",
    "group_sources",
    "compact_sources",
    "monte_carlo_std",
    "linearised_covariance",
    "torque_source_jacobian",
    "std_by_kind",
    "PHASE_DIRECTION",
    "stds_of_draws",
    "tip_amplitude_response",
    "coverage_factor_t_normal",
]

#: Coverage factor of every ``*_u95`` (normal distribution, ≈95 %).
COVERAGE_FACTOR = 2.0

#: Torque error models (see the module notes).
TORQUE_MODELS = ("pieces", "level", "independent")

#: Required keys of a ``rig`` mapping (:class:`vision_torsion.measurements.TorqueRig`).
RIG_KEYS = TorqueRig.required()


@functools.lru_cache(maxsize=64)
def _t_nodes(dof: float):
    """Gauss–Legendre nodes on (0, 1) mapped through Student's t quantile at ``dof``, and their weights."""
    from scipy import special

    x, w = np.polynomial.legendre.leggauss(120)
    return special.stdtrit(dof, 0.5 * (x + 1.0)), 0.5 * w


@functools.lru_cache(maxsize=1)
def _z_nodes():
    z, w = np.polynomial.hermite_e.hermegauss(48)
    return z, w / w.sum()


def coverage_factor_t_normal(u_a: float, dof: float, u_b: float, *, p: float = 0.95) -> float:
    """Coverage factor of a Type A part (Student t) combined with a normal part (JCGM 101).

    The error of the estimate is ``u_a·T + u_b·Z`` with ``T`` Student's t at ``dof``
    degrees of freedom (a mean of ``n`` observations whose scatter gave ``u_a = s/√n``:
    ``dof = n − 1``, GUM Supplement 1, 6.4.9) and ``Z`` standard normal (the parts
    known from propagation). Returns ``k`` with ``P(|u_a·T + u_b·Z| ≤ k·u_c) = p``,
    ``u_c = sqrt(u_a² + u_b²)``: the coverage interval of the convolution, computed by
    quadrature.

    Parameters
    ----------
    u_a : float
        Scale of the Type A part (its standard uncertainty s/√n), ≥ 0.
    dof : float
        Its degrees of freedom (> 0; ``inf`` for a normal part).
    u_b : float
        Standard uncertainty of the normal part, ≥ 0.
    p : float
        Coverage probability.

    Returns
    -------
    float
        ``k``; ``t_p(dof)`` when ``u_b = 0``, the normal quantile when ``u_a = 0``.

    Notes
    -----
    The Welch–Satterthwaite formula (GUM G.4) instead gives ``t_p`` at ``ν_eff =
    u_c⁴/(u_a⁴/dof)``; with few observations (``n = 2, 3``) and a normal part of about
    a third of ``u_a`` its intervals cover only 87–92 % (Hall & Willink, Metrologia 38,
    2001), while this one covers at least ``p`` for any ratio (tested by simulation in
    ``tests/test_analysis_coverage_factor.py``). The probability is integrated over the
    smoother of the two variables: over ``Z`` (Gauss–Hermite) when ``u_a ≥ u_b``,
    else over ``T`` through its quantile function (Gauss–Legendre on (0, 1)).

    Examples
    --------
    >>> round(coverage_factor_t_normal(1.0, 1, 0.0), 3)  # Student's t_0.975 at 1 dof
    12.706
    >>> round(coverage_factor_t_normal(0.0, 1, 1.0), 3)  # normal
    1.96
    """
    u_a, u_b = float(u_a), float(u_b)
    if not (np.isfinite(u_a) and np.isfinite(u_b)) or u_a < 0 or u_b < 0 or u_a + u_b == 0 or not dof > 0:
        raise AnalysisError(f"coverage_factor_t_normal needs u_a, u_b >= 0 (not both 0) and dof > 0, "
                            f"got {u_a!r}, {u_b!r}, {dof!r}")
    from scipy import optimize, special

    two_sided = 0.5 + 0.5 * p
    if u_a == 0.0 or not np.isfinite(dof):
        # a t at infinite dof is normal: the sum is normal with u_c
        return float(special.ndtri(two_sided))
    u_c = math.hypot(u_a, u_b)
    if u_b == 0.0:
        return float(special.stdtrit(dof, two_sided))
    if u_a >= u_b:
        z, w = _z_nodes()
        z = z * u_b

        def inside(q):
            return float(np.sum(w * (special.stdtr(dof, (q - z) / u_a) - special.stdtr(dof, (-q - z) / u_a))))
    else:
        t, w = _t_nodes(float(dof))
        t = t * u_a

        def inside(q):
            return float(np.sum(w * (special.ndtr((q - t) / u_b) - special.ndtr((-q - t) / u_b))))

    hi = special.stdtrit(dof, two_sided) * u_a + special.ndtri(two_sided) * u_b  # |sum| <= |a| + |b|
    q = optimize.brentq(lambda q: inside(q) - p, 0.0, hi, xtol=u_c * 1e-7)
    return q / u_c


def _error(message):
    return AnalysisError(message)


def check_rig(rig) -> TorqueRig:
    """The rig constants of the ``"pieces"`` torque model, as a :class:`~vision_torsion.measurements.TorqueRig`.

    Parameters
    ----------
    rig : TorqueRig or mapping
        A :class:`~vision_torsion.measurements.TorqueRig` (returned as it is: it was
        checked when made), or a mapping of its constants: ``step_mass_kg`` (mass of
        one weight piece, kg), ``mass_std_kg`` (1σ of one piece, kg),
        ``arm_radius_m`` (m); optional ``gravity_m_per_s2`` (9.81),
        ``friction_torque_std_nm`` (1σ per image, N·m), ``arm_radius_std_m`` (m),
        ``gravity_std_m_per_s2`` (m/s²), 0 when absent.

    Returns
    -------
    TorqueRig

    Raises
    ------
    AnalysisError
        Not a mapping, a missing or unknown key, a non-finite value, a non-positive
        step mass, g or r, or a negative uncertainty (the message of the
        :class:`~vision_torsion.errors.RigError` that :class:`TorqueRig` raised).

    Examples
    --------
    >>> rig = check_rig(dict(step_mass_kg=0.02, mass_std_kg=1e-4, gravity_m_per_s2=9.81, arm_radius_m=0.05))
    >>> rig.friction_torque_std_nm
    0.0
    """
    if isinstance(rig, TorqueRig):
        return rig
    try:
        return TorqueRig.from_mapping(rig)
    except RigError as exc:
        raise AnalysisError(str(exc), reason=exc.reason) from None


#: Direction of the torque change that led to an image of each phase (+1 rising).
PHASE_DIRECTION = {
    "reference": 0,
    "positive_unloading": -1,
    "negative_loading": -1,
    "negative_unloading": 1,
    "positive_loading": 1,
    "closing": -1,
}


def torque_sources(frame, *, correlation="level", rig=None, resolution_nm=1e-9, return_kinds=False):
    """Loading matrix ``L`` of the torque errors: ``δτ = L·ξ``, ``ξ ~ N(0, I)``.

    Parameters
    ----------
    frame : pandas.DataFrame
        Rows of ``measurements.csv`` (``torque_nm``, ``torque_std_nm``; for
        ``"pieces"`` also ``phase`` and ``mass_kg``, the mass on each pan, kg).
    correlation : {"pieces", "level", "independent"}
        Error model (module notes).
    rig : mapping, optional
        Rig constants (:func:`check_rig`); required for ``"pieces"``.
    resolution_nm : float
        Torque resolution of the ``"level"`` grouping, N·m.

    Returns
    -------
    L : numpy.ndarray, shape (n_rows, n_sources)
        N·m per unit source. Columns are session-wide: rows of different loops that
        share a source (a piece, a level, the scale) have entries in the same column.
    groups : numpy.ndarray of int, shape (n_rows,)
        Same-nominal-torque index (:func:`torque_groups` with ``"level"``, or
        ``"independent"``), used to merge repeated torques inside a run.
    kinds : numpy.ndarray of str, shape (n_sources,)
        Only with ``return_kinds=True``: what each column is, for the uncertainty
        budget: ``"weights"``, ``"g_r"`` (common scale), ``"friction"``, or
        ``"level"`` (the ``"level"``/``"independent"`` models).

    Raises
    ------
    AnalysisError
        Unknown model, or ``"pieces"`` without a valid rig.

    Notes
    -----
    ``"pieces"``: with ``n_i`` = :func:`pieces_per_pan` and ``s_i`` the sign of
    the phase, ``L[i, (s, k)] = s·g·r·√2·mass_std_kg`` for ``k = 1..n_i`` and
    ``s = s_i``; ``L[i, scale] = τ_i·sqrt((u_g/g)² + (u_r/r)²)``;
    ``L[i, friction] = −d_i·friction_torque_std_nm`` with ``d_i`` the direction of the
    last torque change (+1 for the loading phases of positive torque and the unloading
    of negative torque, −1 otherwise; 0 for a reference image). ``"level"``: ``L[i, g_i] = σ_g``,
    the largest ``torque_std_nm`` of the group. ``"independent"``: ``diag(torque_std_nm)``.

    Examples
    --------
    >>> import pandas as pd
    >>> f = pd.DataFrame({"phase": ["positive_loading"] * 3, "mass_kg": [0.0, 0.02, 0.04],
    ...                   "torque_nm": [0.0, 0.01962, 0.03924], "torque_std_nm": [0.0, 1.0, 1.0]})
    >>> rig = dict(step_mass_kg=0.02, mass_std_kg=1.0, gravity_m_per_s2=1.0, arm_radius_m=1.0)
    >>> L, _ = torque_sources(f, correlation="pieces", rig=rig)
    >>> (L @ L.T).round(6).tolist()  # a random walk: cov(n, n') = 2·min(n, n')
    [[0.0, 0.0, 0.0], [0.0, 2.0, 2.0], [0.0, 2.0, 4.0]]
    """
    tau = np.asarray(frame["torque_nm"], dtype=float).reshape(-1)
    std = np.asarray(frame["torque_std_nm"], dtype=float).reshape(-1)
    if correlation not in TORQUE_MODELS:
        raise _error(f"torque_correlation must be one of {', '.join(TORQUE_MODELS)}, got {correlation!r}")
    groups = torque_groups(
        tau, correlation="independent" if correlation == "independent" else "level", resolution_nm=resolution_nm
    )

    def done(L, kinds):
        return (L, groups, np.asarray(kinds, dtype=object)) if return_kinds else (L, groups)

    if correlation == "independent":
        return done(np.diag(std), ["level"] * tau.size)
    if correlation == "level":
        L = group_sources(groups, std)
        return done(L, ["level"] * L.shape[1])
    if rig is None:
        raise _error(
            "torque_correlation='pieces' needs the rig (step_mass_kg, mass_std_kg, gravity_m_per_s2, arm_radius_m)"
        )
    rig = check_rig(rig)
    import pandas as pd

    mass = pd.to_numeric(pd.Series(np.asarray(frame["mass_kg"], dtype=object)), errors="coerce").to_numpy(float)
    bad = ~np.isfinite(mass) | (mass < 0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        where = f"image {frame['image'].iloc[i]!r}" if "image" in frame else f"row {i}"
        raise _error(
            f"measurements table, {where}: mass_kg is {str(frame['mass_kg'].iloc[i])!r}; the 'pieces' torque "
            "model needs the mass on each pan (kg, >= 0)"
        )
    n = pieces_per_pan(mass.reshape(-1), rig.step_mass_kg)
    sign = np.asarray(frame["phase"].map(PHASE_SIGN), dtype=float)
    sign = np.where(np.isfinite(sign), sign, np.sign(tau))
    g_r = rig.gravity_m_per_s2 * rig.arm_radius_m
    n_max = int(n.max()) if n.size else 0
    k = np.arange(1, n_max + 1)
    step = g_r * np.sqrt(2.0) * rig.mass_std_kg
    cols, kinds = [], []
    for s_ in (1.0, -1.0):
        cols.append(np.where((sign[:, None] == s_) & (n[:, None] >= k[None, :]), s_ * step, 0.0))
        kinds += ["weights"] * n_max
    rel = float(np.hypot(rig.gravity_std_m_per_s2 / rig.gravity_m_per_s2, rig.arm_radius_std_m / rig.arm_radius_m))
    if rel > 0:
        cols.append((tau * rel)[:, None])
        kinds.append("g_r")
    if rig.friction_torque_std_nm > 0:
        direction = np.asarray(frame["phase"].map(PHASE_DIRECTION), dtype=float)
        direction = np.where(np.isfinite(direction), direction, 0.0)
        cols.append((-direction * rig.friction_torque_std_nm)[:, None])
        kinds.append("friction")
    L = np.concatenate(cols, axis=1) if cols else np.zeros((tau.size, 0))
    return done(L, kinds)


def group_sources(groups, torque_std_nm) -> np.ndarray:
    """Loading matrix of the ``"level"`` model: one column per group, ``L[i, g_i] = σ_g``."""
    groups = np.asarray(groups, dtype=int).reshape(-1)
    g_std = _group_std(groups, torque_std_nm)
    out = np.zeros((groups.size, g_std.size))
    out[np.arange(groups.size), groups] = g_std[groups]
    return out


def compact_sources(sources, kinds=None):
    """Drop the all-zero columns of a loading matrix (sources that do not touch these rows).

    With ``kinds`` (one label per column) returns ``(L, kinds)`` of the kept columns.
    """
    L = np.asarray(sources, dtype=float)
    keep = np.any(L != 0.0, axis=0)
    if kinds is None:
        return L[:, keep]
    return L[:, keep], np.asarray(kinds, dtype=object)[keep]


def std_by_kind(gt: np.ndarray, kinds) -> dict:
    """1σ of each parameter from each kind of torque source.

    ``gt`` is ``G·J_τ·L`` (parameters × sources, :func:`linearised_covariance`'s
    torque sensitivity); returns ``{kind: ndarray (parameters,)}``.
    """
    kinds = np.asarray(kinds, dtype=object)
    return {str(k): np.sqrt(np.sum(gt[:, kinds == k] ** 2, axis=1)) for k in dict.fromkeys(kinds.tolist())}


def torque_groups(torque_nm, *, correlation="level", resolution_nm=1e-9) -> np.ndarray:
    """Index of the shared torque error of each sample.

    Parameters
    ----------
    torque_nm : array_like
        Nominal torques, N·m.
    correlation : {"level", "independent"}
        ``"level"``: samples with the same nominal torque (rounded to
        ``resolution_nm``) share one error; ``"independent"``: one error per sample.

    Returns
    -------
    numpy.ndarray of int
        Group index per sample (0 .. n_groups−1).

    Examples
    --------
    >>> torque_groups([0.1, 0.0, 0.1, -0.1]).tolist()
    [2, 1, 2, 0]
    """
    tau = np.asarray(torque_nm, dtype=float).reshape(-1)
    if correlation == "independent":
        return np.arange(tau.size)
    if correlation != "level":
        raise AnalysisError(f"torque_correlation must be 'level' or 'independent', got {correlation!r}")
    keys = np.round(tau / resolution_nm).astype(np.int64)
    _, inverse = np.unique(keys, return_inverse=True)
    return inverse.reshape(-1)


def _group_std(groups: np.ndarray, torque_std_nm: np.ndarray) -> np.ndarray:
    out = np.zeros(int(groups.max()) + 1 if groups.size else 0)
    np.maximum.at(out, groups, np.asarray(torque_std_nm, float))
    return out


def monte_carlo_std(
    evaluate,
    torque_nm,
    angle_rad,
    *,
    angle_std_rad,
    torque_std_nm=None,
    groups=None,
    torque_sources=None,
    n_draws=400,
    seed=0,
    kinds=None,
    torque_response=None,
):
    """Standard deviation of each figure of a loop from angle and from torque errors.

    Parameters
    ----------
    evaluate : callable
        ``evaluate(tau2d, theta2d) -> dict[str, ndarray (D,)]`` evaluating every figure
        on D perturbed copies at once (``tau2d``, ``theta2d`` of shape (D, n)).
    torque_nm, angle_rad : ndarray (n,)
        Nominal data (N·m, rad).
    angle_std_rad : ndarray (n,)
        1σ per sample, rad.
    torque_std_nm, groups : ndarray (n,), optional
        1σ per sample (N·m) and shared torque error index (:func:`torque_groups`):
        the ``"level"`` model; ignored when ``torque_sources`` is given.
    torque_sources : ndarray (n, m), optional
        Loading matrix ``L`` of the torque errors (:func:`torque_sources`), N·m.
    n_draws : int
        Draws per error source.
    seed : int
        Seed of ``numpy.random.default_rng``.

    kinds : array_like of str (m,), optional
        Kind of each torque source; then each kind is drawn on its own and a third
        dict ``{name: {kind: std}}`` is returned, ``std_torque`` being their
        quadrature sum (the kinds are independent).
    torque_response : callable, optional
        ``torque_response(d_tau) -> d_theta`` (both ``(D, n)``, N·m → rad): how the
        measured angles themselves move when the true torques are ``τ + δτ`` beyond
        what the torque axis shows (a loop's amplitude: a torque error at a reversal
        moves the branch that follows it). Given it, a torque draw is evaluated as the
        data would be measured, at the nominal torques ``τ`` with angles
        ``θ + ∂θ/∂τ·δτ + torque_response(δτ)``, the first term by shifting the torque
        axis the other way (``τ − δτ``). Where the callable has an attribute ``held``
        (bool, (n,)), those samples' torque axis is not shifted: ``torque_response``
        gives their whole angle response (a loop's tips, where the image is read on two
        branches whose slopes differ; :func:`tip_amplitude_response`).

    Returns
    -------
    (dict, dict) or (dict, dict, dict)
        ``std_angle[name]`` and ``std_torque[name]`` (NaN where fewer than half the
        draws gave a finite value), and with ``kinds`` the parts by kind.

    Notes
    -----
    Torque draws are ``δτ = ξ·Lᵀ`` with ``ξ`` of shape ``(n_draws, m)`` standard
    normal, so their covariance is ``L·Lᵀ`` with every correlation of the model.
    """
    rng = np.random.default_rng(seed)
    tau = np.asarray(torque_nm, float)[None, :]
    th = np.asarray(angle_rad, float)[None, :]
    if torque_sources is None:
        torque_sources = group_sources(groups, torque_std_nm)
    L = np.asarray(torque_sources, float)
    d_theta = rng.standard_normal((n_draws, th.shape[1])) * np.asarray(angle_std_rad, float)[None, :]
    by_angle = evaluate(np.repeat(tau, n_draws, axis=0), th + d_theta)

    held = getattr(torque_response, "held", None)
    moved = 1.0 if held is None else (~np.asarray(held, bool)).astype(float)[None, :]

    def torque_draw(d_tau):
        if torque_response is None:
            return evaluate(tau + d_tau, np.repeat(th, n_draws, axis=0))
        return evaluate(tau - d_tau * moved, th + torque_response(d_tau))

    if kinds is None:
        d_tau = rng.standard_normal((n_draws, L.shape[1])) @ L.T
        return _stds(by_angle), _stds(torque_draw(d_tau))
    kinds = np.asarray(kinds, dtype=object)
    parts = {}
    for kind in dict.fromkeys(kinds.tolist()):
        Lk = L[:, kinds == kind]
        d_tau = rng.standard_normal((n_draws, Lk.shape[1])) @ Lk.T
        parts[str(kind)] = _stds(torque_draw(d_tau))
    sa = _stds(by_angle)
    by_kind = {name: {k: parts[k][name] for k in parts} for name in sa}
    st = {name: float(np.sqrt(np.sum(np.square(list(v.values()))))) if v else 0.0 for name, v in by_kind.items()}
    return sa, st, by_kind


def _branch_slopes(tau: np.ndarray, th: np.ndarray) -> np.ndarray:
    """dθ/dτ along one branch (samples in path order): central secants, one-sided at the ends."""
    if tau.size < 2:
        return np.full(tau.size, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        step = np.diff(th) / np.diff(tau)
    out = np.empty(tau.size)
    out[0], out[-1] = step[0], step[-1]
    if tau.size > 2:
        with np.errstate(divide="ignore", invalid="ignore"):
            out[1:-1] = (th[2:] - th[:-2]) / (tau[2:] - tau[:-2])
    return out


def tip_amplitude_response(torque_nm, angle_rad, is_desc):
    """How a loop's angles move when its **tips** (reversal torques) are wrong: the amplitude effect.

    The angles of a loop responded to the true torques; a torque error at a reversal
    (a loop tip) changes how far the loop was driven, and with it the branch that
    follows. Shifting the torque axis (:func:`monte_carlo_std`) carries only the
    torque of each image itself; this is the rest.

    Parameters
    ----------
    torque_nm, angle_rad : ndarray (n,)
        The loop's runs (:meth:`.loops.Loop.runs`): the descending run from +Tmax to
        −Tmax, then the ascending run up to +Tmax (N·m, rad).
    is_desc : ndarray of bool (n,)
        Which samples are in the descending run.

    Returns
    -------
    callable
        ``response(d_tau) -> d_theta``, ``(D, n)`` → ``(D, n)`` (N·m → rad), for
        ``torque_response`` of :func:`monte_carlo_std`, with ``response.held`` (bool,
        (n,)): the tip images, whose whole response it gives (their torque axis is
        not shifted).

    Notes
    -----
    A branch after a reversal at ``(τ_r, θ_r)`` follows the **Masing** rule: its shape
    relative to the reversal point is fixed, so a reversal torque wrong by ``δ_r``
    translates the branch by ``(δ_r, s_arr·δ_r)`` (``s_arr`` the slope arriving at the
    tip). At a fixed torque the branch then moves by ``S(τ)·δ_r`` with
    ``S(τ) = s_arr − s(τ)`` (``s(τ)`` the branch's own slope). A Preisach loop (μ ≥ 0)
    bounds the effect: ``0 ≤ S ≤ h = s_arr − s_dep`` (``s_dep`` the slope just after
    the reversal: what arrives at a tip beyond what leaves it is the hysteretic part
    that remembers the tip). So ``S(τ) = clip(s_arr − s(τ), 0, max(h, 0))``: the
    Masing value on smooth loops, and zero where nothing hysteretic switches at the
    tip (the bilinear loop: ``s_arr = s_dep = 1/k_u``; a stop-type play that is
    saturated at the tips). A single major loop cannot tell a Masing loop from other
    Preisach densities of the same shape; this rule is the assumption, and it is
    exact for both the Masing and the bilinear loop. Slopes are central secants of
    the data along each branch; the top tip's arriving slope is the ascending run's
    last step (the loop came up to +Tmax the same way before it), the bottom tip's
    the descending run's last step. The bottom reversal point itself moves by
    ``S_desc(−Tmax)·δ_top`` and carries that to the whole ascending branch.

    A tip image's own angle answers its torque along the **arriving** branch
    (``s_arr·δ_r``), but a shift of the torque axis is read differently by each
    figure at a tip: along the departing run by an interpolation, as a vertex
    between both runs by the loop energy's polygon (which then gains a spurious
    ``δ_r·w(one step)/2``, w the loop's width one step from the tip: 7 % of the
    Masing loop energy's torque part). So the two tip images (+Tmax at the start of
    the descending run when the loop comes back to it; −Tmax, the descending run's
    last image) are ``held``: their axis is not shifted and the response moves their
    angle by ``s_arr·δ_r`` (plus, at −Tmax, the descending branch's shift from
    +Tmax). Where a stop-type play is open (within its width after a reversal) ``S``
    is negative and the clip leaves it at zero: no figure is evaluated there.
    """
    tau = np.asarray(torque_nm, float)
    th = np.asarray(angle_rad, float)
    desc = np.flatnonzero(is_desc)
    asc = np.flatnonzero(~np.asarray(is_desc, bool))
    zero = lambda d_tau: np.zeros_like(d_tau)  # noqa: E731
    if desc.size < 2 or asc.size < 1:
        return zero
    sd = _branch_slopes(tau[desc], th[desc])
    # the ascending branch starts at the bottom tip (the descending run's last image)
    a_path = np.concatenate([[desc[-1]], asc])
    sa = _branch_slopes(tau[a_path], th[a_path])[1:]
    s_arr_top = (th[asc[-1]] - th[asc[-2]]) / (tau[asc[-1]] - tau[asc[-2]]) if asc.size >= 2 else np.nan
    if asc.size < 2 or abs(tau[asc[-1]] - tau[desc[0]]) > 1e-9:
        s_arr_top = np.nan  # the top tip was not reached again: no slope arriving at it
    h_top = s_arr_top - sd[0]
    s_arr_bot = sd[-1]
    h_bot = s_arr_bot - sa[0]

    def sens(s_arr, h, s):
        if not (np.isfinite(s_arr) and np.isfinite(h)) or h <= 0:
            return np.zeros_like(s)
        return np.clip(np.nan_to_num(s_arr - s, nan=0.0), 0.0, h)

    S_d = sens(s_arr_top, h_top, sd)
    S_a = sens(s_arr_bot, h_bot, sa)
    held = np.zeros(tau.size, bool)
    held[desc[-1]] = np.isfinite(s_arr_bot)
    if np.isfinite(s_arr_top):
        # the +Tmax image answers its torque along the branch that arrived there (a stop-type play: closed before
        # the tip, open after it)
        S_d[0] = s_arr_top
        held[desc[0]] = True

    def response(d_tau):
        d_tau = np.asarray(d_tau, float)
        out = np.zeros_like(d_tau)
        d_top = d_tau[:, desc[0] : desc[0] + 1]
        d_bot = d_tau[:, desc[-1] : desc[-1] + 1]
        out[:, desc] = S_d[None, :] * d_top
        out[:, asc] = S_d[-1] * d_top + S_a[None, :] * d_bot
        if held[desc[-1]]:
            out[:, desc[-1]] += s_arr_bot * d_bot[:, 0]
        return out

    response.held = held
    return response


def stds_of_draws(values: dict) -> dict:
    """Standard deviation of each figure over its draws (NaN when fewer than half are finite)."""
    return _stds(values)


def _stds(values: dict) -> dict:
    out = {}
    for name, v in values.items():
        v = np.asarray(v, float)
        ok = np.isfinite(v)
        out[name] = float(np.std(v[ok], ddof=1)) if ok.sum() >= max(2, v.size // 2) else float("nan")
    return out


# ---------------------------------------------------------------------------------
# First-order propagation through least-squares estimates
# ---------------------------------------------------------------------------------


def torque_jacobian(model, tau: np.ndarray, groups: np.ndarray, h: float = 1e-7) -> np.ndarray:
    """d(model angles)/d(shared error of each torque group), by central differences:
    :func:`torque_source_jacobian` with one unit source per group."""
    n_groups = int(groups.max()) + 1 if groups.size else 0
    return torque_source_jacobian(model, tau, (groups[:, None] == np.arange(n_groups)).astype(float), h)


def torque_source_jacobian(model, tau: np.ndarray, sources: np.ndarray, h: float = 1e-7) -> np.ndarray:
    """``J_τ·L``: d(model angles)/d(each torque source), by directional central differences.

    Parameters
    ----------
    model : callable
        ``model(tau) -> angles`` (rad) for a torque sequence (N·m).
    tau : ndarray (n,)
        Nominal torques, N·m.
    sources : ndarray (n, m)
        Loading matrix ``L`` (N·m per unit source).
    h : float
        Step along the normalised column, N·m.

    Returns
    -------
    ndarray (n, m)
        rad per unit source: column ``j`` is ``(f(τ + h·ℓ_j) − f(τ − h·ℓ_j))/(2h)·c_j``
        with ``ℓ_j = L_j / c_j``, ``c_j = max|L_j|``.
    """
    L = np.asarray(sources, float)
    cols = []
    for j in range(L.shape[1]):
        c = float(np.max(np.abs(L[:, j])))
        if c == 0.0:
            cols.append(np.zeros(tau.size))
            continue
        d = L[:, j] * (h / c)
        cols.append((model(tau + d) - model(tau - d)) / (2.0 * h) * c)
    return np.column_stack(cols) if cols else np.zeros((tau.size, 0))


def linearised_covariance(jac_p, weights, angle_var, jac_tau, group_var):
    """Covariance of a weighted least-squares estimate from angle and torque errors.

    Parameters
    ----------
    jac_p : ndarray (n, p)
        d(model)/d(parameters) at the estimate.
    weights : ndarray (n,)
        Weights of the least-squares criterion ``Σ w_i r_i²``.
    angle_var : ndarray (n,)
        Variance of each (independent) angle, rad².
    jac_tau : ndarray (n, g)
        d(model)/d(torque error of each group), or ``J_τ·L`` (per unit torque
        source, :func:`torque_source_jacobian`).
    group_var : ndarray (g,)
        Variance of each group's torque error, (N·m)² (ones for unit sources).

    Returns
    -------
    (ndarray, ndarray)
        Parameter covariance from angle errors and from torque errors.

    Raises
    ------
    numpy.linalg.LinAlgError
        The normal matrix is singular (a parameter is not identified by the data).

    Notes
    -----
    To first order ``δp = G·δθ`` with ``G = (JᵀWJ)⁻¹JᵀW``; a torque error ``δτ`` moves
    the model by ``J_τ·δτ``, which the estimate absorbs like an angle error of opposite
    sign, so ``cov = G·diag(σθ²)·Gᵀ + (G·J_τ)·diag(στ²)·(G·J_τ)ᵀ`` (sandwich form,
    valid also when the weights are not the inverse variances). With correlated
    torque errors ``δτ = L·ξ`` pass ``jac_tau = J_τ·L`` and ``group_var = 1``: the
    torque term is then ``(G·J_τ·L)(G·J_τ·L)ᵀ``, the full covariance ``L·Lᵀ``.
    """
    jw = jac_p * weights[:, None]
    normal = jac_p.T @ jw
    # a near-singular normal matrix means a parameter is not identified by the data
    if not np.all(np.isfinite(normal)) or np.linalg.cond(normal) > 1e14:
        raise np.linalg.LinAlgError("normal matrix is singular")
    g = np.linalg.solve(normal, jw.T)
    cov_a = (g * angle_var[None, :]) @ g.T
    gt = g @ jac_tau
    cov_t = (gt * group_var[None, :]) @ gt.T
    return cov_a, cov_t


def parameter_stds(names, cov_a, cov_t):
    """1σ per parameter name from angle and torque covariance matrices."""
    sa = dict(zip(names, (float(v) for v in np.sqrt(np.clip(np.diag(cov_a), 0, None)))))
    st = dict(zip(names, (float(v) for v in np.sqrt(np.clip(np.diag(cov_t), 0, None)))))
    return sa, st


def least_squares_weights(angle_std_rad) -> np.ndarray:
    """Inverse-variance weights; equal weights when no angle uncertainty is given."""
    s = np.asarray(angle_std_rad, dtype=float)
    if np.all(s > 0):
        return 1.0 / s**2
    return np.ones_like(s)
