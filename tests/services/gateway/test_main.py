"""The gateway fed from a real bus: two Zenoh peers on loopback, multicast scouting off."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import pytest
from fastapi.testclient import TestClient

from bevflow.schemas import Detections2D, Event, Occupancy, Tracks
from bevflow.site import Site

from bevflow_services import bus
from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.cli.serve import run_service
from bevflow_services.gateway.main import bus_feed
from bevflow_services.launcher import free_port
from bevflow_services.runtime import UserError
from tests.services.gateway.feed import S, SITE_YAML, T0, FakeClock, occupancy, tracks, violation

TIMEOUT_S = 10.0


def _wait_for(condition: Callable[[], bool]) -> bool:
    deadline = time.monotonic() + TIMEOUT_S
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


class Garbage:
    """A codec that sends bytes no schema accepts."""

    name = "garbage"

    def __init__(self) -> None:
        self.encoding = bus.JsonCodec(Tracks).encoding

    def encode(self, message: object) -> tuple[bytes, None, object]:
        return b"{not json", None, self.encoding


@pytest.fixture
def sessions() -> Iterator[tuple[object, object]]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    publisher_side = bus.open_session(bus.BusConfig(listen=(endpoint,)))
    gateway_side = bus.open_session(bus.BusConfig(connect=(endpoint,)))
    yield publisher_side, gateway_side
    gateway_side.close()
    publisher_side.close()


def test_the_gateway_serves_what_the_bus_delivers(site: Site, sessions) -> None:
    publisher_side, gateway_side = sessions
    keys = bus.Keys("hall")
    state = GatewayState(site, clock=lambda: T0 + 2 * S)  # the feed's capture times are live
    stats = bus.BusStats()
    app = create_app(site, state, feed=bus_feed(gateway_side, state, stats))
    app.state.bus_stats = stats
    with TestClient(app) as client:
        token = bus.announce(publisher_side, keys, "tracker", "t-1")
        publications = {
            "tracks": bus.Publication(publisher_side, keys.tracks, bus.JsonCodec(Tracks)),
            "occupancy": bus.Publication(publisher_side, keys.occupancy, bus.JsonCodec(Occupancy)),
            "events": bus.Publication(publisher_side, keys.events, bus.JsonCodec(Event, "Event")),
            "detections": bus.Publication(publisher_side, keys.detections("north"), bus.JsonCodec(Detections2D)),
            "garbage": bus.Publication(publisher_side, keys.tracks, Garbage()),
        }
        assert all(p.wait_for_subscribers(TIMEOUT_S) for p in publications.values())
        publications["garbage"].put(None)  # rejected and counted; the stream goes on
        publications["tracks"].put(tracks(T0, {7: (1.0, 1.0)}, zones={7: ["gate"]}))
        publications["occupancy"].put(occupancy(T0, 1, gate=1))
        publications["events"].put(violation("v1", T0))
        publications["detections"].put(Detections2D(camera="north", seq=0, capture_ns=T0))
        publications["detections"].put(Detections2D(camera="north", seq=2, capture_ns=T0 + S))

        assert _wait_for(lambda: client.get("/api/tracks").json()["total"] == 1)
        assert _wait_for(lambda: client.get("/api/violations").json()["total"] == 1)
        assert _wait_for(lambda: client.get("/api/cameras/north").json()["frames_received"] == 2)
        assert _wait_for(lambda: {"tracker", "gateway"} <= {s["name"] for s in client.get("/api/health").json()["services"]})
        assert client.get("/api/occupancy").json()["zones"][0]["count"] == 1
        assert client.get("/api/cameras/north").json()["frames_dropped"] == 1
        health = client.get("/api/health").json()
        assert health["bus"]["rejected"] == {"malformed": 1}

        token.undeclare()
        assert _wait_for(lambda: "tracker" not in {s["name"] for s in client.get("/api/health").json()["services"]})
        for publication in publications.values():
            publication.close()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--site", "no/such/site.yaml"], "cannot read the site file"),
        (["--site", "no-such-built-in-site"], "no built-in site of that name"),
        (["--site", "{site}", "--mode", "client"], "client mode needs at least one --connect endpoint"),
        (["--site", "{site}"], "--auth on keeps its users in a database"),
        (["--site", "{site}", "--auth", "off", "--host", "0.0.0.0"], "--auth off is only allowed when serving on loopback"),
        (["--site", "{site}", "--auth", "off", "--tls-cert", "{site}"], "--tls-cert and --tls-key go together"),
        (["--site", "{site}", "--auth", "off", "--tls-cert", "no.pem", "--tls-key", "no.pem"], "--tls-cert no.pem: no such file"),
        (["--site", "{site}", "--auth", "off", "--cors-origin", "example.com"], "--cors-origin 'example.com'"),
    ],
)
def test_bad_arguments_are_one_line_for_the_user(tmp_path, argv: list[str], message: str) -> None:
    site_file = tmp_path / "site.yaml"
    site_file.write_text(SITE_YAML)
    with pytest.raises(UserError, match=message):
        run_service("gateway", [a.replace("{site}", str(site_file)) for a in argv])


def test_a_forged_far_future_tick_does_not_freeze_the_live_tracks(site: Site, sessions) -> None:
    """One tick at 2**63 - 1 ns used to become the latest, and every true tick after it was
    ignored as older, freezing /api/tracks and /ws/tracks until the gateway restarted."""
    publisher_side, gateway_side = sessions
    now = time.time_ns()
    state = GatewayState(site, clock=time.time_ns)
    stats = bus.BusStats()
    with TestClient(create_app(site, state, feed=bus_feed(gateway_side, state, stats))) as client:
        ticks = bus.Publication(publisher_side, bus.Keys("hall").tracks, bus.JsonCodec(Tracks))
        assert ticks.wait_for_subscribers(TIMEOUT_S)
        ticks.put(tracks(2**63 - 1, {666: (1.0, 1.0)}))
        ticks.put(tracks(now, {7: (2.0, 2.0)}))
        assert _wait_for(lambda: [t["id"] for t in client.get("/api/tracks").json()["items"]] == [7])
        assert stats.snapshot()["rejected"] == {"future_time": 1}
        ticks.close()


def test_the_state_accepts_the_bus_site_id_as_well(site: Site) -> None:
    state = GatewayState(site, site_id="hall-b", clock=FakeClock())
    assert state.apply(tracks(T0, {1: (0.0, 0.0)}).model_copy(update={"site": "hall-b"}))
    assert state.apply(tracks(T0 + S, {1: (0.0, 0.0)}))
    assert not state.apply(tracks(T0 + 2 * S, {}).model_copy(update={"site": "other"}))
