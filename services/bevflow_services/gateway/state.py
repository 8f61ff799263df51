"""Everything the gateway knows about one site, fed message by message, read by the routes.

``GatewayState.apply`` takes the bus's messages (tracks, occupancy, events, per-camera frame
metadata) and keeps the latest of each, the history (through a ``HistoryStore``), camera health,
the set of live services, and the currently active alerts; it fans tracks and alerts out to
websocket subscribers. It is plain Python: tests drive it directly, and ``main`` feeds it from the
bus. ``apply`` and the readers may run on different threads.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from bevflow.alert_lease import OpenAlertLeases, RateLimit
from bevflow.capture_time import CaptureWindow
from bevflow.schemas import (
    AlertMessage,
    CameraCylinders,
    CameraHealthEvent,
    Detections2D,
    Event,
    EventBase,
    FrameHeader,
    Occupancy,
    OpenAlerts,
    Tracks,
    zones_named,
)
from bevflow.site import Site

from bevflow_services.gateway.camera_health import CameraHealth, CameraHealthBook
from bevflow_services.gateway.degraded import DataQuality, DegradedPeriod
from bevflow_services.gateway.fanout import Broadcaster
from bevflow_services.gateway.history import HistoryStore, InMemoryHistory
from bevflow_services.runtime import CAMERA_SILENCE_S

log = logging.getLogger(__name__)

IGNORE_LOG_EVERY_S = 10.0
StateMessage = Tracks | Occupancy | Event | OpenAlerts | FrameHeader | Detections2D | CameraCylinders


@dataclass(frozen=True)
class TickTiming:
    """The tracker's ticks as the gateway received them: how many, the sum of their capture-to-
    arrival times, the newest one's, and the capture interval of the newest two (None until known)."""

    count: int
    latency_sum_s: float
    latency_s: float | None
    interval_s: float | None


@dataclass(frozen=True)
class ServiceEntry:
    """A live service instance, as its liveliness token announced it."""

    name: str
    instance: str
    since_ns: int


class GatewayState:
    """The gateway's view of one site.

    Args:
        site: the site being served; messages for another site or an unknown camera are ignored.
        site_id: the site's name on the bus if it differs from ``site.site``; messages naming
            either are accepted.
        history: where history goes; an in-memory hour by default.
        clock: wall-clock nanoseconds, injectable so tests control camera timeouts.
        camera_timeout_s: silence after which a camera counts as down.
        alert_queue: per-websocket-client queue length for alerts (oldest dropped when full).
        tracks_queue: the same for the live tracks stream; small, since only the newest matters.
        window: how far from ``clock`` live capture times may be (``bevflow.capture_time``).
    """

    def __init__(
        self,
        site: Site,
        history: HistoryStore | None = None,
        *,
        site_id: str | None = None,
        clock: Callable[[], int] = time.time_ns,
        camera_timeout_s: float = CAMERA_SILENCE_S,
        alert_queue: int = 256,
        tracks_queue: int = 4,
        window: CaptureWindow | None = None,
    ) -> None:
        self.site = site
        self.site_id = site_id or site.site
        self._site_names = {site.site, self.site_id}
        self._zone_ids = frozenset(z.id for z in site.zones)
        self.history: HistoryStore = history if history is not None else InMemoryHistory()
        self.clock = clock
        self.window = window if window is not None else CaptureWindow.from_environment()
        self.alerts: Broadcaster[AlertMessage] = Broadcaster(alert_queue)
        self.tracks_stream: Broadcaster[Tracks] = Broadcaster(tracks_queue)
        self.started_ns = clock()
        self._lock = threading.Lock()
        self._cameras = CameraHealthBook([c.id for c in site.cameras], camera_timeout_s)
        self._quality = DataQuality()
        self._tracks: Tracks | None = None
        self._tracks_received_ns: int | None = None
        self._occupancy: Occupancy | None = None
        # The open alerts, each with when it last arrived or was renewed on the gateway's clock.
        self._leases = OpenAlertLeases()
        self._new_alerts = RateLimit()
        self._services: dict[tuple[str, str], ServiceEntry] = {}
        self.ignored = 0  # messages refused (other site, unknown camera), for /api/health
        self._last_ignore_log = -IGNORE_LOG_EVERY_S

    # --- input ---------------------------------------------------------------------------------
    def apply(self, message: StateMessage) -> bool:
        """Take one bus message into account; False (and a log line) if it was ignored."""
        if isinstance(message, (Tracks, Occupancy, EventBase)) and (unknown := zones_named(message) - self._zone_ids):
            shown = ", ".join(repr(z[:40]) for z in sorted(unknown)[:3])
            return self._ignore(f"{type(message).__name__} naming zones the site does not have: {shown}")
        if isinstance(message, Tracks):
            return self._apply_tracks(message)
        if isinstance(message, Occupancy):
            return self._apply_occupancy(message)
        if isinstance(message, EventBase):
            return self._apply_event(message)  # type: ignore[arg-type]
        if isinstance(message, OpenAlerts):
            return self._renew(message)
        if isinstance(message, (FrameHeader, Detections2D, CameraCylinders)):
            with self._lock:
                known = self._cameras.record_frame(message.camera, message.seq, message.capture_ns, self.clock())
            return known or self._ignore(f"message from unknown camera {message.camera!r}")
        raise TypeError(f"GatewayState cannot apply a {type(message).__name__}")

    def _apply_tracks(self, tracks: Tracks) -> bool:
        if tracks.site not in self._site_names:
            return self._ignore(f"tracks for site {tracks.site!r}")
        # The bus refuses times beyond the future bound; the past bound keeps stale data out.
        if self.window.too_old(tracks.time_ns, self.clock()):
            return self._ignore(f"tracks at {tracks.time_ns} ns, older than the live window of this host's clock")
        latest = self._tracks
        if latest is not None and tracks.time_ns < latest.time_ns:
            return self._ignore(f"tracks at {tracks.time_ns} ns, older than the latest ({latest.time_ns} ns)")
        try:
            self.history.add_tracks(tracks)
        except ValueError as exc:  # repeated or out-of-range track ids: a tracker bug, not a reason to stop
            return self._ignore(f"tracks at {tracks.time_ns} ns: {exc}")
        with self._lock:
            self._tracks = tracks
            self._tracks_received_ns = self.clock()
            self._quality.tick(tracks.time_ns, self._tracks_received_ns)
            check = self._quality.due(self._tracks_received_ns)
        if check:  # the degraded periods are recorded whether or not anyone asks for /api/health
            self.degraded()
        self.tracks_stream.publish(tracks)
        return True

    def _apply_occupancy(self, occupancy: Occupancy) -> bool:
        if occupancy.site not in self._site_names:
            return self._ignore(f"occupancy for site {occupancy.site!r}")
        if self.window.too_old(occupancy.time_ns, self.clock()):
            return self._ignore(f"occupancy at {occupancy.time_ns} ns, older than the live window of this host's clock")
        with self._lock:
            if self._occupancy is None or occupancy.time_ns >= self._occupancy.time_ns:
                self._occupancy = occupancy
        self.history.add_occupancy(occupancy)
        return True

    def _apply_event(self, event: Event) -> bool:
        now = self.clock()
        with self._lock:
            if event.id not in self._leases and not self._new_alerts.allow(now):
                return self._ignore(f"alert {event.id!r}: more new alerts than the bus may bring (a flood)")
            if not self._leases.room_for(event):
                return self._ignore(f"alert {event.id!r}: {self._leases.max_open} alerts are open already")
            if isinstance(event, CameraHealthEvent) and not self._cameras.record_event(event):
                return self._ignore(f"{event.type} for unknown camera {event.camera!r}")
            if isinstance(event, CameraHealthEvent) and event.type == "camera_up":
                # "up" is a moment, not a condition: it only ends the camera's open "down" alerts.
                for other in [e for e in self._leases.held() if e.type == "camera_down" and e.camera == event.camera]:
                    self._leases.closed(other.id)
            elif event.end_ns is None:
                self._leases.opened(event, now)
            else:
                self._leases.closed(event.id)
        self.history.add_event(event)
        self.alerts.publish(AlertMessage.from_event(event))
        return True

    def _renew(self, renewal: OpenAlerts) -> bool:
        if renewal.site not in self._site_names:
            return self._ignore(f"open alerts for site {renewal.site!r}")
        now = self.clock()
        with self._lock:
            self._leases.renew(renewal.ids, now)
        return True

    def end_lapsed_alerts(self) -> list[Event]:
        """End the open alerts nobody renewed within the lease (forged, or left open by a tracker
        that died): each ends at its last renewal, goes to the history and to the websocket
        clients. Call it now and then on the thread that applies messages; returns what ended."""
        now = self.clock()
        with self._lock:
            ended = self._leases.lapsed(now)
        for event in ended:
            self.history.add_event(event)
            self.alerts.publish(AlertMessage.from_event(event))
        if ended:
            log.warning("%d open alerts ended by themselves: no renewal from the tracker for their lease", len(ended))
        return ended

    def _ignore(self, why: str) -> bool:
        self.ignored += 1
        now = time.monotonic()
        if now - self._last_ignore_log >= IGNORE_LOG_EVERY_S:  # a stream of bad messages logs a line now and then
            self._last_ignore_log = now
            log.warning("gateway ignored %s (%d ignored so far)", why, self.ignored)
        return False

    def service_up(self, name: str, instance: str) -> None:
        """A service's liveliness token appeared."""
        with self._lock:
            self._services.setdefault((name, instance), ServiceEntry(name, instance, self.clock()))

    def service_down(self, name: str, instance: str) -> None:
        """A service's liveliness token went away (it stopped or its process died)."""
        with self._lock:
            self._services.pop((name, instance), None)

    # --- output --------------------------------------------------------------------------------
    @property
    def tracks(self) -> Tracks | None:
        return self._tracks

    @property
    def occupancy(self) -> Occupancy | None:
        return self._occupancy

    def tracks_age_s(self) -> float | None:
        """Seconds since the latest tracks message arrived (gateway clock), None before the first."""
        received = self._tracks_received_ns
        return None if received is None else max(0.0, (self.clock() - received) / 1e9)

    def tick_timing(self) -> TickTiming:
        """How late the ticks reach the gateway and how far apart they are (``/metrics``)."""
        with self._lock:
            ticks = self._quality.latest_ticks()
            count, latency_sum_ns = self._quality.ticks, self._quality.latency_sum_ns
        return TickTiming(
            count=count,
            latency_sum_s=latency_sum_ns / 1e9,
            latency_s=(ticks[-1][1] - ticks[-1][0]) / 1e9 if ticks else None,
            interval_s=(ticks[-1][0] - ticks[-2][0]) / 1e9 if len(ticks) == 2 else None,
        )

    def active_alerts(self) -> list[Event]:
        """Alerts that have started and not ended (nor lapsed), oldest first."""
        now = self.clock()
        with self._lock:
            live = self._leases.live(now)
        return sorted(live, key=lambda e: (e.start_ns, e.id))

    def camera_health(self) -> list[CameraHealth]:
        """Every site camera's health, in site order."""
        now = self.clock()
        with self._lock:
            return [self._cameras.health(c.id, now) for c in self.site.cameras]

    def degraded(self) -> tuple[list[str], list[DegradedPeriod]]:
        """What is wrong with the live data now (``bevflow_services.gateway.degraded``; empty if
        nothing), and the degraded periods of the last hour, oldest first."""
        cameras = self.camera_health()
        with self._lock:
            reasons = self._quality.reasons(self.clock(), cameras)
            return reasons, [DegradedPeriod(p.start_ns, p.end_ns, list(p.reasons)) for p in self._quality.periods]

    def services(self) -> list[ServiceEntry]:
        """Live service instances, sorted by name then instance."""
        with self._lock:
            return sorted(self._services.values(), key=lambda s: (s.name, s.instance))
