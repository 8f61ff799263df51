"""``bevflow serve mqtt`` against a real broker (Debian's mosquitto, started here): alerts raised
while the broker is down all arrive once it is back, once each and in order; occupancy is
retained and announced to Home Assistant; an open alert nobody renews is published again, ended.
Skipped, saying so, when mosquitto is not installed (``./run test`` installs it)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import paho.mqtt.client as mqtt
import pytest

from bevflow.schemas import Event

from bevflow_services import bus
from bevflow_services.launcher import free_port
from bevflow_services.mqtt.broker import RECONNECT_S
from tests.e2e.renewals import forge_one_and_renew_another
from tests.services.gateway.feed import SITE_YAML, T0, S, incident, occupancy, over_capacity

pytestmark = pytest.mark.e2e
TIMEOUT_S = 30.0
BROKER_DOWN_S = 30.0
# Back, the broker waits for the service's next try: at most paho's longest reconnect wait.
BACK_WITHIN_S = RECONNECT_S[1] + TIMEOUT_S
# Long enough that the alerts of a test about delivery, which nobody renews, do not lapse meanwhile.
LONG_LEASE_S = 3600.0
SHORT_LEASE_S = 1.5


def mosquitto_binary() -> str:
    found = shutil.which("mosquitto") or next((p for p in ("/usr/sbin/mosquitto",) if os.access(p, os.X_OK)), None)
    if found is None:
        pytest.skip("Debian's mosquitto is not installed (./run test installs it when run as root)")
    return found


class Broker:
    """A mosquitto on a loopback port that keeps sessions on disk across its own restarts."""

    def __init__(self, folder: Path) -> None:
        self.binary, self.port, self.folder = mosquitto_binary(), free_port(), folder
        config = folder / "mosquitto.conf"
        lines = [f"listener {self.port} 127.0.0.1", "allow_anonymous true", "persistence true",
                 f"persistence_location {folder}/", "autosave_interval 1"]
        if os.geteuid() == 0:
            lines.append("user root")  # as root it would switch to a 'mosquitto' user that cannot write here
        config.write_text("\n".join(lines) + "\n")
        self.config, self.process = config, None

    def start(self) -> None:
        log = (self.folder / "mosquitto.log").open("ab")
        self.process = subprocess.Popen([self.binary, "-c", str(self.config)], stdout=log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + TIMEOUT_S
        while subprocess.run(["bash", "-c", f"exec 3<>/dev/tcp/127.0.0.1/{self.port}"], capture_output=True).returncode:
            assert self.process.poll() is None and time.monotonic() < deadline, (self.folder / "mosquitto.log").read_text()
            time.sleep(0.1)

    def stop(self) -> None:
        if self.process is not None and self.process.poll() is None:
            self.process.terminate()
            self.process.wait(10)


class Receiver:
    """A subscriber with a persistent session, as an integration would keep one."""

    def __init__(self, port: int) -> None:
        self.messages: list[tuple[str, bytes, bool]] = []
        self.lock = threading.Lock()
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="test-receiver", clean_session=False)
        self.client.on_connect = lambda c, *_: c.subscribe([("bevflow/#", 1), ("homeassistant/#", 1)])
        self.client.on_message = self._on_message
        self.client.reconnect_delay_set(1, 2)
        self.client.connect("127.0.0.1", port)
        self.client.loop_start()

    def _on_message(self, _client, _userdata, message) -> None:
        with self.lock:
            self.messages.append((message.topic, message.payload, bool(message.retain)))

    def alerts(self) -> list[tuple[str, dict]]:
        with self.lock:
            return [(t, json.loads(p)) for t, p, _ in self.messages if "/alerts/" in t]

    def wait_for_alerts(self, n: int, timeout_s: float = TIMEOUT_S) -> list[tuple[str, dict]]:
        deadline = time.monotonic() + timeout_s
        while len(self.alerts()) < n:
            assert time.monotonic() < deadline, f"{len(self.alerts())} of {n} alerts arrived: {self.alerts()}"
            time.sleep(0.1)
        time.sleep(1.0)  # and no more than those
        return self.alerts()

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


def start_service(tmp_path: Path, hub: str, broker: Broker, *options: str) -> subprocess.Popen:
    site = tmp_path / "site.yaml"
    site.write_text(SITE_YAML)
    with (tmp_path / "mqtt.log").open("wb") as log:
        return subprocess.Popen([sys.executable, "-m", "bevflow_services.cli", "serve", "mqtt", "--site", str(site),
                                 "--listen", hub, "--broker", f"mqtt://127.0.0.1:{broker.port}",
                                 "--outbox", str(tmp_path / "outbox.db"), *options],
                                stdout=log, stderr=subprocess.STDOUT)


def test_alerts_raised_while_the_broker_is_down_arrive_once_in_order(tmp_path: Path) -> None:
    broker = Broker(tmp_path)
    broker.start()
    hub = f"tcp/127.0.0.1:{free_port()}"
    service = start_service(tmp_path, hub, broker, "--home-assistant", "--alert-lease-s", str(LONG_LEASE_S))
    receiver = Receiver(broker.port)
    session = bus.open_session(bus.BusConfig(connect=(hub,)))
    events = bus.Publication(session, bus.Keys("hall").events, bus.JsonCodec(Event, "Event"))
    occupancy_out = bus.Publication(session, bus.Keys("hall").occupancy, bus.JsonCodec(type(occupancy(T0, 0))))
    try:
        # Each subscription is declared in turn: the first occupancy must not go out before its own.
        assert events.wait_for_subscribers(TIMEOUT_S) and occupancy_out.wait_for_subscribers(TIMEOUT_S), (
            (tmp_path / "mqtt.log").read_text())
        raised = [incident("i1", T0), over_capacity("c1", T0 + S), incident("i1", T0, end_ns=T0 + 2 * S)]
        for event in raised:
            events.put(event)
        occupancy_out.put(occupancy(T0, total=7, gate=4))
        assert len(receiver.wait_for_alerts(3)) == 3

        broker.stop()
        later = [incident(f"down-{k}", T0 + (10 + k) * S, zone=None if k % 2 else "gate") for k in range(5)]
        for event in later:
            events.put(event)
            time.sleep(BROKER_DOWN_S / len(later))
        broker.start()

        got = receiver.wait_for_alerts(len(raised) + len(later), BACK_WITHIN_S)
        sent = [(e.id, e.end_ns) for e in raised + later]
        assert [(m["id"], m["end_ns"]) for _, m in got] == sent  # every one, once, in order
        assert got[0][0] == "bevflow/hall/alerts/gate/distance_incident"
        assert got[-2][0] == "bevflow/hall/alerts/site/distance_incident"
        with receiver.lock:
            retained = {t: p for t, p, _ in receiver.messages if t.endswith("occupancy")}
        assert retained["bevflow/hall/zones/gate/occupancy"] == b"4"
        assert json.loads(retained["bevflow/hall/occupancy"])["total"] == 7
        with receiver.lock:
            configs = {t: json.loads(p) for t, p, _ in receiver.messages if t.startswith("homeassistant/")}
        gate = configs["homeassistant/sensor/bevflow_hall/gate_occupancy/config"]
        assert gate["state_topic"] == "bevflow/hall/zones/gate/occupancy" and gate["unit_of_measurement"] == "people"
        assert configs["homeassistant/sensor/bevflow_hall/site_occupancy/config"]["value_template"] == "{{ value_json.total }}"
    finally:
        events.close()
        occupancy_out.close()
        session.close()
        receiver.close()
        service.terminate()
        service.wait(10)
        broker.stop()


def test_an_open_alert_nobody_renews_is_published_again_ended_and_a_renewed_one_is_not(tmp_path: Path) -> None:
    broker = Broker(tmp_path)
    broker.start()
    hub = f"tcp/127.0.0.1:{free_port()}"
    service = start_service(tmp_path, hub, broker, "--alert-lease-s", str(SHORT_LEASE_S))
    receiver = Receiver(broker.port)
    session = bus.open_session(bus.BusConfig(connect=(hub,)))

    def explain() -> str:
        return f"{receiver.alerts()}\n{(tmp_path / 'mqtt.log').read_text()}"

    try:
        forge_one_and_renew_another(session, lambda: len(receiver.alerts()), SHORT_LEASE_S, TIMEOUT_S, explain)
        got = [(topic, m["id"], m["active"], m["end_ns"]) for topic, m in receiver.alerts()]
        assert got[:2] == [("bevflow/hall/alerts/gate/distance_incident", "forged", True, None),
                           ("bevflow/hall/alerts/gate/over_capacity", "renewed", True, None)]
        assert [(t, i, a) for t, i, a, _ in got[2:]] == [("bevflow/hall/alerts/gate/distance_incident", "forged", False)]
        assert got[2][3] > T0  # ended when it arrived, on the service's clock
    finally:
        session.close()
        receiver.close()
        service.terminate()
        service.wait(10)
        broker.stop()
