"""Run the gateway: subscribe to one site's tracks, occupancy, events and camera detections over
the bus, keep a ``GatewayState``, and serve the API, the dashboard and the 3D view with uvicorn.

    bevflow serve gateway --site site.yaml --port 8000 --db history.db
    bevflow serve gateway --site site.yaml --host 0.0.0.0 --db history.db --tls-cert cert.pem --tls-key key.pem
    python -m bevflow_services.gateway.main --site example-hall

Zenoh delivers on its own threads; ``AsyncSubscription`` hands each decoded message to the event
loop through a bounded queue, and one task per subscription applies them to the state there, so
the state and the websocket fan-out only ever change on the loop's thread (camera liveliness
changes excepted: ``GatewayState`` locks around those).
"""

from __future__ import annotations

import argparse
import asyncio
import ipaddress
import logging
import queue
import re
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import uvicorn

from bevflow.schemas import (
    CameraCylinders,
    Detections2D,
    Event,
    FrameHeader,
    Occupancy,
    OpenAlerts,
    ServiceMetrics,
    Tracks,
)

from bevflow_services import extras, redact
from bevflow_services.bus import (
    FRAMES,
    AsyncSubscription,
    BusStats,
    JsonCodec,
    Keys,
    LiveService,
    LiveServices,
    announce,
    config_from_args,
    open_session,
    subscribe,
)
from bevflow_services.gateway.app import create_app
from bevflow_services.gateway.auth import Access, check_auth_mode
from bevflow_services.gateway.history_db import history_store
from bevflow_services.gateway.calibration_inputs import CalibrationInputs
from bevflow_services.gateway.site_file import site_file_of
from bevflow_services.gateway.state import GatewayState
from bevflow_services.runtime import UserError, service_site

log = logging.getLogger(__name__)

SERVICE = "gateway"
# Queue lengths: alerts must not be dropped; for tracks only the newest matters.
QUEUES = {"tracks": 16, "occupancy": 64, "events": 4096, "detections": 512, "open_alerts": 16}
LAPSE_CHECK_S = 1.0  # how often open alerts nobody renews are ended (bevflow.alert_lease)


async def _apply_all(sub: AsyncSubscription[Any], state: GatewayState) -> None:
    async for message in sub:
        try:
            state.apply(message)
        except Exception:  # one bad message must not stop the feed
            log.exception("gateway could not apply a message from %s", sub.key)


async def _end_lapsed_alerts(state: GatewayState) -> None:
    while True:
        await asyncio.sleep(LAPSE_CHECK_S)
        try:
            state.end_lapsed_alerts()
        except Exception:  # the next check tries again
            log.exception("gateway could not end the lapsed alerts")


def bus_feed(session: Any, state: GatewayState, stats: BusStats) -> Any:
    """A factory of the async context manager that feeds ``state`` from the bus (``session``, an
    open Zenoh session from ``bus.open_session``) while it is open."""

    @asynccontextmanager
    async def feed() -> AsyncIterator[None]:
        keys = Keys(state.site_id)
        subscriptions: list[AsyncSubscription[Any]] = [
            AsyncSubscription(session, keys.tracks, JsonCodec(Tracks), maxsize=QUEUES["tracks"], stats=stats),
            AsyncSubscription(session, keys.occupancy, JsonCodec(Occupancy), maxsize=QUEUES["occupancy"], stats=stats),
            AsyncSubscription(session, keys.events, JsonCodec[Event](Event, "Event"), maxsize=QUEUES["events"], stats=stats),
            AsyncSubscription(session, keys.detections("*"), JsonCodec(Detections2D), maxsize=QUEUES["detections"], stats=stats),
            AsyncSubscription(session, keys.open_alerts, JsonCodec(OpenAlerts), maxsize=QUEUES["open_alerts"], stats=stats),
        ]

        def on_change(service: LiveService, alive: bool) -> None:  # on a Zenoh thread
            (state.service_up if alive else state.service_down)(service.service, service.instance)

        watcher = LiveServices(session, keys, on_change=on_change)
        token = announce(session, keys, SERVICE)
        tasks = [asyncio.create_task(_apply_all(sub, state)) for sub in subscriptions]
        tasks.append(asyncio.create_task(_end_lapsed_alerts(state)))
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
                       help="loopback port of the 3D view, which the gateway serves at /view3d/ behind its login "
                       "(default: --port + 1; the next free one if taken)")
    group.add_argument("--no-view3d", action="store_true",
                       help="do not start the 3D view (nor does the gateway without the 'view3d' extra)")
    group.add_argument("--history-s", type=float, default=3600.0,
                       help="seconds of occupancy, alert and trajectory history kept in memory (default 3600)")
    group.add_argument("--db", default=None, metavar="URL",
                       help="read the history from this database instead (a SQLite file path or a postgresql:// URL), "
                       "which `bevflow serve recorder --db URL` writes; --history-s is then unused")
    secure = parser.add_argument_group("access control")
    secure.add_argument("--auth", choices=("on", "off"), default="on",
                        help="on (default): users log in (`bevflow users`); off: no login, every request is an admin "
                        "(allowed only with a loopback --host)")
    secure.add_argument("--auth-db", default=None, metavar="URL",
                        help="database of users, sessions, tokens and the audit log (default: --db)")
    secure.add_argument("--tls-cert", default=None, metavar="PEM", help="serve HTTPS with this certificate (chain)")
    secure.add_argument("--tls-key", default=None, metavar="PEM", help="the certificate's private key")
    secure.add_argument("--cors-origin", action="append", default=[], metavar="ORIGIN",
                        help="a web origin (https://host:port) whose pages may call the API; repeat for more (default none)")
    secure.add_argument("--session-hours", type=float, default=12.0, help="how long a dashboard login lasts (default 12)")
    secure.add_argument("--trusted-proxy", action="append", default=[], metavar="ADDRESS",
                        help="a reverse proxy's address or network (10.0.0.2, 10.0.0.0/24) whose X-Forwarded-For and "
                        "X-Forwarded-Proto are believed; repeat for more (default none: each request's address is "
                        "the one it came from, for the audit log and the login limits)")


def access_from_args(args: argparse.Namespace) -> Access:
    """Access control as the flags say; ``UserError`` for a combination that cannot be served."""
    from bevflow_services.storage import StorageError
    from bevflow_services.storage.access import AccessStore

    try:
        check_auth_mode(args.auth, args.host)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if bool(args.tls_cert) != bool(args.tls_key):
        raise UserError("--tls-cert and --tls-key go together: give both, or neither")
    for flag, path in (("--tls-cert", args.tls_cert), ("--tls-key", args.tls_key)):
        if path and not Path(path).is_file():
            raise UserError(f"{flag} {path}: no such file")
    for origin in args.cors_origin:
        if not re.fullmatch(r"https?://[^/\s]+", origin):
            raise UserError(f"--cors-origin {origin!r}: give a scheme and host, like https://ops.example.com")
    if args.session_hours <= 0:
        raise UserError(f"--session-hours must be positive, got {args.session_hours}")
    url = args.auth_db or args.db
    if args.auth == "on" and not url:
        raise UserError("--auth on keeps its users in a database: give --db URL (the history database) or --auth-db URL; "
                        "or, serving on loopback only, --auth off")
    try:
        store = AccessStore.open(url) if url else AccessStore.open(":memory:")
    except StorageError as exc:
        raise UserError(f"{'--auth-db' if args.auth_db else '--db'}: {exc}") from None
    return Access(store, enabled=args.auth == "on", loopback_only=args.auth == "off", secure_cookies=bool(args.tls_cert),
                  session_s=args.session_hours * 3600, cors_origins=tuple(args.cors_origin))


def proxy_options(trusted: list[str]) -> dict[str, Any]:
    """uvicorn's proxy settings: forwarded headers believed only from ``trusted``. uvicorn's own
    default believes them from loopback, which would let any program on this host choose the
    address that the audit log records and the login limits count; ``UserError`` for a bad address."""
    for address in trusted:
        try:
            ipaddress.ip_network(address, strict=False)
        except ValueError:
            raise UserError(f"--trusted-proxy {address!r}: give an IP address or network, like 10.0.0.2 or 10.0.0.0/24") from None
    return {"proxy_headers": bool(trusted), "forwarded_allow_ips": ",".join(trusted)}


def view3d_port_from_args(args: argparse.Namespace) -> int | None:
    """The 3D view's port, or None for no 3D view: --no-view3d, or viser (the 'view3d' extra) not
    installed. Asked for by --view3d-port, its absence raises the ``ModuleNotFoundError`` that
    ``bevflow`` turns into the line naming the extra; by default the gateway serves without it."""
    if args.no_view3d:
        return None
    if args.view3d_port:
        extras.require("view3d")
        return int(args.view3d_port)
    if extras.missing_module("view3d") is not None:
        log.warning("no 3D view: it %s", extras.install_hint("view3d"))
        return None
    return int(args.port) + 1


def announce_setup(access: Access, args: argparse.Namespace) -> None:
    """First run: with no users yet, log the one-time link that creates the first admin."""
    if not access.enabled:
        log.warning("access control is OFF (--auth off): anyone reaching %s:%d is an administrator", args.host, args.port)
        return
    token = access.prepare_setup()
    if token is not None:
        scheme = "https" if args.tls_cert else "http"
        host = "THIS-HOST" if args.host in ("0.0.0.0", "::", "") else args.host  # a wildcard is no address to open
        log.warning("no users yet. Create the first admin within the hour at %s://%s:%d/login.html#setup=%s "
                    "(the token works once, for an hour; each start logs a new one), or with: "
                    "bevflow users --db URL add NAME --role admin",
                    scheme, host, args.port, token)


def main(args: argparse.Namespace) -> int:
    """Serve until interrupted (``bevflow serve gateway``). Bus errors raise ``BusError``."""
    site, site_id = service_site(args)
    access = access_from_args(args)
    proxies = proxy_options(args.trusted_proxy)
    view3d_port = view3d_port_from_args(args)
    session = open_session(config_from_args(args))
    stats = BusStats()
    state = GatewayState(site, history_store(args.db, args.history_s), site_id=site_id)
    app = create_app(site, state, view3d_port=view3d_port, feed=bus_feed(session, state, stats),
                     access=access)
    app.state.bus_stats = stats
    # The calibration page: saves go to the site file (none for a built-in site); the projectors'
    # cylinders feed the consistency table; a frame is fetched only when the page asks for one.
    app.state.site_file = site_file_of(args.site)
    keys = Keys(site_id)
    inputs = app.state.calibration_inputs = CalibrationInputs(fetch_frame=frame_fetcher(session, keys))
    cylinders = subscribe(session, keys.cylinders("*"), JsonCodec(CameraCylinders), inputs.put_cylinders, stats=stats)
    services = subscribe(session, keys.metrics(), JsonCodec(ServiceMetrics), app.state.service_metrics.put, stats=stats)
    announce_setup(access, args)
    try:
        config = uvicorn.Config(app, host=args.host, port=args.port, log_level="info",
                                ssl_certfile=args.tls_cert, ssl_keyfile=args.tls_key, **proxies)
        redact.install()  # after uvicorn set up its loggers: its access log would show ?token=
        uvicorn.Server(config).run()
    finally:
        cylinders.close()
        services.close()
        session.close()
    return 0


def frame_fetcher(session: Any, keys: Keys, timeout_s: float = 1.0) -> Any:
    """``fetch(camera)``: that camera's next frame from the bus, waiting at most ``timeout_s``
    (None if none comes); subscribed only for the wait, since frames are large."""

    def fetch(camera: str) -> tuple[FrameHeader, Any] | None:
        got: queue.Queue[Any] = queue.Queue(maxsize=1)

        def keep(frame: Any) -> None:  # on a Zenoh thread
            try:
                got.put_nowait(frame)
            except queue.Full:
                pass

        sub = subscribe(session, keys.frame(camera), FRAMES, keep)
        try:
            frame = got.get(timeout=timeout_s)
        except queue.Empty:
            return None
        finally:
            sub.close()
        return frame.header, frame.image

    return fetch


if __name__ == "__main__":
    from bevflow_services.cli.serve import run_service

    sys.exit(run_service("gateway", sys.argv[1:]))
