"""A discrete Preisach hysteresis model of the torque–angle loop, fitted by
non-negative least squares.

The angle is a weighted sum of *relays* plus an elastic part,

``θ(t) = θ₀ + c₀·τ(t) + Σⱼ μⱼ·Rⱼ(t)``,   ``μⱼ ≥ 0``, ``c₀ ≥ 0``,

where relay ``j`` with thresholds ``αⱼ > βⱼ`` switches to +1 when the torque reaches
``αⱼ`` and to −1 when it falls to ``βⱼ``, and otherwise keeps its state
(Preisach 1935; Mayergoyz, *Mathematical Models of Hysteresis*, 1991). A relay is a
Coulomb slip element seen from the torque side, so this is also the generalised
Maxwell-slip model. Relays are paired with their mirror images ``(−β, −α)`` (one
weight for the pair), which makes the loop point-symmetric, as a gear's loop is.

Why this model
--------------
- It **contains the paper's bilinear loop**: the stiffness switch is the uniform
  density ``μ = (1/k_l − 1/k_u)/(2τ_c)`` on the square ``0 < α < τ_c``,
  ``−τ_c < β < 0`` with ``c₀ = 1/k_u`` (the relays flip, one after the other, while
  ``|τ|`` rises through ``0..τ_c`` after a reversal, and stay put while it falls).
- It fits **smooth (Masing) loops** (softening after each reversal: relays spread
  along the diagonal band), and **stiffening** gears: relays with ``α = β`` are
  reversible (they flip at the same torque both ways) and give a nonlinear elastic
  curve whose compliance is largest where they sit (near zero torque for a gear that
  stiffens as more teeth come into mesh).
- For fixed thresholds the model is **linear** in the non-negative weights, so
  :func:`scipy.optimize.nnls` fits it with no starting values and a unique optimum.

Thresholds are the mid-points between the torque levels of the loop (a relay that
switches anywhere between two measured levels is the same relay for these data),
thinned to at most ``max_thresholds``, and the two extreme levels (so that a relay
switched at a reversal can flip back on the first step after it). The fit is weighted by the effective variance
``σθ² + (dθ/dτ)²·στ²`` (two passes: the compliance comes from the first fit). Its
number of parameters, for the lack-of-fit test, is the number of weights the fit
leaves positive plus ``θ₀`` (the active-set solution is an ordinary least-squares
fit in those).

What it does not do: creep, rate effects, and asymmetric loops are outside the model
(the lack-of-fit gate shows them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from ..errors import AnalysisError
from .fitcheck import LackOfFit, lack_of_fit, marginal_lack_of_fit, path_compliance

__all__ = ["PreisachFit", "fit_preisach", "preisach_response", "relay_states", "relay_thresholds", "relay_pairs",
           "torque_sensitivity", "loop_description"]


def relay_states(torque_nm, alpha_nm, beta_nm) -> np.ndarray:
    """States (±1) of relays along a torque path, shape ``(n_samples, n_relays)``.

    Before the first sample the path is taken to come **down** from its largest
    torque (the protocol starts at +Tmax after a pre-load to +Tmax): relays with
    ``α ≤ max τ`` start up, and those with ``β ≥ τ₀`` are already switched down.

    Examples
    --------
    >>> relay_states([1.0, 0.0, -1.0, 0.0, 1.0], [0.5], [-0.5])[:, 0].tolist()
    [1.0, 1.0, -1.0, -1.0, 1.0]
    """
    tau = np.asarray(torque_nm, float).reshape(-1)
    a = np.asarray(alpha_nm, float).reshape(-1)
    b = np.asarray(beta_nm, float).reshape(-1)
    path = np.concatenate([[tau.max()], tau])
    state = np.where(a <= path[0], 1.0, -1.0)
    out = np.empty((tau.size, a.size))
    for i, t in enumerate(path[1:]):
        state = np.where(t >= a, 1.0, np.where(t <= b, -1.0, state))
        out[i] = state
    return out


def relay_thresholds(tau: np.ndarray, max_thresholds: int) -> np.ndarray:
    """The relay thresholds of a torque path `tau` (N·m): the mid-points between its
    torque levels (rounded to 1e-12 N·m), thinned evenly to at most `max_thresholds`,
    and the two extreme levels; ascending (N·m)."""
    levels = np.unique(np.round(tau, 12))
    mids = 0.5 * (levels[1:] + levels[:-1])
    if mids.size > max_thresholds:
        idx = np.unique(np.round(np.linspace(0, mids.size - 1, max_thresholds)).astype(int))
        mids = mids[idx]
    # the extreme levels too: a relay that switched at the reversal and flips back on the
    # first step after it (the soft start of a Masing branch) needs them
    return np.concatenate([[levels[0]], mids, [levels[-1]]])


def relay_pairs(h: np.ndarray):
    """Symmetric relay pairs from thresholds ``h`` (N·m): arrays α, β and their mirrors
    −β, −α (N·m).

    Every ``(α, β) = (h[i], h[j])`` with ``j ≤ i`` (``j = i``: a reversible element,
    nonlinear elasticity), in that order, except a pair whose mirror ``(−β, −α)`` came
    earlier (thresholds compared rounded to 1e-12 N·m: the mirror of a mid-point is a
    mid-point up to rounding). All pairs at once: a pair's key is its (pair, mirror)
    sorted, and the first of equal keys is kept.
    """
    h = np.asarray(h, float)
    i, j = np.tril_indices(h.size)  # row-major: (0,0), (1,0), (1,1), (2,0), ...
    r = np.round(h, 12) + 0.0  # + 0.0: -0.0 is 0.0, as in a tuple key
    p = np.column_stack([r[i], r[j]])
    q = np.column_stack([-r[j], -r[i]]) + 0.0
    p_first = (p[:, 0] < q[:, 0]) | ((p[:, 0] == q[:, 0]) & (p[:, 1] <= q[:, 1]))
    key = np.where(p_first[:, None], np.hstack([p, q]), np.hstack([q, p]))
    keep = np.sort(np.unique(key, axis=0, return_index=True)[1])
    i, j = i[keep], j[keep]
    return h[i], h[j], -h[j], -h[i]


def _design(tau, a, b, am, bm):
    r = relay_states(tau, a, b)
    rm = relay_states(tau, am, bm)
    self_mirror = np.isclose(a, am) & np.isclose(b, bm)
    pair = np.where(self_mirror[None, :], r, 0.5 * (r + rm))
    return np.column_stack([np.ones_like(tau), -np.ones_like(tau), tau, pair])


@dataclass(frozen=True)
class PreisachFit:
    """Result of :func:`fit_preisach`.

    Attributes
    ----------
    alpha_nm, beta_nm, weight_rad : ndarray
        Thresholds (N·m) and weights (rad, ≥ 0) of the relays (each with its mirror
        ``(−β, −α)`` carrying the same weight).
    theta0_rad : float
        Angle offset, rad.
    elastic_compliance_rad_per_nm : float
        ``c₀`` (rad/(N·m)); ``1/c₀`` is the stiffness with every relay locked.
    residual_rad : ndarray
        Data minus model per sample, rad.
    n_params : int
        Positive weights + ``c₀`` if positive + ``θ₀``.
    check : LackOfFit
    levels_nm : ndarray
        The loop's torque levels, N·m.
    weights : ndarray
        The least-squares weights of the samples in the final fit, 1/rad².

    Only the model's loop is identified by one loop's data, not its parameters: other
    relay layouts, and ``c₀`` traded for reversible relays, fit as well (``c₀`` often
    comes out 0). :func:`loop_description` gives what the data do identify.
    """

    alpha_nm: np.ndarray
    beta_nm: np.ndarray
    weight_rad: np.ndarray
    theta0_rad: float
    elastic_compliance_rad_per_nm: float
    residual_rad: np.ndarray = field(repr=False)
    n_params: int = 0
    check: LackOfFit | None = None
    levels_nm: np.ndarray | None = field(default=None, repr=False)
    weights: np.ndarray | None = field(default=None, repr=False)

    @property
    def residual_rms_rad(self) -> float:
        return float(np.sqrt(np.mean(self.residual_rad**2)))

    @property
    def hysteretic(self) -> np.ndarray:
        """Mask of the relays with ``α > β`` (the reversible ``α = β`` ones excluded)."""
        return self.alpha_nm > self.beta_nm + 1e-12

    def predict(self, torque_nm) -> np.ndarray:
        """Model angles (rad) along a torque path that starts as the fitted one did."""
        tau = np.asarray(torque_nm, float).reshape(-1)
        a, b = self.alpha_nm, self.beta_nm
        am, bm = -b, -a
        x = _design(tau, a, b, am, bm)
        coef = np.concatenate(
            [
                [max(self.theta0_rad, 0.0), max(-self.theta0_rad, 0.0), self.elastic_compliance_rad_per_nm],
                self.weight_rad,
            ]
        )
        return x @ coef


    def active_design(self, torque_nm) -> np.ndarray:
        """d(model angles)/d(the fit's free parameters) along a torque path, shape ``(n, p)``.

        The columns of the parameters the fit left free (``θ₀``, ``c₀`` when positive, the
        positive weights): for fixed thresholds the model is linear, and the non-negative
        fit is an ordinary least-squares fit in its active set (its ``n_params``).
        """
        tau = np.asarray(torque_nm, float).reshape(-1)
        x = _design(tau, self.alpha_nm, self.beta_nm, -self.beta_nm, -self.alpha_nm)
        active = np.concatenate([[self.elastic_compliance_rad_per_nm > 0], self.weight_rad > 0])
        return np.column_stack([x[:, 0], x[:, 2:][:, active]])


def preisach_response(
    torque_nm, *, alpha_nm, beta_nm, weight_rad, elastic_compliance_rad_per_nm, theta0_rad=0.0
) -> np.ndarray:
    """Angles (rad) of a symmetric discrete Preisach model along a torque path (see the module notes)."""
    fit = PreisachFit(
        np.asarray(alpha_nm, float),
        np.asarray(beta_nm, float),
        np.asarray(weight_rad, float),
        float(theta0_rad),
        float(elastic_compliance_rad_per_nm),
        np.zeros(1),
    )
    return fit.predict(torque_nm)


def _tips(tau: np.ndarray) -> list:
    """Indices of the path's reversals, the first sample included (the path comes down from its top)."""
    d = np.sign(np.diff(tau))
    tips = [0]
    last = d[0] if d.size else 0.0
    for i in range(1, d.size):
        if d[i] == 0:
            continue
        if last != 0 and d[i] != last:
            tips.append(i)
        last = d[i]
    return tips


def torque_sensitivity(torque_nm, model_angle_rad) -> np.ndarray:
    """``A`` with ``δθ ≈ A·δτ`` (rad per N·m, (n, n)): how a model's angles answer torque errors
    along a hysteretic path, the loop's **tips** included.

    Each sample answers its own torque with the model's local compliance (the branch's
    secant slope, :func:`.fitcheck.path_compliance`; a tip along the branch that arrived
    there). A branch after a reversal remembers the reversal (the Masing rule, as
    :func:`.uncertainty.tip_amplitude_response` states it): a tip torque wrong by ``δ_t``
    moves the branch at a sample of slope ``s`` by ``S·δ_t``, ``S = clip(s_arr − s, 0, h)``
    (``s_arr`` the slope arriving at the tip, ``h = s_arr − s_dep`` the hysteretic part
    that switches there); a tip moved by earlier tips carries that shift to its whole
    branch. The first sample is a tip (the path comes down from its top); its arriving
    slope is that of the last segment arriving at the same torque from below.
    """
    tau = np.asarray(torque_nm, float).reshape(-1)
    th = np.asarray(model_angle_rad, float).reshape(-1)
    n = tau.size
    comp = path_compliance(tau, th)
    dt, dth = np.diff(tau), np.diff(th)
    with np.errstate(divide="ignore", invalid="ignore"):
        seg = np.where(dt != 0, np.abs(dth / dt), np.nan)
    tips = _tips(tau)
    a = np.zeros((n, n))
    shift = np.zeros(n)  # the current branch's translation by earlier tips' errors (a row of A)
    for j, t in enumerate(tips):
        if t == 0:
            back = np.flatnonzero((np.abs(tau[1:] - tau[0]) <= 1e-12 * max(abs(tau[0]), 1.0)) & (dt > 0))
            s_arr = float(seg[back[-1]]) if back.size else np.nan
        else:
            s_arr = float(seg[t - 1])
        s_dep = float(seg[t]) if t < n - 1 else np.nan
        end = tips[j + 1] if j + 1 < len(tips) else n - 1
        tip_shift = shift.copy()
        if np.isfinite(s_arr):
            comp[t] = s_arr
        h = s_arr - s_dep
        for i in range(t + 1, end + 1):
            a[i] += tip_shift
            if np.isfinite(h) and h > 0:
                a[i, t] += float(np.clip(s_arr - comp[i], 0.0, h))
        shift = a[end].copy()
    a[np.arange(n), np.arange(n)] += comp
    return a


def fit_preisach(
    torque_nm, angle_rad, *, angle_std_rad, torque_std_nm, max_thresholds=64, torque_sources=None
) -> PreisachFit:
    """Fit the symmetric discrete Preisach model to one loop by non-negative least squares.

    Parameters
    ----------
    torque_nm, angle_rad : array_like (n,)
        Samples in acquisition order (N·m, rad), starting on the way down from the
        loop's largest torque (as the protocol does).
    angle_std_rad, torque_std_nm : array_like (n,)
        1σ per sample (rad; N·m, image-to-image part) for the weights and the
        lack-of-fit test.
    max_thresholds : int
        Most relay thresholds (mid-points between torque levels) used.
    torque_sources : array_like (n, m), optional
        Loading matrix of the image-to-image torque errors (N·m per unit source). The
        gate's noise is then each angle's marginal σ from :func:`torque_sensitivity`
        and these sources (its own torque error and those of the loop tips its branch
        remembers), and the marginal χ²'s null distribution is calibrated for their
        correlations (:func:`.fitcheck.marginal_lack_of_fit`). Without it,
        ``torque_std_nm`` through the local compliance.

    Returns
    -------
    PreisachFit
        With its :class:`.fitcheck.LackOfFit` in ``check``.

    Raises
    ------
    AnalysisError
        Fewer than 6 samples, torque of one sign only, non-finite data, or a sample
        without a positive uncertainty.

    Examples
    --------
    >>> import numpy as np
    >>> from vision_torsion.analysis.models import bilinear_response
    >>> tau = np.concatenate([np.linspace(0.36, -0.36, 37), np.linspace(-0.34, 0.36, 36)])
    >>> th = bilinear_response(tau, k_u=4.4, k_l=0.3, tau_c=0.15)
    >>> f = fit_preisach(tau, th, angle_std_rad=1e-5, torque_std_nm=0.0)
    >>> bool(f.residual_rms_rad < 1e-6), f.check.rejected
    (True, False)
    """
    tau = np.asarray(torque_nm, float).reshape(-1)
    th = np.asarray(angle_rad, float).reshape(-1)
    sa = np.broadcast_to(np.asarray(angle_std_rad, float), tau.shape)
    st = np.broadcast_to(np.asarray(torque_std_nm, float), tau.shape)
    if tau.size < 6:
        raise AnalysisError(f"Preisach fit needs at least 6 samples, got {tau.size}")
    if not (np.all(np.isfinite(tau)) and np.all(np.isfinite(th))):
        raise AnalysisError("Preisach fit: a torque or angle is not a finite number")
    if not (tau.max() > 0 > tau.min()):
        raise AnalysisError("Preisach fit needs torque of both signs (the torque never reverses)")
    if not np.all(sa > 0):
        raise AnalysisError("Preisach fit needs a positive angle uncertainty for every sample")
    h = relay_thresholds(tau, max_thresholds)
    a, b, am, bm = relay_pairs(h)
    x = _design(tau, a, b, am, bm)
    scale = np.linalg.norm(x, axis=0)
    scale[scale == 0] = 1.0
    var = sa**2
    for _ in range(2):
        w_fit = 1.0 / var
        sw = np.sqrt(w_fit)
        coef, _ = optimize.nnls((x / scale) * sw[:, None], th * sw, maxiter=50 * x.shape[1])
        coef = coef / scale
        model = x @ coef
        comp = path_compliance(tau, model)
        var = sa**2 + (comp * st) ** 2
    resid = th - model
    n_pos = int(np.sum(coef[2:] > 0)) + 1
    # the marginal (diagonal) statistic, not rᵀS⁺r of the weight pieces' correlations: the NNLS active set
    # is picked by the data, and the projected χ² of the correlated model then reads about 2 on exact loops
    # (found on simulated bilinear sessions). With the sources, each angle's marginal σ holds its own torque
    # error and those of the tips its branch remembers, and the statistic's null distribution is calibrated
    # for their correlations (marginal_lack_of_fit)
    if torque_sources is not None:
        src = np.asarray(torque_sources, float).reshape(tau.size, -1)
        active = np.concatenate([[True, False], coef[2:] > 0])
        check = marginal_lack_of_fit(resid, angle_std_rad=sa, torque_sources=torque_sensitivity(tau, model) @ src,
                                     jacobian=x[:, active], weights=w_fit, n_params=n_pos)
    else:
        check = lack_of_fit(resid, angle_std_rad=sa, torque_std_nm=st, compliance_rad_per_nm=comp, n_params=n_pos)
    return PreisachFit(
        alpha_nm=a,
        beta_nm=b,
        weight_rad=coef[3:],
        theta0_rad=float(coef[0] - coef[1]),
        elastic_compliance_rad_per_nm=float(coef[2]),
        residual_rad=resid,
        n_params=n_pos,
        check=check,
        levels_nm=np.unique(np.round(tau, 12)),
        weights=w_fit,
    )


def loop_description(fit: PreisachFit, torque_nm, *, angle_std_rad, torque_sources=None) -> dict:
    """The numbers one loop identifies in its Preisach fit.

    The relay weights, thresholds and ``c₀`` are not identified (see :class:`PreisachFit`);
    the model's values at the measured levels are, and so is every number that depends on
    them alone:

    - ``loop_energy_j``: the model's ``∮τ dθ`` over the fitted major loop, ``Σ 2·μⱼ·(αⱼ − βⱼ)``
      over the hysteretic relays (each switches up at α and down at β once a cycle; the
      elastic part and the reversible relays close on themselves) — the integral of the
      dissipation distribution. No 1σ is given for it: its scatter is set by the fit's
      non-negativity (which relays the noise leaves active), which a first-order
      propagation misses; compare it with the loop's measured ``loop_energy`` figure;
    - ``reversal_stiffness_nm_per_rad``: the model's stiffness over the first level step
      after the reversal at the loop's top (the elastic slope at reversal, as the levels
      resolve it; the model is point-symmetric, so the bottom reversal has the same), with
      ``_std_angle`` and ``_std_torque``, its 1σ parts from the angle noise and the
      torque errors.

    Parameters
    ----------
    fit : PreisachFit
        The fit of the loop (its ``weights`` set, as :func:`fit_preisach` leaves them).
    torque_nm : array_like (n,)
        The loop's torque path the fit was made on (N·m), coming down from its top.
    angle_std_rad : array_like (n,)
        1σ of each angle (rad).
    torque_sources : array_like (n, m), optional
        Loading matrix of the image-to-image torque errors (N·m per unit source), carried
        to the angles by :func:`torque_sensitivity`; without it the torque part is NaN.

    Returns
    -------
    dict
        ``loop_energy_j``, ``reversal_stiffness_nm_per_rad`` and its ``_std_angle``,
        ``_std_torque`` (NaN when the path has no step after its top).

    Notes
    -----
    For its active set the non-negative fit is a weighted linear least-squares fit, so the
    model's step ``Δθ̂`` after the reversal is a linear function ``sᵀθ`` of the angles
    (through the pseudo-inverse: it is estimable though the parameters are not), and
    ``σ_k = k²·σ_Δθ̂/|Δτ|`` for ``k = Δτ/Δθ̂``; the active set is held fixed.

    Examples
    --------
    >>> import numpy as np
    >>> from vision_torsion.analysis.models import bilinear_response
    >>> path = np.concatenate([np.linspace(0.3, -0.3, 31), np.linspace(-0.28, 0.3, 30)])  # N·m, 0.02 apart
    >>> fit = fit_preisach(path, bilinear_response(path, k_u=4.4, k_l=0.3, tau_c=0.15), angle_std_rad=1e-5,
    ...                    torque_std_nm=0.0)
    >>> d = loop_description(fit, path, angle_std_rad=1e-5)
    >>> round(d["reversal_stiffness_nm_per_rad"], 3)  # k_u: the bilinear loop is stiff after a reversal
    4.4
    >>> round(d["loop_energy_j"], 3)  # (1/k_l − 1/k_u)·τ_c² = 0.0699 J, up to the levels' spacing
    0.07
    """
    tau = np.asarray(torque_nm, float).reshape(-1)
    sa = np.broadcast_to(np.asarray(angle_std_rad, float), tau.shape)
    per_weight = np.where(fit.hysteretic, 2.0 * (fit.alpha_nm - fit.beta_nm), 0.0)
    out = {"loop_energy_j": float(np.sum(per_weight * fit.weight_rad)), "reversal_stiffness_nm_per_rad": math.nan,
           "reversal_stiffness_nm_per_rad_std_angle": math.nan, "reversal_stiffness_nm_per_rad_std_torque": math.nan}
    a = int(np.argmax(tau))
    model = fit.predict(tau)
    if a + 1 >= tau.size or model[a + 1] == model[a]:
        return out
    j = fit.active_design(tau)
    w = fit.weights if fit.weights is not None else 1.0 / sa**2
    solve = np.linalg.pinv(j.T @ (j * w[:, None])) @ (j * w[:, None]).T  # active coefficients = solve @ θ
    d_tau = tau[a + 1] - tau[a]
    k = d_tau / (model[a + 1] - model[a])
    sens = (k * k / abs(d_tau)) * ((j[a + 1] - j[a]) @ solve)
    out["reversal_stiffness_nm_per_rad"] = float(k)
    out["reversal_stiffness_nm_per_rad_std_angle"] = float(np.sqrt(np.sum((sens * sa) ** 2)))
    if torque_sources is not None:
        carried = torque_sensitivity(tau, model) @ np.asarray(torque_sources, float).reshape(tau.size, -1)
        out["reversal_stiffness_nm_per_rad_std_torque"] = float(np.sqrt(np.sum((sens @ carried) ** 2)))
    return out
