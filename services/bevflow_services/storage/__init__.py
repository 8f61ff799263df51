"""Where the site's history is kept: SQLite (embedded, the default) or PostgreSQL, behind one
``HistoryDatabase``.

The recorder (``bevflow serve recorder --db URL``) writes the tracker's output in batches; the
gateway (``bevflow serve gateway --db URL``) reads it. A URL is a SQLite file path (or
``sqlite:///PATH``) or a ``postgresql://user:password@host/database`` URL; tables are created and
migrated on open. The same database keeps the gateway's users, sessions, API tokens and audit log
(``AccessStore``).
"""

from bevflow_services.storage.batch import Batch, TrackSampler
from bevflow_services.storage.records import (
    SITE,
    Acknowledgement,
    EventFilter,
    OccupancyPoint,
    RetentionPolicy,
    RetentionResult,
    StorageDamaged,
    StorageError,
    StorageUnavailable,
    TrackSummary,
    ZoneVisit,
)
from bevflow_services.storage.store import HistoryDatabase
from bevflow_services.storage.access import AccessStore  # noqa: E402  (it builds on store)

__all__ = [
    "SITE",
    "AccessStore",
    "Acknowledgement",
    "Batch",
    "EventFilter",
    "HistoryDatabase",
    "OccupancyPoint",
    "RetentionPolicy",
    "RetentionResult",
    "StorageDamaged",
    "StorageError",
    "StorageUnavailable",
    "TrackSampler",
    "TrackSummary",
    "ZoneVisit",
]
