"""Torque–angle tables with exact truth, written for the figures benchmark (issue 14).

Independent of ``vision_torsion.analysis``: the loops, the weights, the protocol and
the truth of every figure are computed here from first principles, so the benchmark
checks the analysis against something it does not share code with.

The rig: a force couple of weight pieces (``STEP_MASS_KG`` each, true masses drawn
once per session within ±0.1 g, uniform), ``R_M`` arm radius, ``G`` gravity; the
paper's protocol (``N_STEPS`` steps of one piece per pan per phase, four phases per
cycle, a reference image, a closing zero-torque image per orientation). Torques in
the table are nominal, with the 1σ of the pieces; the angles respond to the **true**
torques.

Loops (angle as a function of the torque path, rad, N·m):

- ``bilinear``: the paper's stiffness switch (k_u, k_l, τ_c);
- ``three_segment``: a reversible stiffening curve with K1, K2, K3 at T1, T2, plus a
  play-operator hysteresis of width ``W < T`` (so the loading branches from zero are
  the elastic curve, shifted: K1–K3 are exact there);
- ``masing``: a smooth Masing loop (softening after each reversal, twice-scaled virgin
  curve ``θ = τ/k₀ + a·(|τ|/s − ln(1 + |τ|/s))·sign τ``).

Two truths are given for a loop. :func:`loop_truth` evaluates the figures' own
definitions on the model sampled at the nominal levels (the issue-14 benchmark).
:func:`physical_truth` is the **physical** quantity of the continuous loop (issue 27):
``∮τ dθ`` integrated over the continuous loop, lost motion at exactly ``±x·T_R`` on the
continuous branches, the generating break torques and stiffnesses. A coarser rig
(:class:`Rig`: heavier pieces, fewer steps to the same maximum torque) is an option of
:func:`session_table`.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

STEP_MASS_KG = 0.02
R_M = 0.05
G = 9.81
N_STEPS = 18
MASS_TOL_KG = 1e-4
MASS_STD_KG = MASS_TOL_KG / math.sqrt(3)
T_MAX = 2 * N_STEPS * STEP_MASS_KG * G * R_M
PHASES = ("positive_unloading", "negative_loading", "negative_unloading", "positive_loading")


# ------------------------------------------------------------------ loop models ---
class Bilinear:
    def __init__(self, k_u=4.4, k_l=0.3, tau_c=0.15):
        self.k_u, self.k_l, self.tau_c = k_u, k_l, tau_c

    def path(self, tau):
        """Angles along a torque path (each step monotone), from θ = 0 at the start.

        Each step is stiff (1/k_u) except the part where |τ| rises below τ_c: on a rising
        step the part of it in ``[0, τ_c]``, on a falling one the part in ``[−τ_c, 0]``
        (the same arithmetic as :meth:`_step`, all steps at once)."""
        tau = np.asarray(tau, float)
        a, b = tau[:-1], tau[1:]
        soft = np.where(
            b > a,
            np.clip(np.minimum(b, self.tau_c) - np.maximum(a, 0.0), 0.0, None),
            -np.clip(np.minimum(a, 0.0) - np.maximum(b, -self.tau_c), 0.0, None),
        )
        d = (b - a) / self.k_u + soft * (1.0 / self.k_l - 1.0 / self.k_u)
        return np.concatenate([[0.0], np.cumsum(d)])

    def _step(self, a, b):
        """One monotone step's angle by splitting it at 0 and ±τ_c (the reference :meth:`path` is checked
        against)."""
        # split at 0 and ±τ_c; loading (|τ| rising) below τ_c is soft
        cuts = sorted({a, b, *[c for c in (0.0, self.tau_c, -self.tau_c) if min(a, b) < c < max(a, b)]})
        if b < a:
            cuts = cuts[::-1]
        d = 0.0
        for x, y in zip(cuts[:-1], cuts[1:]):
            mid = 0.5 * (x + y)
            rising = abs(y) > abs(x)
            soft = rising and abs(mid) < self.tau_c
            d += (y - x) / (self.k_l if soft else self.k_u)
        return d


class ThreeSegment:
    def __init__(self, k=(1.0, 2.5, 4.0), t=(0.1, 0.25), width=0.1, c_h=1.0):
        self.k, self.t, self.width, self.c_h = k, t, width, c_h

    def elastic(self, tau):
        x = np.abs(tau)
        k1, k2, k3 = self.k
        t1, t2 = self.t
        h = np.minimum(x, t1) / k1 + np.clip(x - t1, 0, t2 - t1) / k2 + np.maximum(x - t2, 0) / k3
        return np.sign(tau) * h

    def path(self, tau):
        """Angles along a torque path: the elastic curve less ``c_h·(τ − p)``, ``p`` the play operator's output.

        ``τ − p`` is +W/2 once a loading has closed the play and −W/2 after an unloading,
        so the angle lags the torque: at a given torque the descending branch lies above
        the ascending one, and the loop runs anticlockwise with ``∮τ dθ > 0`` (a passive
        gear's dissipation), as the analysis' loop-direction check expects."""
        half = self.width / 2
        p = tau[0] - half  # arrived at the start from below (a loading to +Tmax)
        z = []
        for t in tau:
            p = max(t - half, min(t + half, p))
            z.append(t - p)
        return self.elastic(np.asarray(tau)) - self.c_h * np.array(z)


class Masing:
    def __init__(self, k0=4.4, a=0.4, s=0.05):
        self.k0, self.a, self.s = k0, a, s

    def virgin(self, x):
        u = np.abs(x) / self.s
        return x / self.k0 + self.a * (u - np.log1p(u)) * np.sign(x)

    def path(self, tau):
        top = float(np.max(np.abs(tau)))
        rev, th_rev, d = top, float(self.virgin(top)), -1.0  # on the major loop, coming down from +Tmax
        out, prev = [], tau[0]
        # the start sample tau[0] lies on the descending major branch
        th_rev = float(self.virgin(top))
        for t in tau:
            s = np.sign(t - prev)
            if s != 0 and s != d:
                rev, th_rev, d = prev, out[-1], s
            out.append(th_rev + 2 * float(self.virgin((t - rev) / 2)))
            prev = t
        return np.array(out)


def make_model(kind, scale=1.0):
    """A loop model; ``scale`` multiplies every stiffness (orientation / cycle effects)."""
    if kind == "bilinear":
        return Bilinear(k_u=4.4 * scale, k_l=0.3 * scale)
    if kind == "three_segment":
        return ThreeSegment(k=(1.0 * scale, 2.5 * scale, 4.0 * scale))
    if kind == "masing":
        return Masing(k0=4.4 * scale, a=0.4 / scale)
    raise ValueError(kind)


# ------------------------------------------------------------------ protocol ---
class Rig:
    """A weight-piece rig: ``step_mass_kg`` per piece, ``n_steps`` pieces per pan at the top.

    The default is the module's rig (0.02 kg, 18 steps, levels 0.0196 N·m apart);
    ``Rig.coarse()`` reaches about the same maximum torque in 9 steps of 0.04 kg
    (levels 0.039 N·m apart: no level between 0 and ±0.04 N·m).
    """

    def __init__(self, step_mass_kg=STEP_MASS_KG, n_steps=N_STEPS):
        self.step_mass_kg, self.n_steps = step_mass_kg, n_steps

    @classmethod
    def coarse(cls):
        return cls(step_mass_kg=0.04, n_steps=9)

    @property
    def t_max(self):
        return 2 * self.n_steps * self.step_mass_kg * G * R_M

    def levels(self):
        """Nominal torque magnitudes, N·m (0 to t_max)."""
        return np.array([2 * n * self.step_mass_kg * G * R_M for n in range(self.n_steps + 1)])

    def as_analysis_rig(self):
        return dict(step_mass_kg=self.step_mass_kg, mass_std_kg=MASS_STD_KG, gravity_m_per_s2=G, arm_radius_m=R_M)


def protocol(cycles, n_steps=N_STEPS):
    """Rows (phase, cycle, step, pieces per pan, sign) of one orientation, in order."""
    rows = [("reference", 0, 0, 0, 0)]
    for c in range(1, cycles + 1):
        if c == 1:
            rows.append(("positive_unloading", c, 0, n_steps, 1))
        for k in range(1, n_steps + 1):
            rows.append(("positive_unloading", c, k, n_steps - k, 1))
        for k in range(1, n_steps + 1):
            rows.append(("negative_loading", c, k, k, -1))
        for k in range(1, n_steps + 1):
            rows.append(("negative_unloading", c, k, n_steps - k, -1))
        for k in range(1, n_steps + 1):
            rows.append(("positive_loading", c, k, k, 1))
    rows.append(("closing", cycles, 0, 0, 0))
    return rows


def piece_masses(rng, rig=None):
    """The session's true piece masses (kg), ``(4, n_steps)``: pans +A, +B, −A, −B; the
    first draw of :func:`session_table` from its ``rng``."""
    rig = rig or Rig()
    return rig.step_mass_kg + rng.uniform(-MASS_TOL_KG, MASS_TOL_KG, (4, rig.n_steps))


#: 1σ of a loop tip's torque (N·m): the 2·N_STEPS pieces of one sign's pans.
TIP_STD_NM = G * R_M * math.sqrt(2 * N_STEPS) * MASS_STD_KG


def tip_errors_nm(pieces):
    """True minus nominal torque (N·m) at the +Tmax and −Tmax tips (magnitudes) from
    :func:`piece_masses`: the weight error every figure of a session shares."""
    nominal = 2 * N_STEPS * STEP_MASS_KG
    return G * R_M * (float(pieces[:2].sum()) - nominal), G * R_M * (float(pieces[2:].sum()) - nominal)


def session_table(
    kind,
    *,
    orientations=(0, 60, 120, 180, 240, 300),
    cycles=1,
    angle_std_deg=0.0005,
    orientation_effect=0.0,
    repeatability=0.02,
    creep_deg=0.0,
    fail=None,
    rig=None,
    rated_nm=None,
    rng,
):
    """A measurements table and the truth of every loop.

    Returns
    -------
    table : pandas.DataFrame
        ``measurements.csv`` columns.
    truth : dict
        ``{(orientation, cycle): {figure: value}}`` from the noise-free model on the
        nominal path, with the loop's own stiffness scale; with ``rated_nm`` (T_R,
        N·m) the :func:`figure_truth` instead: the continuous loop's physical values
        (lost motion at ±3 %, ±4 % of T_R) where the figure has one.
    """
    rig = rig or Rig()
    pieces = piece_masses(rng, rig)
    rows, truth = [], {}
    proto = protocol(cycles, rig.n_steps)
    n_steps, step_mass = rig.n_steps, rig.step_mass_kg
    for o in orientations:
        o_scale = 1.0 + orientation_effect * math.cos(math.radians(o))
        tau_nom, tau_true, meta = [], [], []
        for phase, c, step, n, s in proto:
            pans = pieces[:2] if s > 0 else pieces[2:]
            m_true = float(pans[:, :n].sum()) if n else 0.0
            tau_true.append(s * G * R_M * m_true)
            tau_nom.append(s * 2 * n * step_mass * G * R_M)
            meta.append((phase, c, step, n))
        tau_nom, tau_true = np.array(tau_nom), np.array(tau_true)
        theta = np.zeros(tau_nom.size)
        scales = {c: o_scale * (1.0 + repeatability * rng.standard_normal()) for c in range(1, cycles + 1)}
        # each cycle responds with its own stiffness scale; the path is continuous
        idx_loop = [i for i, m in enumerate(meta) if m[0] not in ("reference", "closing")]
        for c in range(1, cycles + 1):
            ii = [i for i in idx_loop if meta[i][1] == c]
            if c > 1:
                ii = [ii[0] - 1] + ii  # the cycle starts at the previous one's +Tmax
            model = make_model(kind, scales[c])
            warm = np.concatenate([tau_true[ii], tau_true[ii][1:]])  # one cycle to reach the periodic state
            th = model.path(warm)[len(ii) - 1 :]
            th = th - th[0]
            base = theta[ii[0]] if c > 1 else 0.0
            theta[ii] = base + th
            truth[(float(o), c)] = (
                loop_truth(kind, model) if rated_nm is None else figure_truth(kind, model, rig=rig, rated_nm=rated_nm)
            )
        i_close = len(meta) - 1
        i_zero = [i for i, m in enumerate(meta) if m[0] == "positive_unloading" and m[1] == 1 and m[2] == n_steps][0]
        theta[i_close] = theta[i_zero]  # the same load state (zero, unloaded from +Tmax)
        theta[0] = theta[i_zero]  # the reference: no weights
        t_frac = np.linspace(0.0, 1.0, theta.size)
        theta_deg = np.degrees(theta) + creep_deg * t_frac + rng.normal(0.0, angle_std_deg, theta.size)
        theta_deg -= theta_deg[0]
        for i, (phase, c, step, n) in enumerate(meta):
            rows.append(
                {
                    "image": f"o{o:03d}_{i:04d}.png",
                    "orientation_deg": float(o),
                    "cycle": c,
                    "phase": phase,
                    "step": step,
                    "mass_kg": n * step_mass,
                    "torque_nm": tau_nom[i],
                    "torque_std_nm": G * R_M * math.sqrt(2 * n) * MASS_STD_KG,
                    "angle_deg": theta_deg[i],
                    "angle_std_deg": angle_std_deg,
                    "status": "ok",
                    "message": "",
                }
            )
    df = pd.DataFrame(rows)
    if fail == "zero":  # the zero-torque image after the first unloading, first orientation
        m = (df.orientation_deg == orientations[0]) & (df.phase == "positive_unloading") & (df.step == n_steps)
        df.loc[m, ["status", "message"]] = ["failed", "marker not found"]
    elif fail == "half_phase":  # the upper half of positive loading, first orientation
        m = (df.orientation_deg == orientations[0]) & (df.phase == "positive_loading") & (df.step > n_steps // 2)
        df.loc[m, ["status", "message"]] = ["failed", "marker not found"]
    return df, truth


# ------------------------------------------------------------------ truth ---
def _major_branches(model):
    """Noise-free descending and ascending runs on the nominal levels, in the periodic state."""
    lv = np.array([2 * n * STEP_MASS_KG * G * R_M for n in range(N_STEPS + 1)])
    levels = np.concatenate([-lv[::-1], lv[1:]])
    down = levels[::-1]
    up = levels[1:]
    path = np.concatenate([down, up, down[1:], up])  # warm-up cycle, then the measured one
    th = model.path(path)
    n = down.size + up.size
    cyc = th[n:]
    tau = path[n:]
    nd = down.size - 1  # the measured cycle: down[1:] then up
    desc = (np.concatenate([[down[0]], tau[:nd]]), np.concatenate([[th[n - 1]], cyc[:nd]]))
    asc = (np.concatenate([[down[-1]], tau[nd:]]), np.concatenate([[cyc[nd - 1]], cyc[nd:]]))
    return desc, asc


def _interp(tau, th, x):
    o = np.argsort(tau)
    return float(np.interp(x, np.asarray(tau)[o], np.asarray(th)[o]))


def loop_truth(kind, model) -> dict:
    """Every checked figure of one loop, from the model on the nominal levels (the figures' definitions)."""
    (td, yd), (ta, ya) = _major_branches(model)
    grid = np.unique(np.concatenate([td, ta]))
    w = np.array([_interp(td, yd, x) - _interp(ta, ya, x) for x in grid])
    out = {
        "hysteresis": math.degrees(float(np.max(np.abs(w)))),
        "hysteresis_loss": math.degrees(_interp(td, yd, 0.0) - _interp(ta, ya, 0.0)),
    }
    for f in (0.03, 0.04):
        x = f * T_MAX
        mid = lambda t: 0.5 * (_interp(td, yd, t) + _interp(ta, ya, t))  # noqa: E731
        out[f"lost_motion_{round(f * 100)}pct"] = math.degrees(mid(x) - mid(-x))
    lo, hi = 0.5 * T_MAX, T_MAX
    dpos = _interp(ta, ya, hi) - _interp(ta, ya, lo)
    dneg = _interp(td, yd, -lo) - _interp(td, yd, -hi)
    out["secant_stiffness"] = (hi - lo) / (0.5 * (dpos + dneg))
    tau_c = np.concatenate([td, ta[1:], [td[0]]])
    th_c = np.concatenate([yd, ya[1:], [yd[0]]])
    out["loop_energy"] = float(np.sum(0.5 * (tau_c[1:] + tau_c[:-1]) * np.diff(th_c)))
    # phase secants (ends of each phase)
    out["k_positive_unloading_secant"] = T_MAX / (yd[0] - _interp(td, yd, 0.0))
    out["k_negative_loading_secant"] = T_MAX / (_interp(td, yd, 0.0) - yd[-1])
    out["k_negative_unloading_secant"] = T_MAX / (_interp(ta, ya, 0.0) - ya[0])
    out["k_positive_loading_secant"] = T_MAX / (ya[-1] - _interp(ta, ya, 0.0))
    if kind == "bilinear":
        out.update(
            bilinear_k_u=model.k_u,
            bilinear_k_l=model.k_l,
            bilinear_tau_c=model.tau_c,
            k_positive_unloading=model.k_u,
            k_negative_unloading=model.k_u,
            k_negative_loading_below=model.k_l,
            k_negative_loading_above=model.k_u,
            k_positive_loading_below=model.k_l,
            k_positive_loading_above=model.k_u,
        )
    if kind == "three_segment":
        out.update(k1=model.k[0], k2=model.k[1], k3=model.k[2])
    return out


# ------------------------------------------------------------------ physical truth ---
#: Points per run of the dense path of :func:`physical_truth`.
DENSE_POINTS = 20001


def _dense_loop(model, t_max, extra=()):
    """The periodic major loop between ±t_max on a dense torque path (with ``extra`` torques on it exactly):
    ``(desc, asc)``, each ``(tau, theta)`` sorted by increasing torque."""
    grid = np.unique(np.concatenate([np.linspace(-t_max, t_max, DENSE_POINTS), np.asarray(extra, float)]))
    down, up = grid[::-1], grid[1:]
    path = np.concatenate([down, up, down[1:], up])  # a warm-up cycle, then the measured one
    th = model.path(path)
    n = down.size + up.size
    d = slice(n - 1, n - 1 + down.size)
    a = slice(n - 2 + down.size, 2 * n - 1)
    return (path[d][::-1], th[d][::-1]), (path[a], th[a])


def physical_truth(kind, model, *, rig=None, rated_nm) -> dict:
    """The physical figures of the continuous loop between ±Tmax of ``rig`` (issue 27).

    - ``loop_energy``: ``∮τ dθ`` = the area between the branches, trapezoids on
      :data:`DENSE_POINTS` points per run (error below 1e-6 of the value: the
      trapezoid error falls as the step², here ~3e3× smaller than the levels');
    - ``loss_factor``: that energy over ``2π·½·Tmax·θ_a`` (θ_a half the tip-to-tip
      angle), the definition's own form;
    - ``lost_motion_{3,4}pct``: the branches' mid-point at exactly ``±x·T_R`` (the
      torques are points of the dense path);
    - ``hysteresis_loss``: the width at zero torque;
    - ``k1..k3``, ``t1``, ``t2``: the generating loading curve (bilinear: K1 = k_l
      below T1 = τ_c, K2 = k_u; three-segment: K1–K3 at T1, T2); none for Masing.
    """
    rig = rig or Rig()
    t_max = rig.t_max
    xs = [f * rated_nm for f in (0.03, 0.04)]
    (td, yd), (ta, ya) = _dense_loop(model, t_max, extra=[0.0, *xs, *(-x for x in xs)])
    energy = float(np.trapezoid(yd, td) - np.trapezoid(ya, ta))
    theta_a = 0.5 * (yd[-1] - yd[0])
    out = {
        "loop_energy": energy,
        "loss_factor": energy / (2 * math.pi * 0.5 * t_max * theta_a),
        "hysteresis_loss": math.degrees(_interp(td, yd, 0.0) - _interp(ta, ya, 0.0)),
    }
    for f, x in zip((0.03, 0.04), xs):
        mid = lambda t: 0.5 * (_interp(td, yd, t) + _interp(ta, ya, t))  # noqa: E731
        out[f"lost_motion_{round(f * 100)}pct"] = math.degrees(mid(x) - mid(-x))
    if kind == "bilinear":
        out.update(k1=model.k_l, k2=model.k_u, t1=model.tau_c, bilinear_k_u=model.k_u, bilinear_k_l=model.k_l,
                   bilinear_tau_c=model.tau_c)
    if kind == "three_segment":
        out.update(k1=model.k[0], k2=model.k[1], k3=model.k[2], t1=model.t[0], t2=model.t[1])
    return out


def figure_truth(kind, model, *, rig=None, rated_nm) -> dict:
    """The truth every checked figure is scored against: physical wherever the figure has a physical value.

    :func:`physical_truth` (the continuous loop) for the loop energy, loss factor, lost
    motion, the width at zero torque and the generating K1–K3, T1/T2. The other figures
    of :func:`loop_truth` are evaluated at measured levels only, where the continuous
    loop and the sampled one agree (the secant stiffness between the levels ½·Tmax and
    Tmax, the phase secants from a tip to zero, the bilinear and phase stiffnesses: the
    generating slopes), or are defined by the measured levels (``hysteresis``, the
    largest width among them, flagged by the analysis where a flat-topped loop biases
    it): those keep :func:`loop_truth`. With another rig than the module's (whose levels
    :func:`loop_truth` assumes) only the physical figures are given.
    """
    rig = rig or Rig()
    phys = physical_truth(kind, model, rig=rig, rated_nm=rated_nm)
    if (rig.step_mass_kg, rig.n_steps) != (STEP_MASS_KG, N_STEPS):
        return phys
    return {**loop_truth(kind, model), **phys}
