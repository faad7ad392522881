"""Figure family: the catalogue's K1, K2, K3 of a loop — with the catalogue's break torques T1, T2
fixed (linear least squares), or with the breaks fitted (one or two; T1, T2 are then figures too),
their uncertainty by a parametric bootstrap that refits the breaks (:mod:`.catalogue`): the
shown u95 is the larger of ``k·std`` and the draws' own symmetric 95 % half-width
(:func:`.catalogue.break_bootstrap`), and breaks the bootstrap cannot refit withhold the family.
A fitted second break whose neighbouring slopes agree within their uncertainty is merged
(:func:`.catalogue.fit_catalogue_breaks`), so K2 is never the soft slope split in two.

The loading branches from zero are fitted: the descending run below zero torque and the
ascending run above it. A fit that fails its lack-of-fit gate is shown flagged, its
uncertainty multiplied by ``√χ²_red``; K3 and T2 are "not applicable" when one break
describes the branches.
"""

from __future__ import annotations

import numpy as np

from ..errors import AnalysisError
from .catalogue import fit_catalogue_breaks, fit_fixed_breaks
from .loops import Loop
from .parameters import AnalysisOptions
from .rows import FigureRows
from .uncertainty import compact_sources

__all__ = ["catalogue_figures", "CATALOGUE_UNITS"]

#: The stiffnesses of this family, name → unit (the fitted breaks ``t1``, ``t2`` are in N·m).
CATALOGUE_UNITS = {"k1": "nm_per_rad", "k2": "nm_per_rad", "k3": "nm_per_rad"}


def catalogue_figures(loop: Loop, options: AnalysisOptions) -> FigureRows:
    """K1, K2, K3 of `loop` (:data:`CATALOGUE_UNITS`), and T1, T2 when the breaks are fitted.

    Parameters
    ----------
    loop : Loop
        A closed loop.
    options : AnalysisOptions
        ``catalogue_breaks_nm`` (fixed breaks), else ``fit_breaks`` (with ``n_draws`` and
        ``seed`` for the bootstrap).

    Returns
    -------
    FigureRows
        The figures and their issues (failed with the reason when no break is given and
        fitting is off, or when the fit fails).
    """
    col = FigureRows(loop)
    tau, th, th_std, _, _, is_desc, sources = loop.runs()
    kinds = loop.source_kinds if loop.source_kinds is not None else np.array(["level"] * sources.shape[1], object)
    seg_mask = (is_desc & (tau <= 0)) | (~is_desc & (tau >= 0))
    t, y, sa = tau[seg_mask], th[seg_mask], th_std[seg_mask]
    branch = np.where(is_desc[seg_mask], -1, 1)
    src, knd = compact_sources(sources[seg_mask], kinds)
    src_local = src[:, np.asarray(knd) != "g_r"]
    st_local = np.sqrt(np.sum(src_local**2, axis=1))
    names = tuple(CATALOGUE_UNITS.items())
    breaks = options.catalogue_breaks_nm
    data = dict(branch=branch, angle_std_rad=sa, torque_std_nm=st_local, torque_sources=src, gate_sources=src_local)
    try:
        if breaks is not None:
            res = fit_fixed_breaks(t, y, breaks_nm=breaks, **data)
            method = "linear least squares, catalogue T1/T2 fixed"
        elif options.fit_breaks:
            res = fit_catalogue_breaks(t, y, **data, n_draws=options.n_draws, seed=options.seed)
            method = "breaks fitted; uncertainty by a parametric bootstrap that refits the breaks"
        else:
            for n, u in names:
                col.fail(n, u, "no catalogue T1/T2 given and fitting the breaks is off")
            return col
    except AnalysisError as exc:
        for n, u in names + (("t1", "nm"), ("t2", "nm")):
            col.fail(n, u, str(exc))
        return col
    chk = res["check"]
    draws = res.get("draws")
    for j, (n, u) in enumerate(names):
        if j < len(res["k"]):
            col.add(n, u, res["k"][j], res["std_angle"][j], res["std_torque"][j], method, check=chk, draws=draws,
                    interval=res["u95"][j] if "u95" in res else np.nan)
        else:
            col.fail(n, u, f"one break describes the loading branches (two segments: K1, K2); {res['criterion']}",
                     kind="not_applicable")
    if breaks is None and options.fit_breaks:
        for j, n in enumerate(("t1", "t2")):
            if j < len(res["breaks_nm"]):
                col.add(n, "nm", res["breaks_nm"][j], res["breaks_std_angle"][j], res["breaks_std_torque"][j],
                        method, check=chk, draws=draws, interval=res["breaks_u95"][j])
            else:
                col.fail(n, "nm", f"one break describes the loading branches (two segments); {res['criterion']}",
                         kind="not_applicable")
    return col
