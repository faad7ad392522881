"""Stiffness curve and meshing-teeth analysis of harmonic drives (issue 7).

From a torque-angle record of either rig (encoder/torque-sensor CSV or camera-rig
``measurements.csv``) to the stiffness curve K(T) = dT/dθ with its band, the backlash
dead zone, and the effective meshing tooth pairs n(T) = K(T)/Ks with the wrap angle
2·π·n/z of one meshing zone. One module per step:

- :mod:`.rig` — rig constants (TOML) and θ_out = θ_in/i − T/K_sensor;
- :mod:`.records` — reading and validating records;
- :mod:`.filtering` — zero-phase Butterworth low-pass;
- :mod:`.branches` — loading/unloading branches;
- :mod:`.curve` — loading-branch fits, the stiffness curve per cycle and its summary;
- :mod:`.per_step` — camera-rig stiffness per load step, Δτ/Δθ, per loop;
- :mod:`.backlash` — the dead zone;
- :mod:`.meshing` — meshing pairs, wrap angle, Ks calibration, linearity check;
- :mod:`.analysis` — :func:`analyze_stiffness_curve`, the whole chain;
- :mod:`.section` — the session report's stiffness section (its figures are drawn by
  :mod:`vision_torsion.report.stiffness_figures`, the report layer).

Records with known truth are made by :mod:`vision_torsion.synthetic.encoder`.
"""

from ..lazy import attach

# the modules whose __all__ make up this face, each imported on first use of one of its names
_LAZY = ("analysis", "backlash", "branches", "curve", "filtering", "meshing", "records", "rig", "per_step", "section")

__getattr__, __dir__ = attach(__name__, _LAZY)
