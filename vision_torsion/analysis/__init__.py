"""Hysteresis analysis of torque–angle data: models, loop figures, uncertainties and
summaries (issue 5).

Modules, one job each:

- :mod:`.models` — the paper's bilinear stiffness-switching model
  (:func:`bilinear_response`) and a torque-driven Bouc–Wen model, with fits;
- :mod:`.metrics` — figures of one loop (phase stiffness, hysteresis, lost motion,
  K1/K2/K3, secant stiffness, loop energy, loss factor);
- :mod:`.uncertainty` — error model and propagation (first order, Monte Carlo);
- :mod:`.loops` — validation of ``measurements.csv`` and loop assembly;
- :mod:`.summary` — per-orientation and session summaries, orientation test;
- :mod:`.session` — :func:`analyze_session`;
- :mod:`.simulate` — synthetic measurement tables with known truth;
- :mod:`.fitcheck` — the lack-of-fit gate, switching-phase stiffness, secant;
- :mod:`.preisach` — the Preisach / Maxwell-slip model, fitted by NNLS;
- :mod:`.catalogue` — K1, K2, K3 with catalogue (or fitted) break torques;
- :mod:`.checks` — angle sign, gaps, loop closure and creep, outliers.
"""

from .catalogue import fit_catalogue_breaks, fit_fixed_breaks
from .fitcheck import LackOfFit, fit_switch, lack_of_fit
from .loops import validate_measurements
from .metrics import (
    fit_three_segment,
    loop_energy,
    loop_width,
    loss_factor,
    lost_motion,
    phase_stiffness,
    secant_stiffness,
)
from .models import (
    BilinearFit,
    BoucWenFit,
    bilinear_loop_energy,
    bilinear_loop_width,
    bilinear_response,
    bouc_wen_response,
    fit_bilinear,
    fit_bouc_wen,
)
from .preisach import PreisachFit, fit_preisach, preisach_response
from .session import Issue, SessionAnalysis, analyze_session
from .simulate import simulate_measurements, torque_levels
from .summary import orientation_anova, orientation_test

__all__ = [
    "bilinear_response", "bilinear_loop_width", "bilinear_loop_energy", "fit_bilinear", "BilinearFit",
    "bouc_wen_response", "fit_bouc_wen", "BoucWenFit",
    "phase_stiffness", "loop_width", "lost_motion", "secant_stiffness", "loop_energy", "loss_factor",
    "fit_three_segment", "orientation_test", "validate_measurements",
    "analyze_session", "SessionAnalysis", "Issue", "simulate_measurements", "torque_levels",
    "fit_preisach", "preisach_response", "PreisachFit", "lack_of_fit", "LackOfFit", "fit_switch",
    "fit_fixed_breaks", "fit_catalogue_breaks", "orientation_anova",
]
