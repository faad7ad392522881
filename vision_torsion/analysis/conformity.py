"""Conformity of a gear's figures with its catalogue limits, with the uncertainty.

A catalogue gives one-sided limits: a stiffness (K1, K2, K3 at the catalogue's break
torques T1, T2) must be at least its value, an angle (lost motion at a fraction of
the rated torque T_R, the hysteresis loss) at most its value. Each figure is
judged by its session mean ``y`` and that mean's expanded uncertainty ``U`` (the
analysis' ``mean_u95``, ``U = k·u`` with its stated coverage factor).

Decision rule
-------------
ISO 14253-1:2017 with guard bands of width ``U`` on both sides of the limit:

========== ======================= ======================== ============================
limit      pass (conformity        fail (non-conformity     not decidable
           proven)                 proven)
========== ======================= ======================== ============================
minimum L  ``y − U ≥ L``           ``y + U < L``            otherwise
maximum L  ``y + U ≤ L``           ``y − U > L``            otherwise
========== ======================= ======================== ============================

A value exactly ``U`` inside the limit passes (the acceptance zone is closed); a
value exactly ``U`` outside it is not decidable (non-conformity is proven only
strictly beyond the extended zone). A withheld figure (no value, or no
uncertainty) gets ``no_value`` with the analysis' reason: a figure that is not
right is not judged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import AnalysisError

__all__ = ["Limit", "Verdict", "judge", "conformity", "overall", "describe", "decision_counts", "DECISION_RULE",
           "DECISIONS"]

#: The decision rule in one sentence, for the report and summary.json.
DECISION_RULE = (
    "ISO 14253-1 guard bands: a figure passes when its session mean lies inside the limit by at least its "
    "expanded uncertainty U (y − U ≥ minimum, y + U ≤ maximum), fails when it lies outside by more than U "
    "(y + U < minimum, y − U > maximum), and is not decidable within its uncertainty otherwise."
)
#: The possible decisions.
DECISIONS = ("pass", "fail", "not_decidable", "no_value")


@dataclass(frozen=True)
class Limit:
    """One catalogue limit on one figure of the analysis.

    Attributes
    ----------
    figure : str
        The analysis' figure name (``k1``, ``lost_motion_4pct``, ``hysteresis_loss``).
    kind : {"min", "max"}
        A lower limit (stiffness) or an upper limit (angle).
    value : float
        The limit in the figure's analysis unit (N·m/rad for stiffness, degrees for
        angles).
    """

    figure: str
    kind: str
    value: float

    def __post_init__(self):
        if self.kind not in ("min", "max"):
            raise AnalysisError(f"limit on {self.figure}: kind must be 'min' or 'max', got {self.kind!r}",
                                reason="bad_limit")
        if isinstance(self.value, bool) or not isinstance(self.value, (int, float)) or not math.isfinite(self.value):
            raise AnalysisError(f"limit on {self.figure}: value must be a finite number, got {self.value!r}",
                                reason="bad_limit")


@dataclass(frozen=True)
class Verdict:
    """The decision on one figure.

    Attributes
    ----------
    limit : Limit
    value, u95 : float or None
        The session mean and its expanded uncertainty (analysis unit); None when
        withheld.
    coverage_factor : float or None
        k of ``u95``.
    decision : {"pass", "fail", "not_decidable", "no_value"}
    reason : str
        Why, in words (the margin in units of U, or why there is no value).
    flagged : str
        The analysis' flag on the figure ("" when none): its uncertainty is
        inflated by the lack of fit, and the decision uses the inflated value.
    """

    limit: Limit
    value: float | None
    u95: float | None
    coverage_factor: float | None
    decision: str
    reason: str
    flagged: str = ""

    def to_dict(self) -> dict:
        return {"figure": self.limit.figure, "limit_kind": self.limit.kind, "limit": self.limit.value,
                "value": self.value, "u95": self.u95, "coverage_factor": self.coverage_factor,
                "decision": self.decision, "reason": self.reason, "flagged": self.flagged}


def judge(limit: Limit, value, u95) -> tuple[str, str]:
    """The decision on `value` ± `u95` (expanded) against `limit`, and why.

    Parameters
    ----------
    limit : Limit
    value, u95 : float or None
        Measured value and its expanded uncertainty, in the limit's unit.

    Returns
    -------
    (decision, reason) : tuple of str
        decision is one of :data:`DECISIONS`; see the module docstring for the rule.

    Examples
    --------
    >>> judge(Limit("k1", "min", 10.0), 12.0, 2.0)[0]
    'pass'
    >>> judge(Limit("k1", "min", 10.0), 11.0, 2.0)[0]
    'not_decidable'
    >>> judge(Limit("lost_motion_4pct", "max", 1.0), 1.5, 0.4)[0]
    'fail'
    """
    if value is None or u95 is None or not math.isfinite(value) or not math.isfinite(u95) or u95 < 0:
        return "no_value", "no value with an uncertainty to judge"
    margin = (value - limit.value) if limit.kind == "min" else (limit.value - value)  # > 0: inside the limit
    if margin >= u95:
        decision = "pass"
    elif -margin > u95:
        decision = "fail"
    else:
        decision = "not_decidable"
    side = "inside" if margin >= 0 else "outside"
    if u95 > 0:
        return decision, f"{side} the limit by {abs(margin) / u95:.2g} U"
    return decision, f"{side} the limit (U = 0)"


def conformity(summary: dict, limits) -> tuple[Verdict, ...]:
    """Judge the session means of `summary` against `limits`.

    Parameters
    ----------
    summary : dict
        :attr:`SessionAnalysis.summary <vision_torsion.analysis.SessionAnalysis.summary>`:
        figure -> ``{"mean", "mean_u95", "coverage_factor", "flag", ...}``.
    limits : sequence of Limit

    Returns
    -------
    tuple of Verdict
        One per limit, in order. A figure missing from `summary` or without a mean
        gets ``no_value`` with the analysis' reason (its flag, or "not computed").
    """
    out = []
    for limit in limits:
        s = summary.get(limit.figure) or {}
        value, u95 = s.get("mean"), s.get("mean_u95")
        decision, reason = judge(limit, value, u95)
        if decision == "no_value":
            why = s.get("flag") or ("not computed from these data" if not s else "withheld by the analysis")
            reason = f"{reason}: {why}"
        out.append(Verdict(limit=limit, value=value, u95=u95, coverage_factor=s.get("coverage_factor"),
                           decision=decision, reason=reason,
                           flagged=str(s.get("flag") or "") if decision != "no_value" else ""))
    return tuple(out)


def overall(verdicts) -> str:
    """The gear's verdict over all its limits: ``"fail"`` when any figure fails,
    ``"pass"`` when every figure passes, else ``"not_decided"`` (a figure not
    decidable within its uncertainty, or without a value, and none failing).

    Examples
    --------
    >>> v = lambda d: Verdict(Limit("k1", "min", 1.0), 1.0, 0.1, 2.0, d, "")
    >>> overall([v("pass"), v("not_decidable")]), overall([v("pass"), v("fail")]), overall([v("pass")])
    ('not_decided', 'fail', 'pass')
    """
    decisions = [v.decision for v in verdicts]
    if "fail" in decisions:
        return "fail"
    return "pass" if decisions and all(d == "pass" for d in decisions) else "not_decided"


def describe(verdicts) -> str:
    """One line: the overall verdict and the count of each decision.

    Examples
    --------
    >>> v = lambda d: Verdict(Limit("k1", "min", 1.0), 1.0, 0.1, 2.0, d, "")
    >>> describe([v("pass"), v("not_decidable")])
    'NOT DECIDED: 1 pass, 0 fail, 1 not decidable within the uncertainty, 0 without a value'
    """
    return f"{overall(verdicts).replace('_', ' ').upper()}: {decision_counts(verdicts)}"


def decision_counts(verdicts) -> str:
    """``"1 pass, 0 fail, 1 not decidable within the uncertainty, 0 without a value"``."""
    n = {d: sum(v.decision == d for v in verdicts) for d in DECISIONS}
    return (f"{n['pass']} pass, {n['fail']} fail, {n['not_decidable']} not decidable within the uncertainty, "
            f"{n['no_value']} without a value")
