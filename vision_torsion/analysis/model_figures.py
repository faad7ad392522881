"""Figure family: the models of a loop, each fitted to the whole loop and gated — the paper's
bilinear stiffness switch (k_u, k_l, τ_c), the Preisach / Maxwell-slip description
(:mod:`.preisach`), and optionally the Bouc–Wen model.

Model parameters keep a meaning when a model is only approximately right, so a model
that fails its lack-of-fit gate is shown **flagged**, its uncertainty multiplied by
``√χ²_red``; a Bouc–Wen parameter on its bound is flagged without an uncertainty. The
Preisach model is shown as a description of the loop: its residual, not its relays.
The fits also serve the outlier check (:mod:`.data_checks`).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import AnalysisError
from ..numerics import numeric_jacobian
from .fitcheck import lack_of_fit, path_compliance, side_compliance
from .loops import Loop
from .models import BilinearFit, BoucWenFit, fit_bilinear, fit_bouc_wen
from .parameters import AnalysisOptions
from .preisach import fit_preisach
from .rows import FigureRows
from .uncertainty import least_squares_weights

__all__ = ["model_figures", "no_fits", "bilinear_jacobian", "BILINEAR_UNITS"]

#: The bilinear model's parameters, figure name → unit.
BILINEAR_UNITS = {"bilinear_k_u": "nm_per_rad", "bilinear_k_l": "nm_per_rad", "bilinear_tau_c": "nm"}


def no_fits() -> dict:
    """The fits of a loop that has none (the layout :func:`model_figures` returns)."""
    return {"bilinear": None, "bouc_wen": None, "preisach": None, "checks": {}}

_BW_UNITS = {
    "k_e": ("nm_per_rad", 1.0),
    "z_s": ("deg", 180 / math.pi),
    "a": ("per_nm", 1.0),
    "rho": ("1", 1.0),
    "n": ("1", 1.0),
}
_BW_BOUNDS = {"rho": (1e-12, 0.5), "n": (0.3, 40.0)}


def bilinear_jacobian(bil: BilinearFit, tau: np.ndarray) -> np.ndarray:
    """d(model)/d(θ₀, c_u, c_l, τ_c) of a bilinear fit along the torque path (central differences)."""
    from .models import bilinear_response

    p = np.array([bil.theta0_rad, 1 / bil.k_u_nm_per_rad, 1 / bil.k_l_nm_per_rad, bil.tau_c_nm])

    def f(q):
        return bilinear_response(tau, k_u=1 / q[1], k_l=1 / q[2], tau_c=q[3], theta_start=q[0])

    amp = float(np.max(np.abs(tau)))
    return numeric_jacobian(f, p, np.array([1e-6, p[1] * 1e-6, p[2] * 1e-6, amp * 1e-7]))


def _model_check(loop, model: np.ndarray, torque_std_nm, *, n_params: int, compliance=None, **options):
    """Lack-of-fit test of a model of `loop` (its angle, rad, along the loop's torque path):
    the residual, the model's compliance (``compliance``, else its path compliance) and the loop's
    own torque sources."""
    return lack_of_fit(
        loop.angle_rad - model,
        angle_std_rad=loop.angle_std_rad,
        torque_std_nm=torque_std_nm,
        compliance_rad_per_nm=path_compliance(loop.torque_nm, model) if compliance is None else compliance,
        n_params=n_params,
        torque_sources=loop.local_sources(),
        **options,
    )


def model_figures(loop: Loop, options: AnalysisOptions) -> tuple[FigureRows, dict]:
    """The model fits of `loop`, their parameters as figures and their gates.

    Parameters
    ----------
    loop : Loop
        A closed loop.
    options : AnalysisOptions
        ``fit_preisach``, ``fit_bouc_wen``: which models besides the bilinear one.

    Returns
    -------
    rows : FigureRows
        ``bilinear_k_u``, ``_k_l``, ``_tau_c``, ``bilinear_residual_rms``,
        ``preisach_residual_rms``, ``bouc_wen_*``: each flagged when its model fails its
        gate, failed with the reason when the fit fails; and their issues.
    fits : dict
        ``{"bilinear": BilinearFit | None, "bouc_wen": BoucWenFit | None, "preisach": PreisachFit | None,
        "checks": {model: LackOfFit}}``.
    """
    col, out = FigureRows(loop), no_fits()
    _bilinear_figures(col, out)
    if options.fit_preisach:
        _preisach_figures(col, out)
    if options.fit_bouc_wen:
        _bouc_wen_figures(col, out)
    return col, out


def _bilinear_figures(col: FigureRows, out: dict) -> None:
    loop = col.loop
    try:
        bil: BilinearFit = fit_bilinear(loop.torque_nm, loop.angle_rad, angle_std_rad=loop.angle_std_rad,
                                        torque_sources=loop.sources())
    except AnalysisError as exc:
        for name, unit in (*BILINEAR_UNITS.items(), ("bilinear_residual_rms", "deg")):
            col.fail(name, unit, str(exc))
        return
    out["bilinear"] = bil
    chk = _model_check(
        loop,
        bil.predict(loop.torque_nm),
        loop.local_std(),
        n_params=4,
        compliance=side_compliance(bil.predict, loop.torque_nm),
        jacobian=bilinear_jacobian(bil, loop.torque_nm),
        weights=least_squares_weights(loop.angle_std_rad),
    )
    out["checks"]["bilinear"] = chk
    for (name, unit), attr, key in zip(BILINEAR_UNITS.items(), ("k_u_nm_per_rad", "k_l_nm_per_rad", "tau_c_nm"),
                                       ("k_u", "k_l", "tau_c")):
        col.add(name, unit, getattr(bil, attr), bil.std_angle[key], bil.std_torque[key], "first-order", check=chk)
    col.add("bilinear_residual_rms", "deg", math.degrees(bil.residual_rms_rad), method="fit statistic")


def _preisach_figures(col: FigureRows, out: dict) -> None:
    loop = col.loop
    try:
        pre = fit_preisach(
            loop.torque_nm,
            loop.angle_rad,
            angle_std_rad=loop.angle_std_rad,
            torque_std_nm=loop.local_std(),
            torque_sources=loop.local_sources(),
        )
    except AnalysisError as exc:
        col.fail("preisach_residual_rms", "deg", str(exc))
        return
    out["preisach"] = pre
    out["checks"]["preisach"] = pre.check
    col.add(
        "preisach_residual_rms",
        "deg",
        math.degrees(pre.residual_rms_rad),
        method="fit statistic",
        flag=f"Preisach model rejected: {pre.check.describe()}" if pre.check.rejected else "",
    )


def _bouc_wen_figures(col: FigureRows, out: dict) -> None:
    loop = col.loop
    try:
        bw: BoucWenFit = fit_bouc_wen(loop.torque_nm, loop.angle_rad, angle_std_rad=loop.angle_std_rad,
                                      torque_sources=loop.sources())
    except AnalysisError as exc:
        for name, (unit, _) in _BW_UNITS.items():
            col.fail(f"bouc_wen_{name}", unit, str(exc))
        col.fail("bouc_wen_residual_rms", "deg", str(exc))
        return
    out["bouc_wen"] = bw
    chk = _model_check(loop, bw.predict(loop.torque_nm), loop.local_std(), n_params=6)
    out["checks"]["bouc_wen"] = chk
    for name, (unit, scale) in _BW_UNITS.items():
        v = bw.params[name]
        lo_hi = _BW_BOUNDS.get(name)
        on_bound = lo_hi is not None and (v <= lo_hi[0] * 1.001 or v >= lo_hi[1] * 0.999)
        if on_bound:
            col.add(
                f"bouc_wen_{name}",
                unit,
                v * scale,
                method="first-order",
                flag=f"parameter on its bound ({lo_hi[0]:g} to {lo_hi[1]:g}): not identified, no uncertainty given",
            )
        else:
            col.add(
                f"bouc_wen_{name}",
                unit,
                v * scale,
                bw.std_angle[name] * scale,
                bw.std_torque[name] * scale,
                "first-order",
                check=chk,
            )
    col.add("bouc_wen_residual_rms", "deg", math.degrees(bw.residual_rms_rad), method="fit statistic")
