"""``/ws/alerts?since=``: a client away for 30 s gets every alert raised meanwhile once, in order,
then the live ones, while the gateway itself restarts during its absence (so what was raised
while the gateway was down comes from the recorder's database, the rest from the gateway's own
memory of recent alerts). Recorder and gateway run as processes; the test publishes the alerts on
the bus as the tracker would."""

from __future__ import annotations

import itertools
import json
import os
import signal
import time
from pathlib import Path

import pytest
from websockets.sync.client import ClientConnection, connect

from bevflow.schemas import Event

from bevflow_services import bus
from bevflow_services.launcher import Child, ServiceGroup, free_port
from tests.services.gateway.feed import SITE_YAML, incident

pytestmark = [pytest.mark.e2e, pytest.mark.slow]
TIMEOUT_S = 30.0
CLIENT_AWAY_S = 30.0
MISSED = 6  # alerts raised while the client is away, half of them while the gateway is down
PROBE = "probe-"


def raised(event_id: str, start_ns: int | None = None, *, ended: bool = True) -> Event:
    """An incident stamped as the tracker stamps it: raised now (its end now, if ``ended``)."""
    now = time.time_ns()
    start = now if start_ns is None else start_ns
    return incident(event_id, start, end_ns=now if ended else None).model_copy(update={"raised_ns": now})


def start_gateway(group: ServiceGroup, port: int, db: Path) -> Child:
    gateway = group.start("gateway", "--port", str(port), "--db", str(db), "--auth", "off", "--no-view3d")
    group.wait_http(f"http://127.0.0.1:{port}/healthz", TIMEOUT_S)
    return gateway


def stop(group: ServiceGroup, child: Child) -> None:
    os.killpg(child.process.pid, signal.SIGTERM)
    child.process.wait(10)
    group.children.remove(child)


def receive(ws: ClientConnection, n: int) -> list[dict]:
    """The next ``n`` alerts on ``ws``, past any late probe (``hear_each_other``)."""
    got: list[dict] = []
    while len(got) < n:
        try:
            alert = json.loads(ws.recv(timeout=TIMEOUT_S))
        except TimeoutError:
            raise AssertionError(f"{len(got)} of {n} alerts arrived: {[(a['id'], a['active']) for a in got]}") from None
        if not alert["id"].startswith(PROBE):
            got.append(alert)
    return got


def hear_each_other(events: bus.CachedPublication[Event], ws: ClientConnection) -> None:
    """Publish probe alerts until the first reaches ``ws``: the gateway hears live alerts only, and
    the recorder's subscription alone satisfies the bus's own wait for subscribers."""
    deadline = time.monotonic() + TIMEOUT_S
    for k in itertools.count():
        events.put(raised(f"{PROBE}{k}"))
        try:
            ws.recv(timeout=0.5)
            return
        except TimeoutError:
            if time.monotonic() > deadline:
                raise AssertionError(f"no probe alert reached the gateway's websocket in {TIMEOUT_S:g} s") from None


def test_a_client_back_after_30_s_with_since_gets_every_missed_alert_once_in_order(tmp_path: Path) -> None:
    site, db, port = tmp_path / "site.yaml", tmp_path / "history.db", free_port()
    site.write_text(SITE_YAML)
    ws_url = f"ws://127.0.0.1:{port}/ws/alerts"
    with ServiceGroup(site=str(site), log_dir=tmp_path) as group:
        group.start("recorder", "--db", str(db))
        gateway = start_gateway(group, port, db)
        session = bus.open_session(bus.BusConfig(connect=(f"tcp/127.0.0.1:{group.hub_port}",), timestamping=True))
        key, codec = bus.Keys("hall").events, bus.JsonCodec(Event, "Event")
        with bus.Publication(session, key, codec) as probe:
            assert probe.wait_for_subscribers(TIMEOUT_S)
        # As the tracker publishes alerts: a message the bus loses while a peer comes or goes
        # (the gateway here) is fetched again by the recorder from this cache.
        events = bus.CachedPublication(session, key, codec)
        try:
            long = raised("long", ended=False)
            with connect(ws_url, open_timeout=TIMEOUT_S) as ws:
                hear_each_other(events, ws)
                for event in (long, raised("seen")):
                    events.put(event)
                seen = receive(ws, 2)
            assert [(a["id"], a["active"]) for a in seen] == [("long", True), ("seen", False)]

            # Away: the gateway stops for the first half, and "long" (raised before) ends meanwhile.
            away_until = time.monotonic() + CLIENT_AWAY_S
            stop(group, gateway)
            missed = []
            for k in range(MISSED):
                if k == MISSED // 2:
                    gateway = start_gateway(group, port, db)
                now_raised = [raised(f"m{k}")] + ([raised("long", long.start_ns)] if k == 1 else [])
                for event in now_raised:
                    events.put(event)
                missed += now_raised
                time.sleep(CLIENT_AWAY_S / (MISSED + 1))
            time.sleep(max(0.0, away_until - time.monotonic()))

            with connect(f"{ws_url}?since=seen", open_timeout=TIMEOUT_S) as ws:
                replayed = receive(ws, len(missed))
                events.put(raised("live"))
                live = receive(ws, 1)
                with pytest.raises(TimeoutError):
                    ws.recv(timeout=1.0)  # and nothing twice
            assert [(a["id"], a["active"]) for a in replayed] == [(e.id, False) for e in missed]
            assert [a["id"] for a in live] == ["live"]
        finally:
            events.close()
            session.close()
