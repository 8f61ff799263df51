"""The bus with real Zenoh sessions on loopback: explicit endpoints, multicast scouting off."""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import os
import queue
import re
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

from bevflow import schemas
from bevflow.capture_time import CaptureWindow
from bevflow_services import bus
from bevflow_services.launcher import free_port

TIMEOUT = 5.0


@pytest.fixture(scope="module")
def endpoint() -> str:
    return f"tcp/127.0.0.1:{free_port()}"


@pytest.fixture(scope="module")
def sessions(endpoint):
    """(publisher side, subscriber side): two peers linked over one loopback TCP connection,
    shared by the module's tests; each test works in a site of its own (``keys``)."""
    a = bus.open_session(bus.BusConfig(listen=(endpoint,)))
    b = bus.open_session(bus.BusConfig(connect=(endpoint,)))
    yield a, b
    b.close()
    a.close()


@pytest.fixture
def keys(request) -> bus.Keys:
    return bus.Keys(re.sub(r"[^A-Za-z0-9_.-]", "_", request.node.name)[:60] + f"-{time.monotonic_ns()}")


KEYS = bus.Keys("hall")


def wait_for(condition, timeout: float = TIMEOUT) -> bool:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


def publication(session, key, codec) -> bus.Publication:
    pub = bus.Publication(session, key, codec)
    assert pub.wait_for_subscribers(TIMEOUT), "the subscriber never became visible to the publisher"
    return pub


# --- configuration and keys ----------------------------------------------------------------------
def test_config_reaches_zenoh():
    cfg = bus.BusConfig(mode="client", connect=("tcp/10.0.0.1:7447",), listen=("tcp/0.0.0.0:0",),
                        shm_pool_bytes=48 << 20, timestamping=True)
    conf = cfg.to_zenoh()
    assert json.loads(conf.get_json("mode")) == "client"
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/10.0.0.1:7447"]
    assert json.loads(conf.get_json("listen/endpoints")) == ["tcp/0.0.0.0:0"]
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    assert json.loads(conf.get_json("transport/shared_memory/enabled")) is True
    assert json.loads(conf.get_json("transport/shared_memory/transport_optimization/pool_size")) == 48 << 20
    assert json.loads(conf.get_json("timestamping/enabled")) is True


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"mode": "client"}, "client mode needs"),
        ({"mode": "broker"}, "bus mode must be one of"),
        ({"listen": ("127.0.0.1:7447",)}, "PROTOCOL/ADDRESS"),
    ],
)
def test_config_errors(kwargs, message):
    with pytest.raises(bus.BusError, match=message):
        bus.BusConfig(**kwargs)


def test_open_session_error_is_one_line():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(bus.BusError, match=f"cannot join the bus .*{port}.*in use") as err:
            bus.open_session(bus.BusConfig(listen=(f"tcp/127.0.0.1:{port}",)))
    assert "\n" not in str(err.value) and ".rs:" not in str(err.value)


@pytest.mark.parametrize(
    "argv, expected",
    [
        ([], bus.BusConfig()),
        (["-m", "client", "-e", "tcp/1.2.3.4:7447", "-e", "tcp/5.6.7.8:7447"],
         bus.BusConfig(mode="client", connect=("tcp/1.2.3.4:7447", "tcp/5.6.7.8:7447"))),
        (["--listen", "tcp/0.0.0.0:7448", "--multicast-scouting", "--no-shared-memory"],
         bus.BusConfig(listen=("tcp/0.0.0.0:7448",), multicast_scouting=True, shared_memory=False)),
        (["--no-multicast-scouting"], bus.BusConfig(multicast_scouting=False)),
    ],
)
def test_bus_arguments(argv, expected):
    parser = argparse.ArgumentParser()
    bus.add_bus_arguments(parser)
    assert bus.config_from_args(parser.parse_args(argv)) == expected


@pytest.mark.parametrize(
    "key, expected",
    [
        (KEYS.frame("cam1"), "bevflow/hall/cam/cam1/frame"),
        (KEYS.detections("cam-2"), "bevflow/hall/cam/cam-2/detections"),
        (KEYS.cylinders("*"), "bevflow/hall/cam/*/cylinders"),
        (KEYS.tracks, "bevflow/hall/tracks"),
        (KEYS.occupancy, "bevflow/hall/occupancy"),
        (KEYS.events, "bevflow/hall/events"),
        (KEYS.alive("tracker", "host-12"), "bevflow/hall/alive/tracker/host-12"),
        (KEYS.alive(), "bevflow/hall/alive/*/*"),
    ],
)
def test_keys(key, expected):
    assert key == expected


@pytest.mark.parametrize(
    "key, camera",
    [
        ("bevflow/hall/cam/cam1/frame", "cam1"),
        ("bevflow/hall/cam/c.7/cylinders", "c.7"),
        ("bevflow/hall/tracks", ValueError),
        ("bevflow/other/cam/cam1/frame", ValueError),
        ("bevflow/hall/cam/cam1/frame/extra", ValueError),
    ],
)
def test_camera_of(key, camera):
    if camera is ValueError:
        with pytest.raises(ValueError):
            KEYS.camera_of(key)
    else:
        assert KEYS.camera_of(key) == camera


@pytest.mark.parametrize("make", [lambda: bus.Keys("a/b"), lambda: KEYS.frame("c 1"), lambda: KEYS.alive("x", "a*b")])
def test_keys_refuse_unsafe_names(make):
    with pytest.raises(ValueError, match="cannot be part of a bus key"):
        make()


# --- typed round trips ---------------------------------------------------------------------------
T0 = 1_700_000_000_000_000_000
MESSAGES = [
    schemas.FrameHeader(camera="cam1", seq=3, capture_ns=T0, width=640, height=480, encoding="gray8"),
    schemas.Detections2D(camera="cam1", seq=3, capture_ns=T0, boxes=[(1.0, 2.0, 30.5, 80.0)], confidence=[0.9]),
    schemas.CameraCylinders(camera="cam1", seq=3, capture_ns=T0,
                            cylinders=[schemas.CylinderEstimate(xy=(1.5, -2.0), height=1.7, radius=0.25,
                                                                occluded=True)]),
    schemas.Tracks(site="hall", time_ns=T0, tracks=[schemas.TrackState(id=4, xy=(1.0, 2.0), cameras=["cam1"])],
                   violations=[(4, 5)]),
    schemas.Occupancy(site="hall", time_ns=T0, total=12, capacity=100,
                      zones=[schemas.ZoneOccupancy(id="gate", count=3, capacity=10)]),
]
EVENTS = [
    schemas.DistanceViolation(id="v1", start_ns=T0, tracks=[4, 5], min_distance_m=1.2, limit_m=2.0,
                              position=(1.0, 1.0)),
    schemas.OverCapacity(id="c1", start_ns=T0, end_ns=T0 + 5, zone="gate", capacity=10, peak=14),
    schemas.CalibrationDrift(id="d1", start_ns=T0, camera="cam2", shift_m=0.4, reference_camera="cam1"),
    schemas.CameraHealthEvent(id="h1", start_ns=T0, type="camera_down", camera="cam3", reason="no frames"),
]


@pytest.mark.parametrize(
    "codec, message",
    [(bus.JsonCodec(type(m)), m) for m in MESSAGES] + [(bus.JsonCodec(schemas.Event, "Event"), e) for e in EVENTS],
    ids=[type(m).__name__ for m in MESSAGES] + [e.type for e in EVENTS],
)
def test_message_round_trip(keys, sessions, codec, message):
    a, b = sessions
    received: queue.Queue = queue.Queue()
    sub = bus.subscribe(b, keys.events, codec, received.put)
    publication(a, keys.events, codec).put(message)
    got = received.get(timeout=TIMEOUT)
    assert got == message and type(got) is type(message)
    assert sub.stats.snapshot() == {"received": 1, "decoded": 1, "rejected": {}, "dropped": 0, "handler_errors": 0}


@pytest.mark.parametrize(
    "header, image",
    [
        (schemas.FrameHeader(camera="cam1", seq=9, capture_ns=T0, width=64, height=48),
         np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)),
        (schemas.FrameHeader(camera="cam2", seq=0, capture_ns=T0, width=1280, height=1280),
         np.random.default_rng(1).integers(0, 256, (1280, 1280, 3), dtype=np.uint8)),
        (schemas.FrameHeader(camera="cam3", seq=1, capture_ns=T0, width=5, height=4, encoding="gray8"),
         np.arange(20, dtype=np.uint8).reshape(4, 5)),
        (schemas.FrameHeader(camera="cam4", seq=2, capture_ns=T0, width=640, height=480, encoding="jpeg"),
         np.frombuffer(b"\xff\xd8not really a jpeg\xff\xd9", dtype=np.uint8)),
    ],
    ids=["bgr8", "bgr8-1280", "gray8", "jpeg"],
)
def test_frame_round_trip(keys, sessions, header, image):
    a, b = sessions
    received: queue.Queue = queue.Queue()
    bus.subscribe(b, keys.frame("*"), bus.FRAMES, received.put)
    raw: queue.Queue = queue.Queue()
    b.declare_subscriber(keys.frame("*"), lambda s: raw.put((str(s.key_expr), str(s.encoding))))
    pub = publication(a, keys.frame(header.camera), bus.FRAMES)
    frame = None
    for _ in range(20):  # frames are best effort: the first one through shared memory is dropped
        pub.put(bus.Frame(header, image))
        try:
            frame = received.get(timeout=0.25)
            break
        except queue.Empty:
            pass
    assert frame is not None
    assert frame.header == header
    np.testing.assert_array_equal(frame.image, image)
    key, encoding = raw.get(timeout=TIMEOUT)
    assert keys.camera_of(key) == header.camera
    raw_schema = f"application/octet-stream;{header.encoding};{header.width}x{header.height}"
    assert encoding == ("image/jpeg" if header.encoding == "jpeg" else raw_schema)


@pytest.mark.parametrize(
    "image",
    [np.zeros((48, 64), np.uint8), np.zeros((48, 64, 3), np.float32), np.zeros((64, 48, 3), np.uint8)],
)
def test_frame_that_contradicts_its_header_is_a_bug(image):
    header = schemas.FrameHeader(camera="c", seq=0, capture_ns=0, width=64, height=48)
    with pytest.raises(ValueError, match="does not match its header"):
        bus.FRAMES.encode(bus.Frame(header, image))


# --- bad input -----------------------------------------------------------------------------------
GOOD_TRACKS = schemas.Tracks(site="hall", time_ns=T0)
GOOD_HEADER = schemas.FrameHeader(camera="cam1", seq=0, capture_ns=T0, width=4, height=2)


def _tracks_json(**changes) -> bytes:
    return json.dumps({**GOOD_TRACKS.model_dump(mode="json"), **changes}).encode()


TRACKS = bus.JsonCodec(schemas.Tracks)
EVENT = bus.JsonCodec(schemas.Event, "Event")
GOOD_FRAME = bus.Frame(GOOD_HEADER, np.ones((2, 4, 3), np.uint8))
GOOD_EVENT = EVENTS[0]


@pytest.mark.parametrize(
    "codec, good, payload, attachment, reason",
    [
        (TRACKS, GOOD_TRACKS, np.random.default_rng(2).bytes(200), None, "malformed"),
        (TRACKS, GOOD_TRACKS, b'{"site": "hall", "time_ns"', None, "malformed"),
        (TRACKS, GOOD_TRACKS, b"[1, 2, 3]", None, "invalid"),
        (TRACKS, GOOD_TRACKS, _tracks_json(time_ns=-5), None, "invalid"),
        (TRACKS, GOOD_TRACKS, _tracks_json(schema_version=2, heading=[0, 1]), None, "schema_version"),
        (TRACKS, GOOD_TRACKS, _tracks_json(heading=[0, 1]), None, "unknown_fields"),
        (EVENT, GOOD_EVENT, b'{"type": "fire_alarm", "id": "x", "start_ns": 0}', None, "invalid"),
        (EVENT, GOOD_EVENT, GOOD_EVENT.model_dump_json().replace('"schema_version":1', '"schema_version":3').encode(),
         None, "schema_version"),
        (bus.FRAMES, GOOD_FRAME, bytes(4 * 2 * 3 - 1), GOOD_HEADER.model_dump_json().encode(), "frame_size"),
        (bus.FRAMES, GOOD_FRAME, bytes(4 * 2 * 3), None, "no_header"),
        (bus.FRAMES, GOOD_FRAME, bytes(4 * 2 * 3), b"\x00\x01garbage", "malformed"),
        (bus.FRAMES, GOOD_FRAME, bytes(4 * 2 * 3),
         GOOD_HEADER.model_dump_json().replace('"seq":0', '"seq":-1').encode(), "invalid"),
        # Capture times beyond this host's clock plus the window (bevflow.capture_time).
        (TRACKS, GOOD_TRACKS, _tracks_json(time_ns=2**63 - 1), None, "future_time"),
        (TRACKS, GOOD_TRACKS, _tracks_json(time_ns=time.time_ns() + 3600 * 10**9), None, "future_time"),
        (EVENT, GOOD_EVENT, GOOD_EVENT.model_copy(update={"raised_ns": 2**62}).model_dump_json().encode(),
         None, "future_time"),
        (bus.FRAMES, GOOD_FRAME, bytes(4 * 2 * 3),
         GOOD_HEADER.model_copy(update={"capture_ns": 2**63 - 1}).model_dump_json().encode(), "future_time"),
    ],
)
def test_bad_payload_is_counted_and_the_stream_goes_on(keys, sessions, codec, good, payload, attachment, reason):
    a, b = sessions
    received: queue.Queue = queue.Queue()
    sub = bus.subscribe(b, keys.tracks, codec, received.put)
    pub = publication(a, keys.tracks, codec)
    a.put(keys.tracks, payload, attachment=attachment)
    pub.put(good)
    got = received.get(timeout=TIMEOUT)
    assert (got.header == good.header) if codec is bus.FRAMES else (got == good)
    assert received.empty()
    assert sub.stats.snapshot() == {"received": 2, "decoded": 1, "rejected": {reason: 1}, "dropped": 0,
                                    "handler_errors": 0}


def test_a_future_time_is_logged_naming_where_it_came_from(keys, sessions, caplog):
    a, b = sessions
    received: queue.Queue = queue.Queue()
    sub = bus.subscribe(b, keys.tracks, TRACKS, received.put)
    publication(a, keys.tracks, TRACKS)
    with caplog.at_level(logging.WARNING, logger="bevflow_services.bus"):
        a.put(keys.tracks, _tracks_json(site="forged", time_ns=2**63 - 1))
        assert wait_for(lambda: sub.stats.snapshot()["rejected"])
    assert [m for m in caplog.messages if keys.tracks in m and "future_time" in m and "site 'forged'" in m
            and "ahead of this host's clock" in m]


@pytest.mark.parametrize(
    ("environ", "future_s", "past_s"),
    [
        ({}, 5.0, 3600.0),
        ({"BEVFLOW_CLOCK_FUTURE_S": "2.5", "BEVFLOW_CLOCK_PAST_S": "60"}, 2.5, 60.0),
        ({"BEVFLOW_CLOCK_FUTURE_S": " "}, 5.0, 3600.0),
    ],
)
def test_the_capture_window_is_one_setting(environ, future_s, past_s):
    assert CaptureWindow.from_environment(environ) == CaptureWindow(future_s, past_s)


@pytest.mark.parametrize("value", ["-1", "soon", "inf", "nan"])
def test_a_bad_capture_window_names_its_variable(value):
    with pytest.raises(ValueError, match="BEVFLOW_CLOCK_FUTURE_S"):
        CaptureWindow.from_environment({"BEVFLOW_CLOCK_FUTURE_S": value})


def test_a_message_written_as_json_by_its_maker_arrives_like_any_other(keys, sessions):
    a, b = sessions
    codec = bus.JsonCodec(schemas.Tracks)
    received: queue.Queue = queue.Queue()
    sub = bus.subscribe(b, keys.tracks, codec, received.put)
    publication(a, keys.tracks, codec).put_json(GOOD_TRACKS.model_dump_json().encode())
    assert received.get(timeout=TIMEOUT) == GOOD_TRACKS
    assert sub.stats.snapshot()["decoded"] == 1


def test_only_json_publications_take_json(keys, sessions):
    with bus.Publication(sessions[0], keys.frame("cam1"), bus.FRAMES) as frames, pytest.raises(TypeError, match="JsonCodec"):
        frames.put_json(b"{}")


def test_publishing_the_wrong_type_is_a_bug():
    with pytest.raises(Exception, match="serializ"):
        EVENT.encode(GOOD_TRACKS)


def test_handler_exception_is_counted_and_the_stream_goes_on(keys, sessions):
    a, b = sessions
    seen: queue.Queue = queue.Queue()

    def handler(message):
        seen.put(message.time_ns)
        if message.time_ns == 1:
            raise RuntimeError("handler bug")

    sub = bus.subscribe(b, keys.tracks, bus.JsonCodec(schemas.Tracks), handler)
    pub = publication(a, keys.tracks, bus.JsonCodec(schemas.Tracks))
    pub.put(schemas.Tracks(site="hall", time_ns=1))
    pub.put(schemas.Tracks(site="hall", time_ns=2))
    assert [seen.get(timeout=TIMEOUT), seen.get(timeout=TIMEOUT)] == [1, 2]
    assert sub.stats.handler_errors == 1


def test_rejections_are_logged_at_a_limited_rate(caplog):
    stats = bus.BusStats(log_every_s=3600)
    with caplog.at_level(logging.WARNING, logger="bevflow_services.bus"):
        for _ in range(5):
            stats.reject("k", "malformed", "bad")
        stats.reject("k", "frame_size", "short")
    assert stats.rejected == {"malformed": 5, "frame_size": 1}
    assert [r.getMessage().split(": ")[1] for r in caplog.records] == ["malformed", "frame_size"]


def test_log_line_reports_what_it_left_out(caplog):
    stats = bus.BusStats(log_every_s=3600)
    with caplog.at_level(logging.WARNING, logger="bevflow_services.bus"):
        for _ in range(4):
            stats.reject("k", "malformed", "bad")
        stats.log_every_s = 0.0
        stats.reject("k", "malformed", "bad")
    assert len(caplog.records) == 2
    assert "(3 more since the last report)" in caplog.records[1].getMessage()


# --- delivery to consumers -----------------------------------------------------------------------
def test_async_subscription_drops_oldest_when_full(keys, sessions):
    a, b = sessions
    codec = bus.JsonCodec(schemas.Tracks)

    async def scenario():
        sub = bus.AsyncSubscription(b, keys.tracks, codec, maxsize=3)
        pub = publication(a, keys.tracks, codec)
        for t in range(10):
            pub.put(schemas.Tracks(site="hall", time_ns=t))
        deadline = time.monotonic() + TIMEOUT
        while sub.stats.dropped + sub.queue.qsize() < 10 and time.monotonic() < deadline:
            await asyncio.sleep(0.005)
        got = [(await asyncio.wait_for(sub.get(), TIMEOUT)).time_ns for _ in range(3)]
        pub.put(schemas.Tracks(site="hall", time_ns=10))
        async for message in sub:
            got.append(message.time_ns)
            break
        return got, sub.stats.snapshot()

    got, stats = asyncio.run(asyncio.wait_for(scenario(), 3 * TIMEOUT))
    assert got == [7, 8, 9, 10]
    assert stats["dropped"] == 7 and stats["received"] == 11


def test_latest_subscription_keeps_only_the_newest(keys, sessions):
    a, b = sessions
    codec = bus.JsonCodec(schemas.Tracks)
    sub = bus.LatestSubscription(b, keys.tracks, codec)
    pub = publication(a, keys.tracks, codec)
    for t in range(5):
        pub.put(schemas.Tracks(site="hall", time_ns=t))
    assert wait_for(lambda: sub.stats.received == 5)
    assert sub.take(timeout=TIMEOUT).time_ns == 4
    assert sub.take(timeout=0.05) is None
    assert sub.stats.dropped == 4 and sub.stats.decoded == 1


def test_latest_subscription_skips_a_bad_newest_sample(keys, sessions):
    a, b = sessions
    codec = bus.JsonCodec(schemas.Tracks)
    sub = bus.LatestSubscription(b, keys.tracks, codec, keep=2)
    pub = publication(a, keys.tracks, codec)
    pub.put(schemas.Tracks(site="hall", time_ns=1))
    a.put(keys.tracks, b"not json")
    assert wait_for(lambda: sub.stats.received == 2)
    assert sub.take(timeout=TIMEOUT).time_ns == 1
    assert sub.take(timeout=0.05) is None
    assert sub.stats.rejected == {"malformed": 1}


def test_latest_subscription_take_waits_for_a_sample(keys, sessions):
    a, b = sessions
    codec = bus.JsonCodec(schemas.Tracks)
    sub = bus.LatestSubscription(b, keys.tracks, codec)
    pub = publication(a, keys.tracks, codec)
    threading.Timer(0.05, lambda: pub.put(schemas.Tracks(site="hall", time_ns=42))).start()
    assert sub.take(timeout=TIMEOUT).time_ns == 42


# --- liveliness ----------------------------------------------------------------------------------
def test_live_services_follow_tokens(keys, sessions):
    a, b = sessions
    changes: queue.Queue = queue.Queue()
    watcher = bus.LiveServices(b, keys, on_change=lambda s, alive: changes.put((s, alive)))
    token = bus.announce(a, keys, "tracker", "t1")
    assert watcher.wait_until(lambda live: bus.LiveService("tracker", "t1") in live, TIMEOUT)
    token.undeclare()
    assert watcher.wait_until(lambda live: not live, TIMEOUT)
    assert [changes.get(timeout=TIMEOUT), changes.get(timeout=TIMEOUT)] == [
        (bus.LiveService("tracker", "t1"), True), (bus.LiveService("tracker", "t1"), False)]


def test_live_services_include_those_up_before_the_watcher(keys, sessions):
    a, b = sessions
    tokens = [bus.announce(a, keys, "ingest", "cam1"), bus.announce(a, keys, "gateway", "g"),
              bus.announce(a, bus.Keys("other-site"), "ingest", "x")]
    watcher = bus.LiveServices(b, keys)
    assert watcher.wait_until(bus.all_alive(["ingest", "gateway"]), TIMEOUT)
    assert watcher.current() == [bus.LiveService("gateway", "g"), bus.LiveService("ingest", "cam1")]
    del tokens


CHILD = textwrap.dedent("""
    import sys, time
    from bevflow_services import bus
    session = bus.open_session(bus.BusConfig(connect=(sys.argv[1],)))
    token = bus.announce(session, bus.Keys(sys.argv[2]), "ingest", "child")
    print("ready", flush=True)
    time.sleep(60)
""")


def test_a_killed_process_disappears_from_live_services(keys, sessions, endpoint):
    _, b = sessions
    watcher = bus.LiveServices(b, keys)
    child = subprocess.Popen([sys.executable, "-c", CHILD, endpoint, keys.site], stdout=subprocess.PIPE, text=True)
    try:
        assert watcher.wait_until(lambda live: bus.LiveService("ingest", "child") in live, 2 * TIMEOUT)
        os.kill(child.pid, signal.SIGKILL)
        assert watcher.wait_until(lambda live: bus.LiveService("ingest", "child") not in live, 2 * TIMEOUT)
    finally:
        child.kill()
        child.wait(TIMEOUT)
