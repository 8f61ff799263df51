"""Run the gateway: subscribe to one site's tracks, occupancy, events and camera detections over
the bus, keep a ``GatewayState``, and serve the API, the dashboard and the 3D view with uvicorn.

    bevflow serve gateway --site site.yaml --port 8000
    python -m bevflow_services.gateway.main --site example-hall

Zenoh delivers on its own threads; ``AsyncSubscription`` hands each decoded message to the event
loop through a bounded queue, and one task per subscription applies them to the state there, so
the state and the websocket fan-out only ever change on the loop's thread (camera liveliness
changes excepted: ``GatewayState`` locks around those).
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import uvicorn

from bevflow.schemas import Detections2D, Event, Occupancy, Tracks

from bevflow_services.bus import (
    AsyncSubscription,
    BusStats,
    JsonCodec,
    Keys,
    LiveService,
    LiveServices,
    announce,
    config_from_args,
    open_session,
)
from bevflow_services.cli.serve import service_site
from bevflow_services.gateway.app import create_app
from bevflow_services.gateway.history_db import history_store
from bevflow_services.gateway.state import GatewayState

log = logging.getLogger(__name__)

SERVICE = "gateway"
# Queue lengths: alerts must not be dropped; for tracks only the newest matters.
QUEUES = {"tracks": 16, "occupancy": 64, "events": 4096, "detections": 512}


async def _apply_all(sub: AsyncSubscription[Any], state: GatewayState) -> None:
    async for message in sub:
        try:
            state.apply(message)
        except Exception:  # one bad message must not stop the feed
            log.exception("gateway could not apply a message from %s", sub.key)


def bus_feed(session: Any, state: GatewayState, stats: BusStats) -> Any:
    """A factory of the async context manager that feeds ``state`` from the bus (``session``, an
    open Zenoh session from ``bus.open_session``) while it is open."""

    @asynccontextmanager
    async def feed() -> AsyncIterator[None]:
        keys = Keys(state.site_id)
        subscriptions: list[AsyncSubscription[Any]] = [
            AsyncSubscription(session, keys.tracks, JsonCodec(Tracks), maxsize=QUEUES["tracks"], stats=stats),
            AsyncSubscription(session, keys.occupancy, JsonCodec(Occupancy), maxsize=QUEUES["occupancy"], stats=stats),
            AsyncSubscription(session, keys.events, JsonCodec(Event, "Event"), maxsize=QUEUES["events"], stats=stats),
            AsyncSubscription(session, keys.detections("*"), JsonCodec(Detections2D), maxsize=QUEUES["detections"], stats=stats),
        ]

        def on_change(service: LiveService, alive: bool) -> None:  # on a Zenoh thread
            (state.service_up if alive else state.service_down)(service.service, service.instance)

        watcher = LiveServices(session, keys, on_change=on_change)
        token = announce(session, keys, SERVICE)
        tasks = [asyncio.create_task(_apply_all(sub, state)) for sub in subscriptions]
        try:
            yield
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            token.undeclare()
            watcher.close()
            for sub in subscriptions:
                sub.close()

    return feed


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The gateway's own flags; ``bevflow serve`` adds --site, --site-id and the bus flags."""
    group = parser.add_argument_group("gateway")
    group.add_argument("--host", default="127.0.0.1", help="address to serve on (0.0.0.0 for every interface)")
    group.add_argument("--port", type=int, default=8000, help="HTTP port of the API and dashboard (default 8000)")
    group.add_argument("--view3d-port", type=int, default=None,
                       help="port of the 3D view (default: --port + 1; the next free one if taken)")
    group.add_argument("--no-view3d", action="store_true", help="do not start the 3D view")
    group.add_argument("--history-s", type=float, default=3600.0,
                       help="seconds of occupancy, alert and trajectory history kept in memory (default 3600)")
    group.add_argument("--db", default=None, metavar="URL",
                       help="read the history from this database instead (a SQLite file path or a postgresql:// URL), "
                       "which `bevflow serve recorder --db URL` writes; --history-s is then unused")


def main(args: argparse.Namespace) -> int:
    """Serve until interrupted (``bevflow serve gateway``). Bus errors raise ``BusError``."""
    site, site_id = service_site(args)
    view3d_port = None if args.no_view3d else (args.view3d_port or args.port + 1)
    session = open_session(config_from_args(args))
    stats = BusStats()
    state = GatewayState(site, history_store(args.db, args.history_s), site_id=site_id)
    app = create_app(site, state, view3d_port=view3d_port, view3d_host=args.host, feed=bus_feed(session, state, stats))
    app.state.bus_stats = stats
    try:
        uvicorn.Server(uvicorn.Config(app, host=args.host, port=args.port, log_level="info")).run()
    finally:
        session.close()
    return 0


if __name__ == "__main__":
    from bevflow_services.cli.serve import run_service

    sys.exit(run_service("gateway", sys.argv[1:]))
