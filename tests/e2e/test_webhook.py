"""``bevflow serve webhook`` against a local receiver: alerts raised while the receiver is down,
or while it answers 500, all arrive once it is back, once each, in order, signed; an open alert
nobody renews is POSTed again, ended."""

from __future__ import annotations

import hashlib
import hmac
import http.server
import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from bevflow.schemas import Event

from bevflow_services import bus
from bevflow_services.launcher import free_port
from bevflow_services.webhook.main import RETRY_S
from tests.e2e.renewals import forge_one_and_renew_another
from tests.services.gateway.feed import SITE_YAML, T0, S, incident, over_capacity

pytestmark = pytest.mark.e2e
TIMEOUT_S = 30.0
SECRET = b"shared-secret"
RECEIVER_DOWN_S = 30.0
# Back, the receiver waits for the service's next try: at most its longest wait between tries.
BACK_WITHIN_S = RETRY_S[1] + TIMEOUT_S
# Long enough that the alerts of a test about delivery, which nobody renews, do not lapse meanwhile.
LONG_LEASE_S = 3600.0
SHORT_LEASE_S = 1.5


class Receiver:
    """An HTTP endpoint that records signed POSTs; ``fail_next`` answers 500 that many times."""

    def __init__(self, port: int) -> None:
        self.port, self.bodies, self.fail_next, self.server = port, [], 0, None
        self.lock = threading.Lock()

    def start(self) -> None:
        receiver = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = self.rfile.read(int(self.headers["Content-Length"]))
                expected = "sha256=" + hmac.new(SECRET, body, hashlib.sha256).hexdigest()
                with receiver.lock:
                    failing = receiver.fail_next > 0
                    receiver.fail_next -= failing
                    if not failing and self.headers["X-Bevflow-Signature"] == expected:
                        receiver.bodies.append(json.loads(body))
                self.send_response(500 if failing else 204)
                self.end_headers()

            def log_message(self, *_args) -> None:
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", self.port), Handler)
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def stop(self) -> None:
        self.server.shutdown()
        self.server.server_close()

    def wait_for(self, n: int, timeout_s: float = TIMEOUT_S) -> list[dict]:
        deadline = time.monotonic() + timeout_s
        while len(self.bodies) < n:
            assert time.monotonic() < deadline, f"{len(self.bodies)} of {n} alerts arrived"
            time.sleep(0.1)
        time.sleep(1.0)  # and no more than those
        with self.lock:
            return list(self.bodies)


def start_service(tmp_path: Path, hub: str, receiver: Receiver, *options: str) -> subprocess.Popen:
    site, secret = tmp_path / "site.yaml", tmp_path / "secret"
    site.write_text(SITE_YAML)
    secret.write_bytes(SECRET + b"\n")
    with (tmp_path / "webhook.log").open("wb") as log:
        return subprocess.Popen([sys.executable, "-m", "bevflow_services.cli", "serve", "webhook", "--site", str(site),
                                 "--listen", hub, "--url", f"http://127.0.0.1:{receiver.port}/alerts",
                                 "--secret-file", str(secret), "--outbox", str(tmp_path / "outbox.db"), *options],
                                stdout=log, stderr=subprocess.STDOUT)


def test_alerts_arrive_once_in_order_across_a_receiver_outage(tmp_path: Path) -> None:
    receiver = Receiver(free_port())
    receiver.start()
    hub = f"tcp/127.0.0.1:{free_port()}"
    service = start_service(tmp_path, hub, receiver, "--alert-lease-s", str(LONG_LEASE_S))
    session = bus.open_session(bus.BusConfig(connect=(hub,)))
    events = bus.Publication(session, bus.Keys("hall").events, bus.JsonCodec(Event, "Event"))
    try:
        assert events.wait_for_subscribers(TIMEOUT_S), (tmp_path / "webhook.log").read_text()
        receiver.fail_next = 2  # the first alert is refused twice, then taken
        raised = [incident("i1", T0), over_capacity("c1", T0 + S), incident("i1", T0, end_ns=T0 + 2 * S)]
        for event in raised:
            events.put(event)
        assert len(receiver.wait_for(3)) == 3

        receiver.stop()
        later = [incident(f"down-{k}", T0 + (10 + k) * S) for k in range(5)]
        for event in later:
            events.put(event)
            time.sleep(RECEIVER_DOWN_S / len(later))
        receiver.start()

        got = receiver.wait_for(len(raised) + len(later), BACK_WITHIN_S)
        assert [(b["id"], b["end_ns"]) for b in got] == [(e.id, e.end_ns) for e in raised + later]
        assert "trying alert" in (tmp_path / "webhook.log").read_text()
    finally:
        events.close()
        session.close()
        service.terminate()
        service.wait(10)
        receiver.stop()


def test_an_open_alert_nobody_renews_is_posted_again_ended_and_a_renewed_one_is_not(tmp_path: Path) -> None:
    receiver = Receiver(free_port())
    receiver.start()
    hub = f"tcp/127.0.0.1:{free_port()}"
    service = start_service(tmp_path, hub, receiver, "--alert-lease-s", str(SHORT_LEASE_S))
    session = bus.open_session(bus.BusConfig(connect=(hub,)))

    def explain() -> str:
        return f"{receiver.bodies}\n{(tmp_path / 'webhook.log').read_text()}"

    try:
        forge_one_and_renew_another(session, lambda: len(receiver.bodies), SHORT_LEASE_S, TIMEOUT_S, explain)
        with receiver.lock:
            got = [(b["id"], b["active"], b["end_ns"]) for b in receiver.bodies]
        assert got[:2] == [("forged", True, None), ("renewed", True, None)]
        assert [(i, a) for i, a, _ in got[2:]] == [("forged", False)]
        assert got[2][2] > T0  # ended when it arrived, on the service's clock
    finally:
        session.close()
        service.terminate()
        service.wait(10)
        receiver.stop()
