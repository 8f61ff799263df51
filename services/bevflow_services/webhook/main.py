"""POST every alert to a web endpoint (a ticketing system, a VMS, a chat bridge), signed, and
retried until it is delivered.

    BEVFLOW_WEBHOOK_SECRET=... bevflow serve webhook --site site.yaml --url https://vms.hall.local/bevflow \\
        --outbox /var/lib/bevflow/webhook-outbox.db

Each alert is the ``/ws/alerts`` message (JSON), POSTed when the alert starts, changes and ends,
with ``X-Bevflow-Signature: sha256=HEX``, the HMAC-SHA256 of the body under the shared secret, so
the receiver can check it came from here. Any answer but 2xx, or none, is retried with backoff
(1 s doubling up to a minute), the alerts after it waiting, so they arrive once each and in
order; meanwhile they are kept in the outbox (a SQLite file), across restarts too. What the bus
brings is checked as the gateway checks it (``bevflow_services.alert_feed``): a flood of new
alerts is refused, and an open alert the tracker stops renewing is POSTed once more, ended.
"""

from __future__ import annotations

import argparse
import hashlib
import hmac
import logging
import os
import threading
import urllib.error
import urllib.request
from pathlib import Path

from bevflow.schemas import EVENT_TYPES, FEED_EVENT_TYPES, AlertMessage, Event

from bevflow_services import alert_feed, bus
from bevflow_services.alert_feed import AlertFeed
from bevflow_services.outbox import Message, Outbox, deliver
from bevflow_services.redact import redact
from bevflow_services.runtime import UserError, service_site, stop_on_signals

log = logging.getLogger(__name__)
SERVICE = "webhook"
SECRET_VARIABLE = "BEVFLOW_WEBHOOK_SECRET"
SIGNATURE_HEADER = "X-Bevflow-Signature"
RETRY_S = (1.0, 60.0)  # first and longest wait between tries of one alert


def add_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("webhook")
    group.add_argument("--url", required=True, help="where to POST each alert (http:// or https://)")
    group.add_argument("--secret-file", type=Path, metavar="FILE",
                       help=f"a file holding the signing secret (else ${SECRET_VARIABLE}; without either, unsigned)")
    group.add_argument("--outbox", required=True, type=Path, metavar="FILE",
                       help="SQLite file that keeps alerts until the receiver has them (created if missing)")
    group.add_argument("--timeout", type=float, default=10.0, metavar="S", help="seconds to wait for an answer (default 10)")
    group.add_argument("--types", default=",".join(FEED_EVENT_TYPES), metavar="T,T",
                       help="alert types to send (default: all but distance_violation, the per-pair events that "
                       f"distance_incident groups; any of {', '.join(EVENT_TYPES)})")
    alert_feed.add_arguments(group)


def signature(secret: bytes, body: bytes) -> str:
    return "sha256=" + hmac.new(secret, body, hashlib.sha256).hexdigest()


def read_secret(args: argparse.Namespace) -> bytes | None:
    if args.secret_file is not None:
        try:
            return args.secret_file.read_bytes().rstrip(b"\r\n")
        except OSError as exc:
            raise UserError(f"--secret-file {args.secret_file}: {exc.strerror or exc}") from None
    value = os.environ.get(SECRET_VARIABLE)
    return value.encode() if value else None


class Poster:
    """POSTs one alert until a 2xx answer, waiting longer after each failure."""

    def __init__(self, url: str, secret: bytes | None, timeout_s: float) -> None:
        self.url, self.secret, self.timeout_s = url, secret, timeout_s

    def post(self, body: bytes) -> str | None:
        """None when delivered; otherwise why not."""
        headers = {"Content-Type": "application/json", "User-Agent": "bevflow-webhook"}
        if self.secret is not None:
            headers[SIGNATURE_HEADER] = signature(self.secret, body)
        request = urllib.request.Request(self.url, data=body, headers=headers, method="POST")
        try:
            with urllib.request.urlopen(request, timeout=self.timeout_s) as response:
                return None if 200 <= response.status < 300 else f"HTTP {response.status}"
        except urllib.error.HTTPError as exc:
            return f"HTTP {exc.code}"
        except (urllib.error.URLError, OSError) as exc:
            return str(getattr(exc, "reason", exc))

    def send(self, message: Message, stop: threading.Event) -> bool:
        wait = RETRY_S[0]
        while (why := self.post(message.payload)) is not None:
            log.warning("webhook %s: %s; trying alert #%d again in %.0f s", redact(self.url), why, message.seq, wait)
            if stop.wait(wait):
                return False
            wait = min(wait * 2, RETRY_S[1])
        return True


def main(args: argparse.Namespace) -> int:
    _site, site_id = service_site(args)
    if not args.url.startswith(("http://", "https://")):
        raise UserError(f"--url {redact(args.url)!r}: give an http:// or https:// URL")
    types = {t for t in args.types.split(",") if t}
    if not types or types - set(EVENT_TYPES):
        raise UserError(f"--types: choose from {', '.join(EVENT_TYPES)}")
    poster, outbox = Poster(args.url, read_secret(args), args.timeout), Outbox(args.outbox)

    def forward(event: Event) -> None:
        outbox.add(event.type, AlertMessage.from_event(event).model_dump_json().encode())

    feed = AlertFeed(forward, types, lease_s=args.alert_lease_s)
    session = bus.open_session(bus.config_from_args(args))
    keys = bus.Keys(site_id)
    subscriptions = feed.subscribe(session, keys)
    token = bus.announce(session, keys, SERVICE)
    print(f"bevflow webhook: site {site_id!r} to {redact(args.url)}{'' if poster.secret else ' (unsigned)'}, "
          f"{outbox.backlog()} alerts waiting in {args.outbox}", flush=True)
    try:
        with stop_on_signals() as stop, feed.running(session, site_id, SERVICE, outbox):
            deliver(outbox, poster.send, stop)
    finally:
        token.undeclare()
        for subscription in subscriptions:
            subscription.close()
        session.close()
        log.info("webhook stopped; %d alerts still waiting in the outbox; alerts %s", outbox.backlog(), dict(feed.counts))
        outbox.close()
    return 0
