"""vision-torsion: torsional stiffness and hysteresis of precision gears from camera images.

The public API is listed in ``__all__``. Names are imported on first use (PEP 562),
so ``import vision_torsion`` stays light and worker processes that only measure
never load the plotting and analysis stack.

Examples
--------
>>> import vision_torsion as vt
>>> from vision_torsion.synthetic import Scene, render
>>> scene = Scene()
>>> res = vt.rotation_angle(render(scene, 0.0, seed=1).image, render(scene, 30.0, seed=2).image)
>>> bool(abs(res.angle_deg - 30.0) < 0.005)
True
"""

from .errors import *  # noqa: F401,F403
from .errors import __all__ as _errors_all
from .lazy import attach

__version__ = "0.1.0"

# public name -> module that defines it
_LAZY = {
    # images and settings
    "GreyImage": "images",
    "load_image": "images",
    "decode_image": "images",
    "MeasureSettings": "settings",
    # the measurement core
    "find_markers": "markers",
    "Marker": "markers",
    "fit_circle": "circlefit",
    "fit_ellipse": "circlefit",
    "CircleFit": "circlefit",
    "EllipseFit": "circlefit",
    "edge_points": "edges",
    "fit_disc": "pixelfit",
    "DiscFit": "pixelfit",
    "measure_pair": "pair",
    "select_pair": "pair",
    "PairMeasurement": "pair",
    "rotation_angle": "angle",
    "pair_angle": "angle",
    "sequence_angles": "angle",
    "AngleResult": "angle",
    "line_direction_deg": "angle",
    "paper_angle_deg": "angle",
    "measure_folder": "measure",
    # N-marker targets: the layout, identity, the rigid fit of all centres, printing
    "Target": "targets",
    "load_target": "targets",
    "ring_target": "targets",
    "grid_target": "targets",
    "dots_target": "targets",
    "target_angle": "rigid",
    "target_angles": "rigid",
    "TargetAngle": "rigid",
    "identify_markers": "rigid",
    "fit_rigid": "rigid",
    "rotation_centre": "rigid",
    "measure_target_folder": "rigid",
    "write_target_pdf": "targetsheet",
    # sessions
    "plan_config": "session",
    "plan_session": "session",
    "load_session": "session",
    "process_session": "session",
    "ProcessResult": "session",
    "SessionPlan": "session",
    "Session": "session",
    "SessionConfig": "session",
    "couple_torque": "session",
    "TorqueValue": "session",
    # the measurements vocabulary
    "PHASES": "measurements",
    "TorqueRig": "measurements",
    "read_measurements": "measurements",
    "bind_session": "session",
    "watch_session": "session",
    "BindResult": "session",
    # hysteresis analysis and the report
    "analyze_session": "analysis",
    "SessionAnalysis": "analysis",
    "bilinear_response": "analysis",
    "fit_bilinear": "analysis",
    "fit_bouc_wen": "analysis",
    "simulate_measurements": "synthetic",
    "fit_preisach": "analysis",
    "write_report": "report",
    "analyze_table": "report.analyze",
    "report_session": "report.session_report",
    "run_demo": "report.session_report",
    # calibration
    "check_accuracy": "calibration",
    "AccuracyResult": "calibration",
    "calibrate_plane": "calibration",
    "calibrate_from_target": "calibration",
    "PlaneCorrection": "correction",
    "load_correction": "correction",
    # stiffness curve and meshing teeth
    "analyze_stiffness_curve": "stiffness",
    "StiffnessResult": "stiffness",
    "RigConstants": "stiffness",
    "load_rig": "stiffness",
    "meshing_pairs": "stiffness",
    "wrap_angle_rad": "stiffness",
    "synthetic_encoder_record": "synthetic",
}

__getattr__, __dir__ = attach(__name__, _LAZY)
__all__ = [*_errors_all, *_LAZY]
