"""The websockets, over a real server and client (so back-pressure and refusals are the real thing)."""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import ClientConnection, connect

from bevflow.schemas import AlertMessage, CameraHealthEvent, Tracks
from bevflow.site import Site

from bevflow_services.gateway import GatewayState, create_app
from tests.services.gateway.feed import S, T0, incident, over_capacity, tracks, violation
from tests.services.gateway.live import serve_in_thread

TIMEOUT_S = 10.0


@pytest.fixture
def server(site: Site, state: GatewayState) -> Iterator[str]:
    with serve_in_thread(create_app(site, state), send_buffer_bytes=4096) as address:
        yield address


def _open(server: str, path: str, **kwargs) -> ClientConnection:
    return connect(f"ws://{server}{path}", open_timeout=TIMEOUT_S, **kwargs)


def _receive_until(ws: ClientConnection, last_id: str) -> list[dict]:
    received = []
    while not received or received[-1]["id"] != last_id:
        received.append(json.loads(ws.recv(timeout=TIMEOUT_S)))
    return received


def _mixed_alerts() -> list:
    return [
        violation("v-gate", T0, zone="gate"),
        incident("i-gate", T0, zone="gate"),
        violation("v-shop", T0 + S, zone="shop"),
        violation("v-site", T0 + 2 * S, zone=None),
        over_capacity("c-gate", T0 + 3 * S, zone="gate"),
        over_capacity("c-site", T0 + 4 * S, zone=None),
        CameraHealthEvent(id="down", type="camera_down", camera="north", start_ns=T0 + 5 * S),
        violation("v-gate", T0, zone="gate", end_ns=T0 + 6 * S),
    ]


END_V = violation("end", T0 + 9 * S, zone="gate")
END_C = over_capacity("end", T0 + 9 * S, zone="gate")
END_I = incident("end", T0 + 9 * S, zone="gate")


@pytest.mark.parametrize(
    ("query", "last", "expected"),
    [
        ("", END_C, ["i-gate", "c-gate", "c-site", "down", "end"]),  # pair events only when asked for
        ("?types=distance_violation", END_V, ["v-gate", "v-shop", "v-site", "v-gate", "end"]),
        ("?zones=gate", END_C, ["i-gate", "c-gate", "end"]),
        ("?types=distance_incident", END_I, ["i-gate", "end"]),
        ("?types=distance_violation,over_capacity&zones=gate", END_C, ["v-gate", "c-gate", "v-gate", "end"]),
        ("?types=over_capacity&zones=gate,shop", END_C, ["c-gate", "end"]),
    ],
)
def test_alert_subscribers_receive_only_what_their_filters_match(server: str, state: GatewayState, query, last, expected) -> None:
    with _open(server, f"/ws/alerts{query}") as ws:
        for event in _mixed_alerts():
            state.apply(event)
        state.apply(last)  # a last alert the filter matches, to know when everything has arrived
        received = _receive_until(ws, "end")
    assert [a["id"] for a in received] == expected


def test_an_alert_carries_type_zone_start_and_tracks(server: str, state: GatewayState) -> None:
    with _open(server, "/ws/alerts?types=distance_violation") as ws:
        state.apply(violation("v1", T0 + 250_000_000, pair=(3, 8), zone="gate"))
        alert = json.loads(ws.recv(timeout=TIMEOUT_S))
    assert (alert["type"], alert["zone"], alert["start"], alert["tracks"], alert["active"]) == (
        "distance_violation", "gate", "2023-11-14T22:13:20.250Z", [3, 8], True,
    )
    assert AlertMessage.model_validate(alert).event.start_ns == T0 + 250_000_000


def test_replay_sends_the_active_alerts_first(server: str, state: GatewayState) -> None:
    state.apply(violation("old", T0, zone="gate", end_ns=T0 + S))  # ended: not replayed
    state.apply(violation("ongoing-gate", T0 + 2 * S, zone="gate"))
    state.apply(violation("ongoing-shop", T0 + 3 * S, zone="shop"))
    with _open(server, "/ws/alerts?types=distance_violation,over_capacity&zones=gate&replay=active") as ws:
        state.apply(over_capacity("end", T0 + 4 * S, zone="gate"))
        received = _receive_until(ws, "end")
    assert [a["id"] for a in received] == ["ongoing-gate", "end"]


def _raised(event, at_ns: int):
    return event.model_copy(update={"raised_ns": at_ns})


def test_since_replays_what_came_after_that_alert_then_goes_on_live(server: str, state: GatewayState) -> None:
    """Alerts in the order they were raised, each once in its newest state: the end of an alert
    raised before the cursor is missed news, and alerts of other types or zones stay out."""
    for event in [
        _raised(incident("long", T0), T0 + S),
        _raised(incident("seen", T0 + 2 * S), T0 + 3 * S),  # the last alert the client received
        _raised(over_capacity("c1", T0 + 4 * S), T0 + 4 * S),
        _raised(incident("long", T0, end_ns=T0 + 5 * S), T0 + 6 * S),
        _raised(over_capacity("c-shop", T0 + 6 * S, zone="shop"), T0 + 7 * S),
        _raised(violation("pair", T0 + 7 * S), T0 + 7 * S),
        _raised(over_capacity("c1", T0 + 4 * S, end_ns=T0 + 8 * S), T0 + 8 * S),
    ]:
        state.apply(event)
    with _open(server, "/ws/alerts?zones=gate&since=seen") as ws:
        replayed = _receive_until(ws, "c1")
        state.apply(_raised(incident("after", T0 + 9 * S), T0 + 9 * S))
        live = _receive_until(ws, "after")
    assert [(a["id"], a["active"]) for a in replayed] == [("long", False), ("c1", False)]
    assert [a["id"] for a in live] == ["after"]


def test_since_reads_alerts_the_gateway_never_saw_from_the_database(site: Site, tmp_path) -> None:
    """A restarted gateway: the recorder's database is all it has."""
    from bevflow_services.gateway.history_db import DatabaseHistory
    from bevflow_services.storage import HistoryDatabase
    from bevflow_services.storage.batch import Batch

    db = HistoryDatabase.open(f"sqlite:///{tmp_path / 'history.db'}")
    batch = Batch()
    for k in range(5):
        batch.add_event(_raised(incident(f"i{k}", T0 + k * S), T0 + k * S))
    db.write(batch)
    state = GatewayState(site, DatabaseHistory(db))
    with serve_in_thread(create_app(site, state)) as address, _open(address, "/ws/alerts?since=i1") as ws:
        replayed = _receive_until(ws, "i4")
    assert [a["id"] for a in replayed] == ["i2", "i3", "i4"]


@pytest.mark.parametrize(
    ("path", "detail"),
    [
        ("/ws/alerts?since=nobody", "since: no alert 'nobody' in the history"),
        ("/ws/alerts?since=", "since: give the id of the last alert received"),
        ("/ws/alerts?since=x&replay=active", "since and replay=active exclude each other"),
        ("/ws/alerts?types=fire", "types: unknown value(s) fire; allowed: distance_violation, distance_incident, over_capacity"),
        ("/ws/alerts?zones=gate,roof", "zones: unknown value(s) roof; allowed: gate, shop"),
        ("/ws/alerts?replay=all", "replay: must be one of none, active, got 'all'"),
        ("/ws/alerts?zone=gate", "unknown parameter(s) zone; allowed: types, zones, replay, since"),
        ("/ws/tracks?zones=gate", "unknown parameter(s) zones; /ws/tracks takes only token"),
    ],
)
def test_a_bad_subscription_is_refused_with_400_naming_the_parameter(server: str, path: str, detail: str) -> None:
    with pytest.raises(InvalidStatus) as refused:
        _open(server, path)
    response = refused.value.response
    assert response.status_code == 400
    assert json.loads(response.body)["detail"].startswith(detail)


def test_the_tracks_stream_starts_with_the_latest_tick(server: str, state: GatewayState) -> None:
    state.apply(tracks(T0, {1: (0.0, 0.0)}))
    with _open(server, "/ws/tracks") as ws:
        first = Tracks.model_validate_json(ws.recv(timeout=TIMEOUT_S))
        state.apply(tracks(T0 + S, {1: (0.5, 0.0), 2: (3.0, 3.0)}, [(1, 2)]))
        second = Tracks.model_validate_json(ws.recv(timeout=TIMEOUT_S))
    assert first.time_ns == T0 and [t.id for t in first.tracks] == [1]
    assert second.time_ns == T0 + S and second.violations == [(1, 2)]


def test_a_client_that_stops_reading_does_not_hold_up_the_others(server: str, state: GatewayState) -> None:
    """The stuck client's socket fills up; its queue then drops the oldest alerts while the
    reading client keeps receiving every alert, in order."""
    n, batch = 2000, 50
    path = "/ws/alerts?types=distance_violation"
    with _raw_websocket(server, path) as stuck, _open(server, path) as reader:
        got = []
        for start in range(0, n, batch):
            for k in range(start, start + batch):
                state.apply(violation(f"a{k}", T0 + k * 1_000_000, pair=(k, k + 1)))
            got += [json.loads(reader.recv(timeout=TIMEOUT_S))["id"] for _ in range(batch)]
        dropped = sorted(sub.dropped for sub in state.alerts.subscriptions)
        # Now read the stuck client: it missed alerts in the middle but ends with the newest one.
        late = []
        while not late or late[-1] != f"a{n - 1}":
            late.append(json.loads(_read_text_frame(stuck))["id"])
    assert got == [f"a{k}" for k in range(n)]
    assert dropped[0] == 0 and dropped[1] > 0
    assert len(late) + dropped[1] == n
    assert late[0] == "a0" and late == sorted(late, key=lambda i: int(i[1:]))


@contextmanager
def _raw_websocket(server: str, path: str) -> Iterator[socket.socket]:
    """A websocket client that reads nothing unless told to, with a tiny receive buffer."""
    host, port = server.split(":")
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 2048)  # before connecting, so the window stays small
    sock.settimeout(TIMEOUT_S)
    sock.connect((host, int(port)))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        f"GET {path} HTTP/1.1\r\nHost: {server}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
    )
    head = b""
    while b"\r\n\r\n" not in head:
        head += sock.recv(1)
    assert head.startswith(b"HTTP/1.1 101"), head
    try:
        yield sock
    finally:
        sock.close()


def _read_exactly(sock: socket.socket, n: int) -> bytes:
    chunks = b""
    while len(chunks) < n:
        chunk = sock.recv(n - len(chunks))
        assert chunk, "connection closed"
        chunks += chunk
    return chunks


def _read_text_frame(sock: socket.socket) -> str:
    """One unfragmented, unmasked text frame (what a server sends)."""
    first, second = _read_exactly(sock, 2)
    assert first & 0x0F == 0x1, f"opcode {first & 0x0F}"
    length = second & 0x7F
    if length == 126:
        length = struct.unpack("!H", _read_exactly(sock, 2))[0]
    elif length == 127:
        length = struct.unpack("!Q", _read_exactly(sock, 8))[0]
    return _read_exactly(sock, length).decode()
