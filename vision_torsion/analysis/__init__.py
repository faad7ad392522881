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
- :mod:`.session_analysis` — :func:`analyze_session`, a short orchestrator over the figure
  families below;
- :mod:`.parameters` — :class:`AnalysisOptions`, the analysis' options, checked once;
- :mod:`.rows` — the figure rows and issues every family returns;
- the figure families, one module each: :mod:`.phase_figures` (phase stiffness),
  :mod:`.loop_figures` (loop figures by Monte Carlo), :mod:`.catalogue_figures`
  (K1–K3), :mod:`.model_figures` (bilinear, Preisach, Bouc–Wen fits and gates),
  :mod:`.data_checks` (failed images, rig, sign, creep, outliers);
- :mod:`.fitcheck` — the lack-of-fit gate, switching-phase stiffness, secant;
- :mod:`.preisach` — the Preisach / Maxwell-slip model, fitted by NNLS;
- :mod:`.catalogue` — K1, K2, K3 with catalogue (or fitted) break torques;
- :mod:`.checks` — angle sign, gaps, loop closure and creep, outliers.
"""

from ..lazy import attach

# the modules whose __all__ make up this face, each imported on first use of one of its names
_LAZY = ("catalogue", "fitcheck", "loops", "metrics", "models", "parameters", "preisach", "session_analysis", "summary")

__getattr__, __dir__ = attach(__name__, _LAZY)
