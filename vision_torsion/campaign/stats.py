"""Statistics over many reports: differences between gears, trends over a life test,
control limits and capability of a batch.

Each function returns numbers with the reason they were withheld where the data
cannot support them (too few reports, no spread, no uncertainty).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Difference",
    "difference",
    "Trend",
    "fit_trend",
    "ControlLimits",
    "control_limits",
    "Capability",
    "capability",
    "MIN_CONTROL_POINTS",
    "MIN_CAPABILITY_POINTS",
]

#: Fewer reports than this give no control limits (the moving range is too uncertain).
MIN_CONTROL_POINTS = 8
#: Fewer reports than this give no capability index.
MIN_CAPABILITY_POINTS = 10
_D2 = 1.128  # E[moving range of 2] / sigma for normal data (ISO 7870-2)


def _finite(x) -> bool:
    """A reported number: not None, not NaN (a withheld value read from a table)."""
    return x is not None and math.isfinite(float(x))


@dataclass(frozen=True)
class Difference:
    """``a − b`` with its expanded uncertainty and the normalised error
    E_n = |a − b| / √(U_a² + U_b²) (ISO 13528); ``significant`` when E_n > 1.
    ``reason`` says why nothing could be said (a value or its uncertainty missing)."""

    value: float | None
    u95: float | None
    en: float | None
    significant: bool | None
    reason: str = ""


def difference(a, u95_a, b, u95_b) -> Difference:
    """The difference of two reported values and whether it exceeds their uncertainties.

    Notes
    -----
    The two U95 are combined as independent. Two tests on one rig share the weights'
    and the arm radius' errors; those then cancel in the difference, so E_n here is
    conservative (too small) for gears tested on the same rig.
    """
    if not (_finite(a) and _finite(b)):
        return Difference(None, None, None, None, "a value is withheld")
    d = float(a) - float(b)
    if not (_finite(u95_a) and _finite(u95_b)):
        return Difference(d, None, None, None, "a value has no uncertainty")
    u = math.hypot(float(u95_a), float(u95_b))
    if u <= 0:
        return Difference(d, u, None, None, "zero uncertainty")
    en = abs(d) / u
    return Difference(d, u, en, bool(en > 1.0))


@dataclass(frozen=True)
class Trend:
    """A straight line ``value = intercept + slope·x`` over a life test.

    ``slope_std`` includes the scatter about the line when it exceeds the reported
    uncertainties (σ scaled by √χ²_red, never down); ``p_value`` of slope = 0
    (Student t, n − 2 dof); ``band(x)`` gives the line's 95 % band; ``cov`` is the
    covariance of (intercept, slope) and ``dof`` is n − 2. ``reason`` is set (and the
    numbers None) when fewer than 3 points with uncertainties or a single x.
    """

    n: int
    slope: float | None
    slope_std: float | None
    intercept: float | None
    p_value: float | None
    chi2_red: float | None
    reason: str = ""
    cov: tuple = ()
    dof: int = 0

    def band(self, x):
        """(line, half-width of its 95 % band) at ``x``."""
        from scipy import stats

        x = np.asarray(x, float)
        if self.slope is None:
            nan = np.full(x.shape, np.nan)
            return nan, nan
        (vaa, vab), (_, vbb) = self.cov
        line = self.intercept + self.slope * x
        var = vaa + 2 * vab * x + vbb * x**2
        return line, stats.t.ppf(0.975, max(self.dof, 1)) * np.sqrt(np.maximum(var, 0.0))


def fit_trend(x, y, std) -> Trend:
    """Weighted least-squares line through values with standard uncertainties."""
    from scipy import stats

    x, y, std = (np.asarray(v, float) for v in (x, y, std))
    keep = np.isfinite(x) & np.isfinite(y) & np.isfinite(std) & (std > 0)
    x, y, std = x[keep], y[keep], std[keep]
    n = int(x.size)
    if n < 3:
        return Trend(n, None, None, None, None, None, f"{n} value(s) with an uncertainty: a trend needs 3")
    if np.ptp(x) == 0:
        return Trend(n, None, None, None, None, None, "every value at the same time: no trend")
    x0 = float(x.mean())
    design = np.column_stack([np.ones(n), x - x0]) / std[:, None]
    coef, *_ = np.linalg.lstsq(design, y / std, rcond=None)
    resid = (y - (coef[0] + coef[1] * (x - x0))) / std
    dof = n - 2
    chi2_red = float(resid @ resid / dof) if dof else float("nan")
    cov = np.linalg.inv(design.T @ design) * max(1.0, chi2_red if math.isfinite(chi2_red) else 1.0)
    slope, slope_std = float(coef[1]), float(math.sqrt(cov[1, 1]))
    intercept = float(coef[0] - coef[1] * x0)
    # covariance of (intercept at x = 0, slope)
    vaa = cov[0, 0] + x0**2 * cov[1, 1] - 2 * x0 * cov[0, 1]
    vab = cov[0, 1] - x0 * cov[1, 1]
    p = float(2 * stats.t.sf(abs(slope) / slope_std, dof)) if slope_std > 0 and dof else None
    return Trend(n, slope, slope_std, intercept, p, chi2_red, "", ((vaa, vab), (vab, cov[1, 1])), dof)


@dataclass(frozen=True)
class ControlLimits:
    """Individuals (X) chart limits: centre ± 3σ̂ with σ̂ = mean moving range / 1.128.
    ``out_of_control`` lists the positions of points beyond the limits."""

    n: int
    centre: float | None
    lower: float | None
    upper: float | None
    sigma: float | None
    out_of_control: tuple[int, ...] = ()
    reason: str = ""


def control_limits(values) -> ControlLimits:
    """Shewhart individuals chart of values in test order (ISO 7870-2)."""
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], float)
    n = int(v.size)
    if n < MIN_CONTROL_POINTS:
        return ControlLimits(n, None, None, None, None, (), f"{n} report(s): control limits need "
                                                            f"{MIN_CONTROL_POINTS}")
    sigma = float(np.mean(np.abs(np.diff(v))) / _D2)
    centre = float(v.mean())
    lower, upper = centre - 3 * sigma, centre + 3 * sigma
    out = tuple(int(i) for i in np.flatnonzero((v < lower) | (v > upper)))
    return ControlLimits(n, centre, lower, upper, sigma, out)


@dataclass(frozen=True)
class Capability:
    """Process performance of a batch against its specification limits.

    ``ppk`` = min(USL − μ, μ − LSL) / 3s with the overall standard deviation s (one
    side where only one limit is given); ``ppk_lower95`` its one-sided 95 % lower
    confidence bound (Bissell's approximation); ``conforming`` the fraction of values
    inside the limits. ``reason`` when it cannot be given.
    """

    n: int
    mean: float | None
    sd: float | None
    ppk: float | None
    ppk_lower95: float | None
    conforming: float | None
    reason: str = ""


def capability(values, *, lower=None, upper=None) -> Capability:
    """Ppk of values against a lower and/or upper specification limit."""
    v = np.asarray([x for x in values if x is not None and math.isfinite(x)], float)
    n = int(v.size)
    if lower is None and upper is None:
        return Capability(n, None, None, None, None, None, "no specification limit")
    if n < MIN_CAPABILITY_POINTS:
        return Capability(n, None, None, None, None, None,
                          f"{n} report(s): a capability index needs {MIN_CAPABILITY_POINTS}")
    mean, sd = float(v.mean()), float(v.std(ddof=1))
    inside = np.ones(n, bool)
    sides = []
    if lower is not None:
        sides.append(mean - lower)
        inside &= v >= lower
    if upper is not None:
        sides.append(upper - mean)
        inside &= v <= upper
    if sd == 0:
        return Capability(n, mean, sd, None, None, float(inside.mean()), "no spread: every value the same")
    ppk = min(sides) / (3 * sd)
    lower95 = ppk - 1.645 * math.sqrt(1 / (9 * n) + ppk**2 / (2 * (n - 1)))
    return Capability(n, mean, sd, ppk, lower95, float(inside.mean()))
