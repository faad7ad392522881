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
- :mod:`.steps` — camera-rig stiffness per load step, Δτ/Δθ, per loop;
- :mod:`.backlash` — the dead zone;
- :mod:`.meshing` — meshing pairs, wrap angle, Ks calibration, linearity check;
- :mod:`.analysis` — :func:`analyze_stiffness_curve`, the whole chain;
- :mod:`.plots`, :mod:`.report` — figures and the session-report section;
- :mod:`.synthetic` — records with known truth.
"""

from .analysis import MeshingSummary, StiffnessResult, analyze_stiffness_curve
from .backlash import Backlash, detect_backlash
from .branches import split_branches
from .curve import BranchFit, StiffnessCurve, fit_loading_branch, stiffness_curve, summarise_curves
from .filtering import filter_record, lowpass
from .meshing import (
    LinearityCheck,
    calibrate_tooth_stiffness,
    check_linearity,
    meshing_pairs,
    wrap_angle_rad,
)
from .plots import plot_meshing, plot_step_stiffness, plot_stiffness, plot_torque_angle
from .records import TorqueAngleRecord, read_record
from .report import StiffnessSection, stiffness_section
from .rig import RigConstants, load_rig, output_angle_deg
from .steps import step_stiffness, summarise_steps
from .synthetic import (
    SaturatingStiffness,
    realistic_encoder_record,
    stiffening_law,
    synthetic_encoder_record,
    synthetic_measurements,
)

__all__ = [
    "analyze_stiffness_curve", "StiffnessResult", "MeshingSummary",
    "RigConstants", "load_rig", "output_angle_deg",
    "TorqueAngleRecord", "read_record",
    "lowpass", "filter_record", "split_branches",
    "fit_loading_branch", "stiffness_curve", "summarise_curves", "BranchFit", "StiffnessCurve",
    "step_stiffness", "summarise_steps",
    "detect_backlash", "Backlash",
    "meshing_pairs", "wrap_angle_rad", "calibrate_tooth_stiffness", "check_linearity",
    "LinearityCheck",
    "plot_torque_angle", "plot_stiffness", "plot_meshing", "plot_step_stiffness",
    "stiffness_section", "StiffnessSection",
    "SaturatingStiffness", "stiffening_law", "synthetic_encoder_record", "realistic_encoder_record",
    "synthetic_measurements",
]
