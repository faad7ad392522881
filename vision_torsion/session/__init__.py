"""Test sessions: plan the six-orientation protocol, then process the folder of images.

A session folder holds ``session.toml`` (rig, markers, protocol, angle sign),
``manifest.csv`` (one row per image) and the images; ``process`` writes
``measurements.csv`` into its output folder (``results/`` by default) and nothing
else into the session folder. See docs/sessions.md.
"""

from .._lazy import attach

# public name -> submodule, imported on first use: a worker process of ``process``
# imports .worker, which must not pull in pandas and scipy through this package
_LAZY = {
    "PHASES": "torque",
    "Manifest": "manifest",
    "ManifestRow": "manifest",
    "ProcessResult": "process",
    "ProtocolConfig": "config",
    "RigConfig": "config",
    "Session": "load",
    "SessionConfig": "config",
    "SessionPlan": "plan",
    "TorqueValue": "torque",
    "bind_session": "bind",
    "watch_session": "watch",
    "Watcher": "watch",
    "BindResult": "bind",
    "Binding": "binding",
    "load_binding": "binding",
    "couple_torque": "torque",
    "load_config": "config",
    "load_manifest": "manifest",
    "load_session": "load",
    "plan_session": "plan",
    "process_session": "process",
    "write_config": "config",
}

__all__ = list(_LAZY)
__getattr__, __dir__ = attach(__name__, _LAZY)

