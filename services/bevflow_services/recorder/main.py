"""Record the site's history: occupancy, alerts and trajectories, into SQLite or PostgreSQL.

    bevflow serve recorder --site site.yaml --db /var/lib/bevflow/history.db
    bevflow serve recorder --site site.yaml --db postgresql://bevflow:PASSWORD@dbhost/bevflow

Subscribes to the tracker's occupancy, tracks and alerts, and commits what arrived at least once
per ``--commit-interval`` (0.25 s by default). Durability: a committed batch survives a killed
recorder (and, on SQLite, a power cut); a hard kill loses at most the occupancy and positions of
the last interval. No alert is lost or stored twice: alerts are fetched again from the tracker's
cache when the recorder restarts, and stored once per alert id, updated in place when it ends.
Downsampling and retention run in the same loop, a bounded slice at a time.

A database that does not answer is retried; one that is damaged (a corrupt SQLite file) leaves the
recorder nothing to do: it stops with one line saying so and what to do (exit status 2).
"""

from __future__ import annotations

import argparse
import logging
import sys
import threading
import time

from bevflow.schemas import Event, Occupancy, OpenAlerts, Tracks

from bevflow_services import bus
from bevflow_services.recorder.recorder import Recorder
from bevflow_services.runtime import UserError, service_site, stop_on_signals
from bevflow_services.service_metrics import MetricsBook, reporting
from bevflow_services.storage import HistoryDatabase, RetentionPolicy, StorageDamaged, StorageError, StorageUnavailable

log = logging.getLogger(__name__)
SERVICE = "recorder"
DAY_S = 86_400.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("recorder")
    group.add_argument("--db", required=True, metavar="URL",
                       help="the history database: a SQLite file path (created if missing) or a "
                       "postgresql://USER:PASSWORD@HOST/DATABASE URL")
    group.add_argument("--commit-interval", type=float, default=0.25, metavar="S",
                       help="seconds between commits, 0.05 to 1 (default 0.25); a hard kill loses at most "
                       "this much occupancy and trajectory data")
    group.add_argument("--track-period", type=float, default=1.0, metavar="S",
                       help="store each person's position once per this many seconds (default 1)")
    group.add_argument("--fine-days", type=float, default=7.0,
                       help="keep occupancy per second this many days, then per minute (default 7)")
    group.add_argument("--occupancy-days", type=float, default=365.0,
                       help="keep occupancy this many days in all (default 365)")
    group.add_argument("--event-days", type=float, default=365.0,
                       help="keep alerts and their acknowledgements this many days after they end (default 365)")
    group.add_argument("--track-days", type=float, default=30.0,
                       help="keep trajectories (personal data) this many days (default 30)")
    group.add_argument("--retention-every", type=float, default=60.0, metavar="S",
                       help="seconds between downsampling and retention passes (default 60)")


def retention_policy(args: argparse.Namespace) -> RetentionPolicy:
    try:
        return RetentionPolicy(fine_s=args.fine_days * DAY_S, occupancy_s=args.occupancy_days * DAY_S,
                               events_s=args.event_days * DAY_S, tracks_s=args.track_days * DAY_S)
    except ValueError as exc:
        raise UserError(f"retention: {exc}".replace("fine_s", "--fine-days").replace("occupancy_s", "--occupancy-days")
                        .replace("events_s", "--event-days").replace("tracks_s", "--track-days")) from None


def check_arguments(args: argparse.Namespace) -> None:
    if not 0.05 <= args.commit_interval <= 1.0:
        raise UserError(f"--commit-interval must be between 0.05 and 1 s, got {args.commit_interval:g}")
    if args.track_period <= 0:
        raise UserError(f"--track-period must be positive, got {args.track_period:g}")
    if args.retention_every <= 0:
        raise UserError(f"--retention-every must be positive, got {args.retention_every:g}")


def main(args: argparse.Namespace) -> int:
    check_arguments(args)
    policy = retention_policy(args)
    site, site_id = service_site(args)
    keys = bus.Keys(site_id)
    try:
        db = HistoryDatabase.open(args.db)
        db.save_retention(policy)
    except StorageError as exc:
        raise UserError(str(exc)) from None
    recorder = Recorder(db, track_period_s=args.track_period, zones=frozenset(z.id for z in site.zones))
    session = bus.open_session(bus.config_from_args(args))
    stats = bus.BusStats()
    subscriptions: list[bus.Subscription] = [
        bus.subscribe(session, keys.occupancy, bus.JsonCodec(Occupancy), recorder.on_occupancy, stats=stats),
        bus.subscribe(session, keys.tracks, bus.JsonCodec(Tracks), recorder.on_tracks, stats=stats),
        bus.HistorySubscription(session, keys.events, bus.JsonCodec[Event](Event, "Event"), recorder.on_event, stats=stats),
        bus.subscribe(session, keys.open_alerts, bus.JsonCodec(OpenAlerts), recorder.on_open_alerts, stats=stats),
    ]
    token = bus.announce(session, keys, SERVICE)  # after subscribing: "alive" means "recording"
    print(f"bevflow recorder: site {site_id!r} into {db.url}, commit every {args.commit_interval:g} s", flush=True)
    try:
        book = MetricsBook()
        with stop_on_signals() as stop, reporting(session, site_id, SERVICE, book):
            run(recorder, policy, stop, args.commit_interval, args.retention_every, book)
    except StorageDamaged as exc:
        raise UserError(str(exc)) from None
    finally:
        token.undeclare()
        for subscription in subscriptions:
            subscription.close()
        session.close()
        try:
            recorder.flush()
        except StorageError as exc:
            log.error("could not write the last %d rows: %s", recorder.pending(), exc)
        db.close()
        log.info("recorder stopped: %s; bus %s", dict(recorder.counts), stats.snapshot())
    return 0


def run(recorder: Recorder, policy: RetentionPolicy, stop: threading.Event, commit_interval: float,
        retention_every: float, book: MetricsBook | None = None) -> None:
    """Flush every ``commit_interval`` and apply retention every ``retention_every`` seconds until
    ``stop`` is set; ``book`` gets each flush's time and the rows still pending."""
    book = book if book is not None else MetricsBook()
    next_flush = next_retention = time.monotonic()
    down_since: float | None = None
    while not stop.wait(max(0.0, next_flush - time.monotonic())):
        next_flush = max(next_flush + commit_interval, time.monotonic())
        try:
            started = time.perf_counter()
            if recorder.flush():  # a flush with nothing to write is no database write
                book.observe("history_write_seconds", time.perf_counter() - started)
            if time.monotonic() >= next_retention:
                now = recorder.clock()
                result = recorder.db.apply_retention(policy, now, latest_ns=recorder.window.latest_ns(now))
                recorder.end_lapsed_alerts()
                # A backlog (first run, a retention shortened) is worked off a slice per flush.
                next_retention = time.monotonic() + (retention_every if result.done else 0.0)
            book.set("history_backlog_rows", recorder.pending())
            if down_since is not None:
                log.info("database back after %.1f s; %d rows pending", time.monotonic() - down_since, recorder.pending())
                down_since = None
        except StorageUnavailable as exc:
            book.set("history_backlog_rows", recorder.pending())
            if down_since is None:
                down_since = time.monotonic()
                log.warning("database unavailable, keeping %d rows to retry: %s", recorder.pending(), exc)


if __name__ == "__main__":  # until `bevflow serve` lists the recorder: python -m bevflow_services.recorder.main
    from bevflow_services.cli.serve import run_service

    try:
        sys.exit(run_service("recorder", sys.argv[1:]))
    except UserError as exc:
        print(f"bevflow serve recorder: {exc}", file=sys.stderr)
        sys.exit(2)
