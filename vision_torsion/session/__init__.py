"""Test sessions: plan the six-orientation protocol, then process the folder of images.

A session folder holds ``session.toml`` (rig, markers, protocol, angle sign),
``manifest.csv`` (one row per image) and the images; ``process`` writes
``measurements.csv`` into its output folder (``results/`` by default) and nothing
else into the session folder. See the README section "Session folders".
"""

from .config import (ProtocolConfig, RigConfig, SessionConfig, load_config,
                     write_config)
from .load import Session, load_session
from .manifest import Manifest, ManifestRow, load_manifest
from .plan import SessionPlan, plan_session
from .process import ProcessResult, process_session
from .torque import PHASES, TorqueValue, couple_torque

__all__ = [
    "PHASES",
    "Manifest",
    "ManifestRow",
    "ProcessResult",
    "ProtocolConfig",
    "RigConfig",
    "Session",
    "SessionConfig",
    "SessionPlan",
    "TorqueValue",
    "couple_torque",
    "load_config",
    "load_manifest",
    "load_session",
    "plan_session",
    "process_session",
    "write_config",
]
