"""Property-based fuzzing of the bus codecs: any payload and attachment decode to a message or
raise ``Rejected`` with a stable reason (never another exception), and a subscription fed garbage
over a real Zenoh session counts it and goes on delivering good messages."""

from __future__ import annotations

import json
import threading
import time
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import TypeAdapter

from bevflow import schemas
from bevflow.capture_time import CaptureWindow
from bevflow_services import bus
from tests.bevflow.test_schemas_fuzz import VALID_MESSAGES, json_values, mutated
from tests.services.test_bus import free_port, wait_for

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
REASONS = {"malformed", "schema_version", "unknown_fields", "invalid", "no_header", "frame_size"}

CODECS: dict[str, Any] = {name: bus.JsonCodec(model, name) for name, (model, _) in VALID_MESSAGES.items()}
CODEC_NAMES = sorted(CODECS)


def check_json_decode(name: str, payload: bytes) -> Any:
    """Decode with the service codec; a refusal names one of the known reasons."""
    codec = CODECS[name]
    try:
        message = codec.decode(payload, None)
    except bus.Rejected as exc:
        assert exc.reason in REASONS and exc.detail, (exc.reason, exc.detail)
        return None
    encoded, attachment, _ = codec.encode(message)
    assert attachment is None and codec.decode(encoded, None) == message
    return message


@FUZZ
@given(name=st.sampled_from(CODEC_NAMES), payload=st.binary(max_size=300))
def test_json_codec_on_arbitrary_bytes(name: str, payload: bytes) -> None:
    check_json_decode(name, payload)


@FUZZ
@given(name=st.sampled_from(CODEC_NAMES), tree=json_values)
def test_json_codec_on_arbitrary_json(name: str, tree: Any) -> None:
    check_json_decode(name, json.dumps(tree).encode())


@FUZZ
@given(data=st.data(), name=st.sampled_from(CODEC_NAMES))
def test_json_codec_on_mutated_messages(data: st.DataObject, name: str) -> None:
    check_json_decode(name, json.dumps(data.draw(mutated(VALID_MESSAGES[name][1]))).encode())


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (b"", "malformed"),
        (b"\xff\xfe{", "malformed"),
        (b'{"schema_version": 2}', "schema_version"),
        (b"[1, 2]", "invalid"),
    ],
)
def test_json_codec_reasons(payload: bytes, reason: str) -> None:
    with pytest.raises(bus.Rejected) as caught:
        CODECS["Tracks"].decode(payload, None)
    assert caught.value.reason == reason


# --- frames --------------------------------------------------------------------------------------
sizes = st.one_of(st.integers(1, 8), st.integers(-2, 2**70), st.sampled_from([2**31, 2**32, 2**62, 2**63, 2**64 + 1]))
headers = st.fixed_dictionaries(
    {"camera": st.text(max_size=5), "seq": st.integers(-1, 2**64), "capture_ns": st.integers(-1, 2**64),
     "width": sizes, "height": sizes, "encoding": st.sampled_from(["bgr8", "gray8", "jpeg", "rgb8", ""])},
)


def check_frame_decode(payload: bytes, attachment: bytes | None) -> bus.Frame | None:
    try:
        frame = bus.FRAMES.decode(payload, attachment)
    except bus.Rejected as exc:
        assert exc.reason in REASONS and exc.detail
        return None
    header, image = frame.header, frame.image
    assert image.dtype == np.uint8 and image.tobytes() == payload
    if header.encoding == "bgr8":
        assert image.shape == (header.height, header.width, 3)
    elif header.encoding == "gray8":
        assert image.shape == (header.height, header.width)
    else:
        assert image.ndim == 1 and len(image) > 0
    assert bus.FRAMES.encode(frame)[0] == payload
    return frame


@FUZZ
@given(payload=st.binary(max_size=64), header=headers)
def test_frame_codec_on_fuzzed_headers(payload: bytes, header: dict[str, Any]) -> None:
    check_frame_decode(payload, json.dumps(header).encode())


@FUZZ
@given(payload=st.binary(max_size=64), attachment=st.one_of(st.none(), st.binary(max_size=100)))
def test_frame_codec_on_arbitrary_attachments(payload: bytes, attachment: bytes | None) -> None:
    check_frame_decode(payload, attachment)


@FUZZ
@given(width=st.integers(1, 6), height=st.integers(1, 6), encoding=st.sampled_from(["bgr8", "gray8"]),
       extra=st.integers(-5, 5))
def test_frame_codec_accepts_exactly_the_right_size(width: int, height: int, encoding: str, extra: int) -> None:
    channels = 3 if encoding == "bgr8" else 1
    size = width * height * channels + extra
    header = schemas.FrameHeader(camera="c", seq=0, capture_ns=1, width=width, height=height, encoding=encoding)
    frame = check_frame_decode(bytes(range(256)) * 2 if size > 512 else bytes(max(0, size)),
                               header.model_dump_json().encode())
    assert (frame is not None) == (extra == 0)


@pytest.mark.parametrize(
    ("width", "height"),
    [(2**32, 2**32), (2**62, 2), (2**63, 1), (2**64 + 1, 1), (6148914691236517206, 1)],
    ids=["wraps-to-zero", "wraps-negative", "past-int64", "past-uint64", "wraps-to-two"],
)
def test_frame_sizes_that_overflow_64_bits_are_rejected(width: int, height: int) -> None:
    header = json.dumps({"camera": "c", "seq": 0, "capture_ns": 1, "width": width, "height": height}).encode()
    for payload in (b"", b"ab", b"abc", b"x" * 6):
        with pytest.raises(bus.Rejected) as caught:
            bus.FRAMES.decode(payload, header)
        assert caught.value.reason == "frame_size"


# --- capture times against the receiver's clock -------------------------------------------------
WINDOW = CaptureWindow(future_s=5.0, past_s=3600.0)
NOW = 1_800_000_000 * 10**9
FAR_TIMES = st.one_of(
    st.integers(0, 2**63 - 1),
    st.sampled_from([0, 1, 2**62, 2**63 - 1, NOW, NOW - 3600 * 10**9 - 1]),  # epoch, 2262, the past edge
    st.integers(NOW - 10 * 10**9, NOW + 10 * 10**9),  # around the future edge
)
TIMED = sorted(name for name, (_, example) in VALID_MESSAGES.items() if any(k.endswith("_ns") for k in example))


@FUZZ
@given(name=st.sampled_from(TIMED), data=st.data())
def test_every_time_a_message_carries_is_checked_against_the_clock(name: str, data: st.DataObject) -> None:
    """Any message, with any of its times anywhere from 1970 to 2262: refused exactly when one
    of them lies beyond the clock plus the window; far-past times are the live state's to judge."""
    model, example = VALID_MESSAGES[name]
    times = {k: data.draw(FAR_TIMES, label=k) for k in example if k.endswith("_ns")}
    message = TypeAdapter(model).validate_python({**example, **times})
    refused = WINDOW.first_too_new(message, NOW)
    assert (refused is not None) == any(t > NOW + 5 * 10**9 for t in times.values())
    assert refused is None or (refused[0] in times and times[refused[0]] == refused[1])


# --- through a real session ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def sessions():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    a = bus.open_session(bus.BusConfig(listen=(endpoint,)))
    b = bus.open_session(bus.BusConfig(connect=(endpoint,)))
    yield a, b
    b.close()
    a.close()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(garbage=st.lists(st.tuples(st.binary(max_size=80), st.one_of(st.none(), st.binary(max_size=40))),
                        min_size=1, max_size=5),
       codec_name=st.sampled_from(["Tracks", "Frame"]))
def test_a_subscription_survives_garbage_and_keeps_delivering(sessions, garbage, codec_name) -> None:
    publisher, subscriber = sessions
    key = f"bevflow/fuzz/{threading.get_ident()}/{id(garbage)}"
    codec = bus.FRAMES if codec_name == "Frame" else CODECS["Tracks"]
    good = (bus.Frame(schemas.FrameHeader(camera="c", seq=1, capture_ns=1, width=2, height=1, encoding="gray8"),
                      np.array([[1, 2]], dtype=np.uint8)) if codec_name == "Frame"
            else schemas.Tracks(site="s", time_ns=1))
    received: list[Any] = []
    stats = bus.BusStats(log_every_s=3600)
    raw = publisher.declare_publisher(key)
    with bus.subscribe(subscriber, key, codec, received.append, stats=stats), \
            bus.Publication(publisher, key, codec) as pub:
        assert pub.wait_for_subscribers(5.0)
        for payload, attachment in garbage:
            raw.put(payload, attachment=attachment)
        pub.put(good)
        assert wait_for(lambda: stats.snapshot()["received"] == len(garbage) + 1)
    raw.undeclare()
    snapshot = stats.snapshot()
    assert snapshot["handler_errors"] == 0 and "decoder_error" not in snapshot["rejected"]
    assert sum(snapshot["rejected"].values()) + snapshot["decoded"] == len(garbage) + 1
    assert received[-1] == good if codec_name != "Frame" else received[-1].header == good.header


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(offsets_s=st.lists(st.one_of(st.sampled_from([-1e9, -3600.0, 0.0, 1.0, 60.0, 1e9]),
                                    st.floats(-1e6, 1e6).filter(lambda o: not 2.0 < o < 8.0)), min_size=1, max_size=8))
def test_a_subscription_refuses_far_future_ticks_and_delivers_the_rest(sessions, offsets_s: list[float]) -> None:
    """Ticks from 1970 to 2262 over a real session: those beyond this host's clock plus the
    window (5 s) are counted as future_time, every other one is delivered, in order. Offsets
    close to the edge are left out: the receiver's clock moves on while they travel."""
    publisher, subscriber = sessions
    key = f"bevflow/fuzz/times/{threading.get_ident()}/{id(offsets_s)}"
    codec = CODECS["Tracks"]
    received: list[Any] = []
    stats = bus.BusStats(log_every_s=3600)
    now = time.time_ns()
    ticks = [(min(max(0, now + int(offset * 1e9)), 2**63 - 1), offset <= 2.0) for offset in offsets_s]
    with bus.subscribe(subscriber, key, codec, received.append, stats=stats, window=WINDOW), \
            bus.Publication(publisher, key, codec) as pub:
        assert pub.wait_for_subscribers(5.0)
        for t, _ in ticks:
            pub.put(schemas.Tracks(site="s", time_ns=t))
        assert wait_for(lambda: stats.snapshot()["received"] == len(ticks))
    assert [m.time_ns for m in received] == [t for t, live in ticks if live]
    assert stats.snapshot()["rejected"].get("future_time", 0) == sum(not live for _, live in ticks)
