"""``Recorder``: the tracker's messages in, batches of rows out to the history database.

Messages arrive on Zenoh threads and go into the pending ``Batch`` under a lock (cheap: a few
dictionary updates); ``flush``, called by the service's main loop at least once a second, swaps
the batch out and writes it in one transaction. If the database does not answer, the batch goes
back in front of what arrived meanwhile and the next flush tries again; alerts are never dropped,
while occupancy and positions are capped (oldest dropped first) so memory stays bounded during a
long database outage.

What a hard kill loses: the pending batch, that is what arrived since the last flush began. For
occupancy and positions that is at most one flush interval plus one write. Alerts lost that way
come back when the recorder restarts: it subscribes to alerts with
``bus.HistorySubscription``, which fetches what the tracker's ``bus.CachedPublication`` still
caches, and writing an alert twice changes nothing (see ``storage.batch``).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable

from bevflow.alert_lease import LEASE_S, RateLimit
from bevflow.capture_time import CaptureWindow
from bevflow.schemas import Event, Occupancy, OpenAlerts, Tracks, zones_named
from bevflow.units import NS_PER_S

from bevflow_services.storage import Batch, HistoryDatabase, StorageUnavailable, TrackSampler

log = logging.getLogger(__name__)


class Recorder:
    """Gathers messages between flushes and writes them to ``db``.

    Args:
        track_period_s: one stored position per track per this many seconds of capture time.
        max_pending_rows: while the database is down, keep at most this many occupancy rows and
            as many positions (alerts are always kept).
        clock: wall-clock nanoseconds, stored with each alert as when it was recorded.
        window: how old (by ``clock``) occupancy and positions may be and still be stored
            (``bevflow.capture_time``; the bus refuses times in the future); older ones are counted
            in ``counts["outside_window"]``.

    With ``zones`` (the site's zone ids), a message naming another zone is not stored (counted in
    ``counts["unknown_zones"]``): a forged id must not reach the history or its CSV exports.

    Alerts come at most at ``bevflow.alert_lease``'s rate (a flood is refused and counted in
    ``counts["events_refused"]``), and ``end_lapsed_alerts`` ends the open ones the tracker stopped
    renewing (``on_open_alerts``).
    """

    def __init__(self, db: HistoryDatabase, *, track_period_s: float = 1.0, max_pending_rows: int = 1_000_000,
                 clock: Callable[[], int] = time.time_ns, window: CaptureWindow | None = None,
                 zones: frozenset[str] | None = None) -> None:
        self.db = db
        self.zones = zones
        self.max_pending_rows = max_pending_rows
        self.clock = clock
        self.window = window if window is not None else CaptureWindow.from_environment()
        self.counts: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._pending = Batch()
        self._alert_rate = RateLimit()
        # Resume sampling after the newest stored position, so a restart mid-second does not
        # store a second sample in the same period; a stored position beyond the clock (written
        # before the bus refused such times) is not one to resume after.
        newest = db.newest_track_time_ns(until_ns=self.window.latest_ns(clock()))
        self._sampler = TrackSampler(track_period_s, newest)

    # --- input, on Zenoh threads ----------------------------------------------------------------
    def _known_zones(self, message: Tracks | Occupancy | Event) -> bool:
        known = self.zones is None or zones_named(message) <= self.zones
        if not known:
            self.counts["unknown_zones"] += 1
        return known

    def _live(self, time_ns: int) -> bool:
        live = not self.window.too_old(time_ns, self.clock())
        if not live:
            self.counts["outside_window"] += 1
        return live

    def on_occupancy(self, occupancy: Occupancy) -> None:
        with self._lock:
            if self._known_zones(occupancy) and self._live(occupancy.time_ns):
                self._pending.add_occupancy(occupancy)
                self.counts["occupancy"] += 1

    def on_tracks(self, tracks: Tracks) -> None:
        with self._lock:
            if self._known_zones(tracks) and self._live(tracks.time_ns) and self._sampler.keep(tracks.time_ns):
                self._pending.add_track_sample(tracks)
                self.counts["track_samples"] += 1

    def on_event(self, event: Event) -> None:
        with self._lock:
            if not self._known_zones(event):
                return
            if not self._alert_rate.allow(self.clock()):
                self.counts["events_refused"] += 1
                return
            self._pending.add_event(event)
            self.counts["events"] += 1

    def on_open_alerts(self, renewal: OpenAlerts) -> None:
        with self._lock:
            self._pending.renewals.update(renewal.ids)
            self.counts["renewals"] += 1

    def end_lapsed_alerts(self) -> int:
        """End the stored open alerts that nobody renewed within the lease; returns how many."""
        ended = self.db.end_lapsed_events(self.clock() - int(LEASE_S * NS_PER_S))
        if ended:
            self.counts["lapsed_alerts"] += ended
            log.warning("%d open alerts ended by themselves: no renewal from the tracker for their lease", ended)
        return ended

    # --- output, on the main thread -------------------------------------------------------------
    def pending(self) -> int:
        """Rows waiting for the next flush."""
        with self._lock:
            return len(self._pending)

    def flush(self) -> int:
        """Write what is pending in one transaction; returns the rows written. Raises
        ``StorageUnavailable`` (after putting the rows back) when the database does not answer."""
        with self._lock:
            batch, self._pending = self._pending, Batch()
        if not batch:
            return 0
        try:
            self.db.write(batch, recorded_ns=self.clock())
        except StorageUnavailable:
            with self._lock:
                batch.merge(self._pending)
                self._pending = batch
                dropped = batch.drop_oldest_samples(self.max_pending_rows)
            self.counts["failed_flushes"] += 1
            if dropped:
                self.counts["dropped_rows"] += dropped
                log.warning("database down: dropped the %d oldest occupancy/position rows held for it", dropped)
            raise
        self.counts["flushes"] += 1
        self.counts["rows_written"] += len(batch)
        return len(batch)
