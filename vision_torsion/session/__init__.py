"""Test sessions: plan the six-orientation protocol, then process the folder of images.

A session folder holds ``session.toml`` (rig, markers, protocol, angle sign),
``manifest.csv`` (one row per image) and the images; ``process`` writes
``measurements.csv`` into its output folder (``results/`` by default) and nothing
else into the session folder. See docs/sessions.md.
"""

from ..lazy import attach

# the modules whose __all__ make up this face, each imported on first use of one of its names:
# a worker process of ``process`` imports .worker, which must not pull in pandas and scipy
_LAZY = ("bind", "binding", "config", "load", "manifest", "plan", "process", "torque", "watch")

__getattr__, __dir__ = attach(__name__, _LAZY)
