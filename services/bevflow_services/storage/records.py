"""What the history database holds and returns, as plain typed values.

Times are capture times in integer nanoseconds since the Unix epoch, positions are metres on the
floor, as everywhere in bevflow.
"""

from __future__ import annotations

from dataclasses import dataclass, field


DAY_S = 86_400.0
SITE = ""  # the zone key of site-wide counts (zone ids are never empty)


class StorageError(Exception):
    """A database that cannot be used as asked (a bad URL, a schema from a newer release); one
    line, fit to show a user as is."""


class StorageDamaged(StorageError):
    """The database file is corrupt: retrying will not help, restoring a backup will."""


class StorageUnavailable(StorageError):
    """The database did not answer (locked, restarting, unreachable). Retrying later may work;
    nothing of the failed call was written."""


@dataclass(frozen=True)
class OccupancyPoint:
    """The highest counts in the ``step_s`` seconds from ``time_ns``: ``total`` site-wide, and
    per zone id in ``zones`` (zones with no stored count are absent)."""

    time_ns: int
    step_s: int
    total: int
    zones: dict[str, int]


@dataclass(frozen=True)
class EventFilter:
    """Which alerts to list. An alert matches the time range when it overlaps it: it started at
    or before ``until_ns`` and had not ended before ``since_ns``."""

    types: frozenset[str] | None = None
    zone: str | None = None
    track: int | None = None
    active: bool | None = None
    since_ns: int | None = None
    until_ns: int | None = None
    # An open alert not written nor renewed since then has lapsed (``bevflow.alert_lease``): it is
    # listed as ended, at its last renewal, even before the recorder closes it.
    renewed_since_ns: int | None = None


@dataclass(frozen=True)
class ZoneVisit:
    zone: str
    first_ns: int
    last_ns: int


@dataclass(frozen=True)
class TrackSummary:
    """A track as stored: when it was first and last sampled, how many positions are kept, and
    the zones it was sampled in."""

    track_id: int
    first_ns: int
    last_ns: int
    points: int
    zones: list[ZoneVisit] = field(default_factory=list)


@dataclass(frozen=True)
class Acknowledgement:
    """Someone (``user``) acknowledged an alert at ``time_ns``."""

    id: int
    event_id: str
    user: str
    time_ns: int
    note: str = ""


@dataclass(frozen=True)
class RetentionPolicy:
    """How long each kind of history is kept, counted back from "now".

    Occupancy is kept per second for ``fine_s``, then as ``coarse_step_s`` maxima (and means) until
    ``occupancy_s``. Trajectories are personal data and get a shorter default.
    """

    fine_s: float = 7 * DAY_S
    coarse_step_s: int = 60
    occupancy_s: float = 365 * DAY_S
    events_s: float = 365 * DAY_S
    tracks_s: float = 30 * DAY_S

    def __post_init__(self) -> None:
        for name in ("fine_s", "occupancy_s", "events_s", "tracks_s"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        if not 1 <= self.coarse_step_s <= 86_400 or 86_400 % self.coarse_step_s:
            raise ValueError(f"coarse_step_s must divide a day (1 to 86400 s), got {self.coarse_step_s}")
        if self.fine_s > self.occupancy_s:
            raise ValueError(f"fine_s ({self.fine_s:g}) must not exceed occupancy_s ({self.occupancy_s:g})")


@dataclass(frozen=True)
class RetentionResult:
    """What one ``apply_retention`` call did; ``done`` is False when work remains for the next one."""

    rolled_up_rows: int = 0
    deleted: dict[str, int] = field(default_factory=dict)
    done: bool = True
