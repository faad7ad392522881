"""Campaigns: every tested gear's reports in one database, compared, followed over a
life test and summarised for a batch.

- :mod:`.store` — :class:`CampaignDB`, the database itself (SQLite; records immutable);
- :mod:`.folder_record` — one report folder read as a record (:func:`read_report`);
- :mod:`.views` — :func:`add_reports`, :func:`list_reports`, :func:`compare_serials`,
  :func:`figure_trend`, :func:`export_campaign` (what the commands ask);
- :mod:`.page` — :func:`write_campaign_report`, the batch page with control charts,
  conformity and capability against a catalogue (:func:`catalogue_limits`);
- :mod:`.stats` — differences (E_n), trends, control limits, capability.
"""

from ..lazy import attach

# the modules whose __all__ make up this face, each imported on first use of one of its names
_LAZY = ("page", "folder_record", "stats", "store", "views")

__getattr__, __dir__ = attach(__name__, _LAZY)
