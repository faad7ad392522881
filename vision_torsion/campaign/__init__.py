"""Campaigns: every tested gear's reports in one database, compared, followed over a
life test and summarised for a batch.

- :func:`add_reports` — add report folders (``vision-torsion campaign add``);
- :func:`list_reports`, :func:`compare_serials`, :func:`figure_trend` — questions
  asked of a campaign;
- :func:`write_campaign_report` — the batch page with control charts, conformity
  and capability;
- :func:`export_campaign` — every figure of every record as CSV or Parquet;
- :class:`CampaignDB` — the database itself (SQLite; records immutable).
"""

from .._lazy import attach

_LAZY = {
    "CampaignDB": "store",
    "AddResult": "store",
    "read_report": "records",
    "ReportRecord": "records",
    "FigureRecord": "records",
    "AddOutcome": "views",
    "add_reports": "views",
    "list_reports": "views",
    "compare_serials": "views",
    "figure_trend": "views",
    "export_campaign": "views",
    "write_campaign_report": "page",
    "CampaignReport": "page",
    "difference": "stats",
    "fit_trend": "stats",
    "control_limits": "stats",
    "capability": "stats",
}

__all__ = list(_LAZY)
__getattr__, __dir__ = attach(__name__, _LAZY)
