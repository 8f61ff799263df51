"""Publish the site's alerts and occupancy to an MQTT broker (Home Assistant, Node-RED, a VMS).

    bevflow serve mqtt --site site.yaml --broker mqtt://broker.hall.local --outbox /var/lib/bevflow/mqtt-outbox.db
    BEVFLOW_MQTT_PASSWORD=... bevflow serve mqtt --site site.yaml --broker mqtt://bevflow@broker --outbox outbox.db

Topics, under ``--topic-prefix`` (default ``bevflow``) and the site's bus name:

    bevflow/SITE/alerts/ZONE/TYPE     every alert as it starts, changes and ends (the /ws/alerts message,
                                      JSON; ZONE is "site" for site-wide alerts); QoS 1, not retained
    bevflow/SITE/occupancy            the newest Occupancy message (JSON); retained
    bevflow/SITE/zones/ZONE/occupancy the newest count of each zone; retained

With ``--home-assistant``, the site's and each zone's occupancy are announced as Home Assistant
sensors (retained config messages under ``--discovery-prefix``, sent again at each connection).

No alert is lost while the broker is down or this service restarts: each is written to the
outbox (a SQLite file) before it is sent, and sent oldest first, one at a time, until the broker
acknowledges it. Alerts the service missed while it was down come back from the tracker's cache
(``bevflow serve tracker --event-cache``). What the bus brings is checked as the gateway checks it
(``bevflow_services.alert_feed``): a flood of new alerts is refused, and an open alert the tracker
stops renewing is published once more, ended.
"""

from __future__ import annotations

import argparse
import logging
import os
from pathlib import Path
from typing import Any

from bevflow.schemas import FEED_EVENT_TYPES, EVENT_TYPES, AlertMessage, Event, Occupancy

from bevflow_services import alert_feed, bus
from bevflow_services.alert_feed import AlertFeed
from bevflow_services.mqtt.broker import BrokerAddress, Latest, Reliable
from bevflow_services.mqtt.discovery import discovery_messages
from bevflow_services.outbox import Outbox, deliver
from bevflow_services.runtime import UserError, service_site, stop_on_signals

log = logging.getLogger(__name__)
SERVICE = "mqtt"
PASSWORD_VARIABLE = "BEVFLOW_MQTT_PASSWORD"
SITE_WIDE = "site"  # the zone part of the topic of an alert that belongs to no zone


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("mqtt")
    group.add_argument("--broker", required=True, metavar="URL",
                       help=f"the broker: mqtt://[USER@]HOST[:PORT] (password from ${PASSWORD_VARIABLE} or --password-file)")
    group.add_argument("--password-file", type=Path, metavar="FILE", help="a file holding only the broker password")
    group.add_argument("--outbox", required=True, type=Path, metavar="FILE",
                       help="SQLite file that keeps alerts until the broker has them (created if missing)")
    group.add_argument("--topic-prefix", default="bevflow", help="first level of every topic (default bevflow)")
    group.add_argument("--home-assistant", action="store_true",
                       help="announce the site's and each zone's occupancy as Home Assistant sensors (MQTT discovery)")
    group.add_argument("--discovery-prefix", default="homeassistant",
                       help="Home Assistant's discovery prefix (default homeassistant)")
    group.add_argument("--types", default=",".join(FEED_EVENT_TYPES), metavar="T,T",
                       help="alert types to publish (default: all but distance_violation, the per-pair events "
                       f"that distance_incident groups; any of {', '.join(EVENT_TYPES)})")
    alert_feed.add_arguments(group)


def alert_topic(prefix: str, site: str, message: AlertMessage) -> str:
    return f"{prefix}/{site}/alerts/{message.zone or SITE_WIDE}/{message.type}"


def broker_password(args: argparse.Namespace) -> str | None:
    if args.password_file is not None:
        try:
            return args.password_file.read_text(encoding="utf-8").rstrip("\r\n")
        except OSError as exc:
            raise UserError(f"--password-file {args.password_file}: {exc.strerror or exc}") from None
    return os.environ.get(PASSWORD_VARIABLE) or None


def check_types(text: str) -> set[str]:
    types = {t for t in text.split(",") if t}
    unknown = sorted(types - set(EVENT_TYPES))
    if unknown or not types:
        raise UserError(f"--types: unknown {', '.join(unknown) or '(none given)'}; choose from {', '.join(EVENT_TYPES)}")
    return types


def main(args: argparse.Namespace) -> int:
    site, site_id = service_site(args)
    types = check_types(args.types)
    try:
        address = BrokerAddress.parse(args.broker, broker_password(args))
    except ValueError as exc:
        raise UserError(f"--broker: {exc}") from None
    outbox = Outbox(args.outbox)
    prefix, keys = args.topic_prefix.rstrip("/"), bus.Keys(site_id)
    discovery = discovery_messages(site, site_id, prefix, args.discovery_prefix) if args.home_assistant else []
    reliable = Reliable(address, f"bevflow-{site_id}-alerts")
    latest = Latest(address, f"bevflow-{site_id}-occupancy", on_connect=discovery)

    def forward(event: Event) -> None:
        message = AlertMessage.from_event(event)
        outbox.add(alert_topic(prefix, site_id, message), message.model_dump_json().encode())

    def on_occupancy(occupancy: Occupancy) -> None:  # on a Zenoh thread
        latest.send(f"{prefix}/{site_id}/occupancy", occupancy.model_dump_json().encode())
        for zone in occupancy.zones:
            latest.send(f"{prefix}/{site_id}/zones/{zone.id}/occupancy", str(zone.count).encode())

    feed = AlertFeed(forward, types, lease_s=args.alert_lease_s)
    session = bus.open_session(bus.config_from_args(args))
    subscriptions: list[bus.Subscription[Any]] = [
        *feed.subscribe(session, keys),
        bus.subscribe(session, keys.occupancy, bus.JsonCodec(Occupancy), on_occupancy),
    ]
    token = bus.announce(session, keys, SERVICE)
    print(f"bevflow mqtt: site {site_id!r} to {address.host}:{address.port} under {prefix}/, "
          f"{outbox.backlog()} alerts waiting in {args.outbox}", flush=True)
    try:
        with stop_on_signals() as stop, feed.running(session, site_id, SERVICE, outbox):
            deliver(outbox, lambda message, stop_: reliable.send(message.topic, message.payload, stop_), stop)
    finally:
        token.undeclare()
        for subscription in subscriptions:
            subscription.close()
        session.close()
        reliable.close()
        latest.close()
        log.info("mqtt stopped; %d alerts still waiting in the outbox; alerts %s", outbox.backlog(), dict(feed.counts))
        outbox.close()
    return 0

