"""Report folders of a synthetic campaign: a batch of gears, and a life test.

One session table is simulated and analysed for real (the bilinear model, the paper's
protocol); each report of the campaign is that summary.json with its gear identity
and test metadata set and its headline figures scaled as a batch of gears scatters
(stiffness by a factor f per gear, angles and energies by 1/f; a life-test gear's
stiffness falling with its test hours). The rest of the summary is the analysed
session's as it was: these folders exercise a campaign database (its speed, its
statistics, its concurrency), not the analysis.
"""

from __future__ import annotations

import copy
import json
from datetime import date, timedelta
from pathlib import Path

import numpy as np

__all__ = ["base_summary", "campaign_summary", "write_campaign_folders"]

_SCALED_KEYS = ("mean", "sd", "min", "max", "range", "mean_std", "mean_u95")


def base_summary(*, seed: int = 0, n_cycles: int = 2) -> dict:
    """summary.json content of one simulated session (bilinear model, 6 orientations).

    Parameters
    ----------
    seed : int
        Seed of the simulated table's noise.
    n_cycles : int
        Cycles per orientation.
    """
    from ..analysis import analyze_session
    from ..synthetic import simulate_measurements

    rng = np.random.default_rng(seed)
    table = simulate_measurements(k_u=4.4, k_l=0.3, tau_c=0.15, max_torque_nm=0.36, angle_std_deg=0.001,
                                  mass_std_kg=5.8e-5, rng=rng, n_cycles=n_cycles, torque_model="pieces")
    summary = analyze_session(table, n_draws=100, seed=seed).to_dict()
    summary["software"] = {"name": "vision-torsion", "version": "synthetic"}
    return summary


def campaign_summary(base: dict, *, model: str, serial: str, test_date: str, stiffness_factor: float,
                     rng: np.random.Generator, operator: str = "synthetic", test_hours: float | None = None,
                     limits=()) -> dict:
    """``base`` as the report of one gear: identity and test set, figures scaled.

    Parameters
    ----------
    stiffness_factor : float
        Multiplies every stiffness figure (N·m/rad); angle (deg) and energy (J)
        figures are divided by it.
    rng : numpy.random.Generator
        Each figure's mean is then moved by a normal draw of its own standard
        uncertainty (``mean_std``): a report scatters about its gear's truth as its
        ± says.
    limits : sequence of vision_torsion.analysis.conformity.Limit
        Catalogue limits: the report then carries its conformity verdicts, as
        ``report`` writes them with a ``[spec]``.
    """
    from ..analysis.conformity import DECISION_RULE, conformity

    out = copy.deepcopy(base)
    out["identity"] = {"gear": model, "serial": serial, "operator": operator, "date": test_date}
    out["test"] = {"operator": operator, "date": test_date}
    if test_hours is not None:
        out["test"]["test_hours"] = float(test_hours)
    for entry in out["summary"].values():
        unit = entry.get("unit", "")
        factor = stiffness_factor if unit == "nm_per_rad" else 1.0 / stiffness_factor if unit in ("deg", "j") else 1
        for key in _SCALED_KEYS:
            if isinstance(entry.get(key), (int, float)):
                entry[key] = entry[key] * factor
        if isinstance(entry.get("mean"), (int, float)) and isinstance(entry.get("mean_std"), (int, float)):
            entry["mean"] += float(rng.normal(0.0, entry["mean_std"]))
    if limits:
        out["conformity"] = {"rule": DECISION_RULE,
                             "verdicts": [v.to_dict() for v in conformity(out["summary"], limits)]}
    return out


def write_campaign_folders(out_dir, *, n_reports: int, seed: int = 0, model: str = "CSF-14-100",
                           batch_sd: float = 0.03, life_test_every: int = 0, life_drift_per_1000h: float = -0.05,
                           base: dict | None = None, limits=None) -> list[Path]:
    """Write ``n_reports`` report folders (``report_0001/summary.json`` ...).

    Parameters
    ----------
    out_dir : str or Path
        Created; one sub-folder per report.
    n_reports : int
    seed : int
        Seed of the batch scatter (and of :func:`base_summary` when ``base`` is None).
    batch_sd : float
        Relative standard deviation of the gears' stiffness.
    life_test_every : int
        Every that many reports is a test of one life-test gear (serial ``LT-1``)
        after 100 more hours; 0 for none.
    life_drift_per_1000h : float
        Relative stiffness change of the life-test gear per 1000 h.
    base : dict, optional
        The analysed summary to vary (default :func:`base_summary`).
    limits : sequence of vision_torsion.analysis.conformity.Limit, optional
        Catalogue limits every report is judged against; default: K1 at least 0.95
        of the base session's and lost motion at 4 % at most 1.05 of it (a batch
        that mostly passes, some gears failing or not decidable).

    Returns
    -------
    list of Path
        The report folders, in test order (one test a day from 2026-01-01).
    """
    from ..analysis.conformity import Limit

    rng = np.random.default_rng(seed)
    base = base if base is not None else base_summary(seed=seed)
    if limits is None:
        limits = (Limit("k1", "min", 0.95 * base["summary"]["k1"]["mean"]),
                  Limit("lost_motion_4pct", "max", 1.05 * base["summary"]["lost_motion_4pct"]["mean"]))
    out = Path(out_dir)
    folders, hours = [], 0.0
    start = date(2026, 1, 1)
    for i in range(n_reports):
        day = (start + timedelta(days=i)).isoformat()
        if life_test_every and i % life_test_every == 0:
            factor = 1.0 + life_drift_per_1000h * hours / 1000.0
            summary = campaign_summary(base, model=model, serial="LT-1", test_date=day, stiffness_factor=factor,
                                       rng=rng, test_hours=hours, limits=limits)
            hours += 100.0
        else:
            factor = float(np.exp(rng.normal(0.0, batch_sd)))
            summary = campaign_summary(base, model=model, serial=f"S{1000 + i}", test_date=day,
                                       stiffness_factor=factor, rng=rng, limits=limits)
        folder = out / f"report_{i + 1:04d}"
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "summary.json").write_text(json.dumps(summary), encoding="utf-8")
        folders.append(folder)
    return folders
