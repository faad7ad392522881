"""Report tables: the paper's Table 1 layout and the catalogue metrics per orientation."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from ..analysis.loops import LOOP_PHASES

__all__ = ["STIFFNESS_TABLE_COLUMNS", "stiffness_table", "metrics_table", "orientation_flags"]

#: Columns of stiffness_table.csv (paper, Table 1, with uncertainties and catalogue units).
STIFFNESS_TABLE_COLUMNS = [
    "orientation_deg", "phase", "torque_from_nm", "torque_to_nm", "n_cycles",
    "stiffness_nm_per_rad", "stiffness_std_nm_per_rad", "stiffness_nm_per_arcmin", "stiffness_std_nm_per_arcmin",
    "hysteresis_deg", "hysteresis_std_deg",
    # a phase whose straight line does not fit (stiffness withheld): its two stiffnesses and the switch
    "switch_torque_nm", "stiffness_below_nm_per_rad", "stiffness_below_std_nm_per_rad",
    "stiffness_above_nm_per_rad", "stiffness_above_std_nm_per_rad",
    # every phase: the secant from its first to its last image
    "secant_nm_per_rad", "secant_std_nm_per_rad",
    # why a value of the row is shown flagged (a creep finding flags every figure of its orientation), or ""
    "flag",
]
_ARCMIN_PER_RAD = 180.0 * 60.0 / math.pi


def _index(po: pd.DataFrame) -> dict:
    """``{(orientation, figure): (mean, std, n_cycles)}`` of the per-orientation table
    (the first row of each pair), built once: one boolean filter of the frame per
    table cell cost more than the rest of the report's tables together."""
    out = {}
    for o, f, m, s, n in zip(po["orientation_deg"], po["figure"], po["mean"], po["std"], po["n_cycles"]):
        out.setdefault((float(o), f), (float(m), float(s), int(n)))
    return out


def _lookup(index: dict, orient: float, figure: str) -> tuple[float, float, int]:
    return index.get((float(orient), figure), (np.nan, np.nan, 0))


def stiffness_table(analysis) -> pd.DataFrame:
    """Table 1 of the paper: per orientation and phase, torque range, stiffness, hysteresis.

    Stiffness is the mean over cycles of the phase slope, with the standard
    uncertainty of that mean; the hysteresis (per loop, not per phase) is repeated on
    the four rows of its orientation. A phase whose straight line does not fit its
    data (its stiffness withheld, NaN) carries its stiffness below and above the
    switch and the switch torque; every phase its secant. Missing figures are NaN.
    ``flag`` says why a value of the row is flagged (:func:`orientation_flags`; each
    reason once), or is "".
    """
    ph = analysis.phases
    po = _index(analysis.per_orientation)
    flags = orientation_flags(analysis)
    rows = []
    ranges = {}  # (orientation, phase) -> median torque range over cycles
    if len(ph):
        for key, sub in ph.groupby(["orientation_deg", "phase"], sort=False):
            ranges[key] = (_median(sub["torque_from_nm"]), _median(sub["torque_to_nm"]))
    for orient in sorted(ph["orientation_deg"].unique()) if len(ph) else []:
        h, h_std, _ = _lookup(po, orient, "hysteresis")
        for phase in LOOP_PHASES:
            t_from, t_to = ranges.get((orient, phase), (np.nan, np.nan))
            k, k_std, n = _lookup(po, orient, f"k_{phase}")
            below, below_std, n_below = _lookup(po, orient, f"k_{phase}_below")
            above, above_std, _ = _lookup(po, orient, f"k_{phase}_above")
            switch, _, _ = _lookup(po, orient, f"switch_{phase}")
            sec, sec_std, n_sec = _lookup(po, orient, f"k_{phase}_secant")
            n = max(n, n_below, n_sec)
            rows.append({
                "orientation_deg": orient, "phase": phase,
                "torque_from_nm": t_from,
                "torque_to_nm": t_to,
                "n_cycles": n, "stiffness_nm_per_rad": k, "stiffness_std_nm_per_rad": k_std,
                "stiffness_nm_per_arcmin": k / _ARCMIN_PER_RAD, "stiffness_std_nm_per_arcmin": k_std / _ARCMIN_PER_RAD,
                "hysteresis_deg": h, "hysteresis_std_deg": h_std,
                "switch_torque_nm": switch, "stiffness_below_nm_per_rad": below,
                "stiffness_below_std_nm_per_rad": below_std, "stiffness_above_nm_per_rad": above,
                "stiffness_above_std_nm_per_rad": above_std, "secant_nm_per_rad": sec, "secant_std_nm_per_rad": sec_std,
                "flag": "; ".join(dict.fromkeys(
                    flags[(float(orient), f)] for f in ("hysteresis", f"k_{phase}", f"k_{phase}_below",
                                                        f"k_{phase}_above", f"switch_{phase}", f"k_{phase}_secant")
                    if (float(orient), f) in flags)),
            })
    return pd.DataFrame(rows, columns=STIFFNESS_TABLE_COLUMNS)


def _median(values) -> float:
    """Median of the finite values, NaN when there are none (without the "mean of
    empty slice" warning pandas 2 with numpy 2.2 gives, on Python 3.10)."""
    finite = values[np.isfinite(values)]
    return float(finite.median()) if len(finite) else np.nan


#: The report's figure vocabulary: figure -> (label, unit shown, scale from the analysis unit).
#: The catalogue table and the uncertainty budget (report/analysis_sections.py) both take theirs from here.
#: Every angle in arcmin (the catalogues' unit): one angle unit per table.
FIGURE_VOCABULARY = {
    "hysteresis": ("Hysteresis (paper: max width)", "arcmin", 60.0),
    "hysteresis_loss": ("Hysteresis loss (width at 0 N·m)", "arcmin", 60.0),
    "lost_motion_3pct": ("Lost motion ±3 %", "arcmin", 60.0),
    "lost_motion_4pct": ("Lost motion ±4 %", "arcmin", 60.0),
    "k1": ("K1", "N·m/rad", 1.0),
    "k2": ("K2", "N·m/rad", 1.0),
    "k3": ("K3", "N·m/rad", 1.0),
    "t1": ("T1", "N·m", 1.0),
    "t2": ("T2", "N·m", 1.0),
    "k_positive_unloading": ("k positive unloading", "N·m/rad", 1.0),
    "k_negative_loading_below": ("k negative loading, below the switch", "N·m/rad", 1.0),
    "k_negative_loading_above": ("k negative loading, above the switch", "N·m/rad", 1.0),
    "k_negative_loading_secant": ("k negative loading, secant", "N·m/rad", 1.0),
    "secant_stiffness": ("Secant stiffness", "N·m/rad", 1.0),
    "loop_energy": ("Loop energy ∮τ dθ", "J", 1.0),
    "loss_factor": ("Loss factor η", "–", 1.0),
    "bilinear_k_u": ("Bilinear k_u", "N·m/rad", 1.0),
    "bilinear_k_l": ("Bilinear k_l", "N·m/rad", 1.0),
    "bilinear_tau_c": ("Bilinear τ_c", "N·m", 1.0),
    "bilinear_residual_rms": ("Bilinear residual RMS", "arcmin", 60.0),
    "bouc_wen_k_e": ("Bouc–Wen k_e", "N·m/rad", 1.0),
    "bouc_wen_z_s": ("Bouc–Wen z_s", "arcmin", 60.0),
    "bouc_wen_a": ("Bouc–Wen a", "1/(N·m)", 1.0),
    "bouc_wen_rho": ("Bouc–Wen ρ", "–", 1.0),
    "bouc_wen_n": ("Bouc–Wen n", "–", 1.0),
    "bouc_wen_residual_rms": ("Bouc–Wen residual RMS", "deg", 1.0),
}


def figure_rows(figures, labels=None) -> list[tuple[str, str, str, float]]:
    """``(figure, label, unit, scale)`` of `figures` from :data:`FIGURE_VOCABULARY`;
    `labels` (figure -> label) overrides a label."""
    labels = labels or {}
    return [(f, labels.get(f, FIGURE_VOCABULARY[f][0]), *FIGURE_VOCABULARY[f][1:]) for f in figures]


#: Rows of the catalogue metrics table: (figure, label, unit shown, scale from the analysis unit)
CATALOGUE_FIGURES = figure_rows([
    f for f in FIGURE_VOCABULARY
    if f not in ("k_positive_unloading", "k_negative_loading_below", "k_negative_loading_above",
                 "k_negative_loading_secant")
])


def orientation_flags(analysis) -> dict:
    """``{(orientation_deg, figure): why its orientation mean is shown flagged}``, for the flagged ones.

    A mean over cycles is flagged as :func:`vision_torsion.analysis.summary.summarise_figures`
    says, with the reasons its flagged loop values all share added (an orientation's creep
    finding, a torque model that was not declared: each flags every figure of the loop); a mean
    of one loop is flagged only when that loop's value is (that it holds no repeatability is
    said once, for the whole table).
    """
    figs = analysis.figures
    flagged = figs[figs["flag"].astype(str) != ""]
    loop_flags = {}
    for o, f, g in zip(flagged["orientation_deg"], flagged["figure"], flagged["flag"].astype(str)):
        loop_flags.setdefault((float(o), f), []).append(g)
    pof = analysis.per_orientation
    out = {}
    for o, f, g, n in zip(pof["orientation_deg"], pof["figure"], pof["flag"], pof["n_cycles"]):
        texts = loop_flags.get((float(o), f), [])
        if n == 1 and texts:
            out[(float(o), f)] = "; ".join(dict.fromkeys(texts))
        elif g and n > 1:
            shared = [part for part in texts[0].split("; ") if all(part in t for t in texts)] if texts else []
            out[(float(o), f)] = "; ".join(dict.fromkeys([str(g), *shared]))
    return out


def metrics_table(analysis) -> pd.DataFrame:
    """Wide table of the catalogue metrics: one row per figure, one column per orientation.

    Cells are ``(mean, std)`` tuples of the orientation mean (NaN when missing); the
    last columns hold the session mean, its standard uncertainty, the sd between
    loops and the orientation test's Holm-adjusted p-value; ``flags`` maps an orientation to why its
    mean is flagged (:func:`orientation_flags`), for the flagged ones.
    """
    po = _index(analysis.per_orientation)
    flags = orientation_flags(analysis)
    orients = sorted({lp.orientation_deg for lp in analysis.loop_data})
    rows = []
    for fig, label, unit, scale in CATALOGUE_FIGURES:
        s = analysis.summary.get(fig)
        if s is None:
            continue
        row = {"figure": fig, "label": label, "unit": unit}
        for o in orients:
            m, sd, _ = _lookup(po, o, fig)
            row[o] = (m * scale, sd * scale)

        def scale_or_nan(v, scale=scale):
            return np.nan if v is None else v * scale

        row["mean"] = scale_or_nan(s["mean"])
        row["mean_std"] = scale_or_nan(s["mean_std"])
        row["sd"] = scale_or_nan(s["sd"])
        row["p_value"] = s["orientation_test"].get("p_value_holm")  # the family's p (Holm), which decides
        row["flags"] = {o: flags[(float(o), fig)] for o in orients if (float(o), fig) in flags}
        rows.append(row)
    return pd.DataFrame(rows)
