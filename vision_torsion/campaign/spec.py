"""Specification limits for a campaign report, from a TOML file.

One table per figure, with its limit in the figure's stored unit::

    [k1]
    min = 0.28          # N·m/rad
    [lost_motion_4pct]
    max = 3.0           # deg
"""

from __future__ import annotations

import math

from ..errors import CampaignError

__all__ = ["read_spec_limits"]


def read_spec_limits(path) -> dict:
    """``{figure: {"min": x} | {"max": y} | {"min": x, "max": y}}`` from a TOML file.

    Raises
    ------
    CampaignError
        Not TOML, a figure that is not a table, a key other than min/max, a limit
        that is not a finite number, or min above max; the message names the file
        and the figure.
    """
    from ..textfiles import read_toml

    data = read_toml(path, what="a campaign specification", error=CampaignError)
    out = {}
    for figure, entry in data.items():
        if not isinstance(entry, dict):
            raise CampaignError(f"{path}: [{figure}] must be a table with min and/or max", reason="bad_spec")
        unknown = sorted(set(entry) - {"min", "max"})
        if unknown or not entry:
            raise CampaignError(f"{path}: [{figure}] takes min and/or max, not {', '.join(unknown) or 'nothing'}",
                                reason="bad_spec")
        for key, value in entry.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise CampaignError(f"{path}: [{figure}] {key} = {value!r} is not a finite number", reason="bad_spec")
        if "min" in entry and "max" in entry and entry["min"] > entry["max"]:
            raise CampaignError(f"{path}: [{figure}] min {entry['min']} is above max {entry['max']}",
                                reason="bad_spec")
        out[str(figure)] = {k: float(v) for k, v in entry.items()}
    return out
