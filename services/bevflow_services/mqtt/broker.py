"""A connection to an MQTT broker (paho-mqtt) that reconnects by itself, for one kind of
message: ``Reliable`` sends one QoS 1 message at a time and waits for the broker's
acknowledgement, ``Latest`` fires retained QoS 0 updates (occupancy: only the newest matters).

Each keeps its own connection, so an acknowledgement is never mistaken for another's.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from urllib.parse import urlsplit

import paho.mqtt.client as mqtt
from paho.mqtt.enums import CallbackAPIVersion

from bevflow_services.redact import redact

log = logging.getLogger(__name__)

DEFAULT_PORT = 1883
RECONNECT_S = (1, 30)  # paho's reconnect backoff: first and longest wait
KEEPALIVE_S = 30


@dataclass(frozen=True)
class BrokerAddress:
    host: str
    port: int = DEFAULT_PORT
    user: str | None = None
    password: str | None = field(default=None, repr=False)

    @classmethod
    def parse(cls, url: str, password: str | None = None) -> BrokerAddress:
        """``mqtt://[user[:password]@]host[:port]``; ``ValueError`` naming what is wrong."""
        parts = urlsplit(url)
        if parts.scheme != "mqtt" or not parts.hostname:
            raise ValueError(f"broker {redact(url)!r}: give mqtt://HOST[:PORT] (mqtts is not supported yet)")
        return cls(parts.hostname, parts.port or DEFAULT_PORT, parts.username, password or parts.password)


class _Connection:
    def __init__(self, address: BrokerAddress, client_id: str) -> None:
        self.address = address
        self.connected = threading.Event()
        self.client = mqtt.Client(CallbackAPIVersion.VERSION2, client_id=client_id)
        if address.user:
            self.client.username_pw_set(address.user, address.password)
        self.client.on_connect = self._on_connect
        self.client.on_disconnect = self._on_disconnect
        self.client.reconnect_delay_set(*RECONNECT_S)
        self.client.connect_async(address.host, address.port, keepalive=KEEPALIVE_S)
        self.client.loop_start()

    def _on_connect(self, _client, _userdata, _flags, reason, _properties) -> None:
        if reason.is_failure:
            log.warning("the MQTT broker %s:%d refused the connection: %s", self.address.host, self.address.port, reason)
            return
        log.info("connected to the MQTT broker %s:%d", self.address.host, self.address.port)
        self.connected.set()

    def _on_disconnect(self, _client, _userdata, _flags, reason, _properties) -> None:
        if self.connected.is_set():
            log.warning("lost the MQTT broker %s:%d (%s); reconnecting", self.address.host, self.address.port, reason)
        self.connected.clear()

    def close(self) -> None:
        self.connected.clear()  # a disconnect asked for is no loss to warn about
        self.client.disconnect()
        self.client.loop_stop()


class Reliable(_Connection):
    """QoS 1, one message in flight: ``send`` returns once the broker acknowledged it. Across a
    lost connection paho sends the message again (flagged DUP) when the link is back."""

    def __init__(self, address: BrokerAddress, client_id: str) -> None:
        self._acked: set[int] = set()
        self._ack = threading.Condition()
        super().__init__(address, client_id)
        self.client.on_publish = self._on_publish

    def _on_publish(self, _client, _userdata, mid: int, _reason, _properties) -> None:
        with self._ack:
            self._acked.add(mid)
            self._ack.notify_all()

    def send(self, topic: str, payload: bytes, stop: threading.Event) -> bool:
        """Publish and wait for the acknowledgement; False if ``stop`` was set first (the message
        then counts as not sent)."""
        while not self.connected.wait(0.2):
            if stop.is_set():
                return False
        with self._ack:
            self._acked.clear()  # a late second acknowledgement of an earlier message
        info = self.client.publish(topic, payload, qos=1)
        with self._ack:
            while info.mid not in self._acked:
                if stop.is_set():
                    return False
                self._ack.wait(0.2)
        return True


class Latest(_Connection):
    """Retained QoS 0: the broker keeps the newest for subscribers that come later; an update
    made while the broker is unreachable is dropped (the next one replaces it anyway).
    ``on_connect`` messages (Home Assistant discovery) are published again at every connection."""

    def __init__(self, address: BrokerAddress, client_id: str, on_connect: Sequence[tuple[str, bytes]] = ()) -> None:
        self.announce = list(on_connect)
        super().__init__(address, client_id)

    def _on_connect(self, client, userdata, flags, reason, properties) -> None:
        super()._on_connect(client, userdata, flags, reason, properties)
        if not reason.is_failure:
            for topic, payload in self.announce:
                self.client.publish(topic, payload, qos=1, retain=True)

    def send(self, topic: str, payload: bytes) -> None:
        if self.connected.is_set():
            self.client.publish(topic, payload, qos=0, retain=True)
