"""Fuse every camera's cylinders, track everyone in the site, and publish tracks, occupancy and
alerts.

    bevflow serve tracker --site site.yaml

Camera results arrive on Zenoh threads, unsynchronised and sometimes late. They go into a
``TickAssembler`` (capture-time slots, a bounded wait for late cameras); the main thread releases
ready ticks in time order and hands each to a ``TickHandler`` (``ticks.py``): the ``SiteTracker``
steps with it, and a ``DriftMonitor`` compares overlapping cameras' estimates of the same people
to raise a ``calibration_drift`` alert when a camera seems to have moved (``--no-drift`` turns that
off). A camera silent for ``--camera-timeout`` seconds (``--camera-first-report`` before its first
result since the tracker started) raises a ``camera_down`` alert, ended once
it has reported again for ``--camera-up-after`` seconds without falling silent (a camera that keeps
dropping out, on an overloaded machine, is one alert, not one per dropout). Every few seconds it
publishes the ids of the alerts it still has open (``OpenAlerts``), which renews their lease: an
open alert nobody renews ends by itself (``bevflow.alert_lease``).
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import threading
import time
from pathlib import Path

from bevflow.alert_lease import RENEW_EVERY_S
from bevflow.calibration.drift import DriftConfig
from bevflow.live.assembler import TickAssembler
from bevflow.live.site_tracker import SiteTracker
from bevflow.schemas import CameraCylinders, CameraHealthEvent, Event, Occupancy, OpenAlerts, Tracks
from bevflow.units import NS_PER_S

from bevflow_services import bus
from bevflow_services.runtime import CAMERA_FIRST_REPORT_S, CAMERA_SILENCE_S, UserError, service_site, stop_on_signals
from bevflow_services.service_metrics import MetricsBook, reporting
from bevflow_services.tracker.ticks import TickHandler
from bevflow_services.tracker.track_ids import TrackIdError, TrackIdReservation

log = logging.getLogger(__name__)
SERVICE = "tracker"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("tracker")
    group.add_argument("--tick-ms", type=float, default=100.0,
                       help="length of one tracking tick; match the cameras' frame interval (default 100 = 10 fps)")
    group.add_argument("--max-wait-ms", type=float, default=150.0,
                       help="how long a tick waits for a late camera before it goes without it (default 150)")
    group.add_argument("--camera-timeout", type=float, default=CAMERA_SILENCE_S,
                       help=f"seconds of silence after which a camera is reported down (default {CAMERA_SILENCE_S:g})")
    group.add_argument("--camera-first-report", type=float, default=CAMERA_FIRST_REPORT_S,
                       help="seconds a camera may take to send its first result after the tracker starts before it is "
                       f"reported down (default {CAMERA_FIRST_REPORT_S:g}; never less than --camera-timeout)")
    group.add_argument("--camera-up-after", type=float, default=10.0,
                       help="seconds a camera reported down must report steadily before it counts as up again (default 10)")
    group.add_argument("--event-cache", type=int, default=10000,
                       help="recent alerts kept for a history recorder that restarts (default 10000)")
    group.add_argument("--first-id", type=int, default=1,
                       help="lowest track id to hand out (default 1)")
    group.add_argument("--id-file", type=Path, default=None,
                       help="file that reserves track ids across restarts, so a restarted tracker never reuses an id "
                       "(default: none, ids start again at --first-id)")
    drift = DriftConfig()
    group.add_argument("--no-drift", action="store_true",
                       help="do not watch for cameras that have moved since calibration (calibration_drift alerts)")
    group.add_argument("--drift-shift", type=float, default=drift.shift_m, metavar="M",
                       help=f"how far (metres) two overlapping cameras' estimates of the same people must move apart "
                       f"before a camera is reported moved (default {drift.shift_m:g})")
    group.add_argument("--drift-warmup", type=float, default=drift.warmup_s, metavar="S",
                       help=f"seconds after start during which the cameras' normal disagreement is learnt (default {drift.warmup_s:g})")
    group.add_argument("--drift-window", type=float, default=drift.window_s, metavar="S",
                       help=f"seconds of recent samples compared with it (default {drift.window_s:g})")


def drift_config(args: argparse.Namespace) -> DriftConfig | None:
    """The drift watch's settings from the command line; None with ``--no-drift``."""
    if args.no_drift:
        return None
    try:
        return DriftConfig(warmup_s=args.drift_warmup, window_s=args.drift_window, shift_m=args.drift_shift)
    except ValueError as exc:
        raise UserError(f"--drift-*: {exc}") from None


class CameraWatch:
    """Per camera, when it last reported; ``check`` turns silences into down/up alerts. A camera
    that is down counts as up again once it has reported for ``up_after_ns`` without a silence. A
    camera that has not reported since ``now_ns`` (the start) is down only after ``first_report_ns``
    (at least ``timeout_ns``)."""

    def __init__(self, cameras: list[str], timeout_ns: int, now_ns: int, up_after_ns: int = 0,
                 first_report_ns: int = 0) -> None:  # fmt: skip
        self.timeout_ns = timeout_ns
        self.up_after_ns = up_after_ns
        self.first_report_ns = max(timeout_ns, first_report_ns)
        self.last_ns = dict.fromkeys(cameras, now_ns)
        self.waiting = set(cameras)  # not heard from since the start
        self.down: dict[str, CameraHealthEvent] = {}
        self.back_ns: dict[str, int] = {}  # down cameras reporting again: since when, without a silence

    def seen(self, camera: str, now_ns: int) -> None:
        if camera in self.down and now_ns - self.last_ns[camera] > self.timeout_ns:
            self.back_ns[camera] = now_ns  # back after a silence: the steady stretch starts now
        self.last_ns[camera] = now_ns
        self.waiting.discard(camera)

    def check(self, now_ns: int) -> list[CameraHealthEvent]:
        events = []
        for camera, last in self.last_ns.items():
            first = camera in self.waiting
            limit = self.first_report_ns if first else self.timeout_ns
            silent = now_ns - last > limit
            if silent and camera not in self.down:
                # raised_ns, as every alert has: when it was found, which orders it among the
                # alerts (a client resuming the alert websocket relies on it).
                reason = f"no results since the tracker started {limit / 1e9:.0f} s ago" if first else \
                    f"no results for {limit / 1e9:.0f} s"
                self.down[camera] = CameraHealthEvent(
                    id=f"camera-{camera}-{last}", type="camera_down", camera=camera, start_ns=last,
                    raised_ns=now_ns, reason=reason)
                events.append(self.down[camera])
            elif not silent and camera in self.down and now_ns - self.back_ns.get(camera, last) >= self.up_after_ns:
                back = self.back_ns.pop(camera, last)
                ended = self.down.pop(camera).model_copy(update={"end_ns": back, "raised_ns": now_ns})
                events.append(ended)
                events.append(CameraHealthEvent(id=f"{ended.id}-up", type="camera_up", camera=camera,
                                                start_ns=back, end_ns=back, raised_ns=now_ns))
        return events


class OpenAlertBook:
    """The alerts this tracker has raised and not ended, and when to renew them next."""

    def __init__(self, site_id: str, renew_every_s: float = RENEW_EVERY_S) -> None:
        self.site_id = site_id
        self.ids: set[str] = set()
        self.renew_every_ns = int(renew_every_s * NS_PER_S)
        self._next_ns: int | None = None

    def observe(self, event: Event) -> None:
        (self.ids.add if event.end_ns is None else self.ids.discard)(event.id)

    def renewal(self, now_ns: int) -> OpenAlerts | None:
        """The renewal to publish now, if one is due."""
        if self._next_ns is not None and now_ns < self._next_ns:
            return None
        self._next_ns = now_ns + self.renew_every_ns
        return OpenAlerts(site=self.site_id, time_ns=now_ns, ids=sorted(self.ids))


def reserve_ids(reservation: TrackIdReservation, next_id: int) -> None:
    """Reserve ids before any new one leaves the process. If the disk fails, tracking goes on (a
    site without tracks is worse) and the log says that a restart may now reuse ids."""
    try:
        reservation.cover(next_id)
    except TrackIdError as exc:
        log.error("%s; a restarted tracker may reuse track ids until this is fixed", exc)


def main(args: argparse.Namespace) -> int:
    site, site_id = service_site(args)
    keys = bus.Keys(site_id)
    reservation = TrackIdReservation(args.id_file) if args.id_file else None
    try:
        first_id = reservation.first_id(args.first_id) if reservation else args.first_id
    except TrackIdError as exc:
        raise UserError(str(exc)) from None
    tracker = SiteTracker(site, first_id=first_id)
    handler = TickHandler(site, tracker, drift_config(args))
    assembler: TickAssembler[CameraCylinders] = TickAssembler(
        site.camera_ids, period_ns=int(args.tick_ms * 1e6), max_wait_ns=int(args.max_wait_ms * 1e6))
    watch = CameraWatch(site.camera_ids, int(args.camera_timeout * 1e9), time.time_ns(), int(args.camera_up_after * 1e9),
                        int(args.camera_first_report * 1e9))
    lock = threading.Lock()
    book = MetricsBook()
    for camera in site.camera_ids:  # every camera's series from the start, at 0
        book.count("camera_frames_late", 0, camera=camera)

    def on_cylinders(message: CameraCylinders) -> None:  # on a Zenoh thread
        with lock:
            now = time.time_ns()
            result = assembler.push(message.camera, message.capture_ns, message, now_ns=now)
            if result == "accepted":
                watch.seen(message.camera, now)
        if result == "late":
            book.count("camera_frames_late", camera=message.camera)
        if result != "accepted":
            log.debug("cylinders from %s at %d: %s", message.camera, message.capture_ns, result)

    # Timestamps let the events' cache serve a restarted recorder what it missed.
    session = bus.open_session(dataclasses.replace(bus.config_from_args(args), timestamping=True))
    stats = bus.BusStats()
    tracks_out = bus.Publication(session, keys.tracks, bus.JsonCodec(Tracks))
    occupancy_out = bus.Publication(session, keys.occupancy, bus.JsonCodec(Occupancy))
    events_out = bus.CachedPublication(session, keys.events, bus.JsonCodec[Event](Event, "Event"), cache=args.event_cache)
    renewals_out = bus.Publication(session, keys.open_alerts, bus.JsonCodec(OpenAlerts))
    open_alerts = OpenAlertBook(site_id)

    def raise_alert(event: Event) -> None:
        open_alerts.observe(event)
        events_out.put(event)
    inbox = bus.subscribe(session, keys.cylinders("*"), bus.JsonCodec(CameraCylinders), on_cylinders, stats=stats)
    token = bus.announce(session, keys, SERVICE)
    drift = handler.drift.config if handler.drift is not None else None
    watch_line = "off" if drift is None else f"on (learns for {drift.warmup_s:g} s, then reports shifts over {drift.shift_m:g} m)"
    print(f"bevflow tracker: site {site_id!r}, {len(site.camera_ids)} cameras, tick {args.tick_ms:g} ms; "
          f"calibration drift watch {watch_line}", flush=True)
    try:
        with stop_on_signals() as stop, reporting(session, site_id, SERVICE, book):
            while not stop.wait(0.01):
                with lock:
                    now = time.time_ns()
                    ticks = assembler.pop_ready(now_ns=now)
                    health = watch.check(now)
                for alert in health:
                    raise_alert(alert)
                for tick in ticks:
                    try:
                        with book.timed("tick_duration_seconds"):
                            output = handler.handle(tick)
                    except Exception:  # a bug on one tick must not stop the site
                        stats.count("handler_errors")
                        log.exception("tracking failed at tick %d; skipping it", tick.time_ns)
                        continue
                    if reservation:
                        reserve_ids(reservation, tracker.tracker.next_id)
                    tracks_out.put_json(output.tracks_json)
                    occupancy_out.put(output.occupancy)
                    for event in output.events:
                        raise_alert(event)
                renewal = open_alerts.renewal(now)
                if renewal is not None:
                    renewals_out.put(renewal)
    finally:
        token.undeclare()
        inbox.close()
        for publication in (tracks_out, occupancy_out, events_out, renewals_out):
            publication.close()
        session.close()
        log.info("tracker stopped; next track id %d; assembler %s", tracker.tracker.next_id, dict(assembler.counts))
    return 0
