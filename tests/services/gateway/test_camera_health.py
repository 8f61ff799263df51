from __future__ import annotations

import pytest

from bevflow.schemas import CameraHealthEvent

from bevflow_services.gateway.camera_health import CameraHealthBook

S = 1_000_000_000


@pytest.mark.parametrize(
    ("seqs", "received", "dropped", "last_seq"),
    [
        ([], 0, 0, None),
        ([0, 1, 2, 3], 4, 0, 3),
        ([0, 1, 5, 6], 4, 3, 6),  # frames 2, 3, 4 never arrived
        ([0, 0, 1, 1, 2], 3, 0, 2),  # the same frame twice (detections and cylinders) counts once
        ([10, 11, 0, 1, 3], 5, 1, 3),  # the ingest worker restarted at 0: no huge gap
    ],
)
def test_frames_received_and_dropped_come_from_sequence_numbers(seqs, received, dropped, last_seq) -> None:
    book = CameraHealthBook(["a"])
    for k, seq in enumerate(seqs):
        assert book.record_frame("a", seq, capture_ns=k * S, received_ns=k * S)
    health = book.health("a", now_ns=len(seqs) * S)
    assert (health.received, health.dropped, health.last_seq) == (received, dropped, last_seq)


@pytest.mark.parametrize(
    ("last_message_s", "now_s", "state", "reason"),
    [
        (None, 10.0, "unknown", "no message yet"),
        (8.0, 10.0, "up", ""),
        (5.0, 10.0, "up", ""),  # exactly the timeout: still up
        (4.0, 10.0, "down", "no message for 6.0 s"),
    ],
)
def test_a_camera_is_down_after_a_silence_longer_than_the_timeout(last_message_s, now_s, state, reason) -> None:
    book = CameraHealthBook(["a"], timeout_s=5.0)
    if last_message_s is not None:
        book.record_frame("a", 0, capture_ns=0, received_ns=int(last_message_s * S))
    health = book.health("a", now_ns=int(now_s * S))
    assert (health.state, health.reason) == (state, reason)


def test_a_down_event_holds_until_the_camera_is_reported_up() -> None:
    book = CameraHealthBook(["a"], timeout_s=5.0)
    book.record_frame("a", 0, capture_ns=0, received_ns=0)
    assert book.record_event(CameraHealthEvent(id="d1", type="camera_down", camera="a", start_ns=0, reason="stream lost"))
    assert (book.health("a", 1 * S).state, book.health("a", 1 * S).reason) == ("down", "stream lost")
    book.record_event(CameraHealthEvent(id="u1", type="camera_up", camera="a", start_ns=2 * S))
    assert book.health("a", 2 * S).state == "up"


def test_messages_of_unknown_cameras_are_refused() -> None:
    book = CameraHealthBook(["a"])
    assert not book.record_frame("zzz", 0, 0, 0)
    assert not book.record_event(CameraHealthEvent(id="d", type="camera_down", camera="zzz", start_ns=0))
    assert "zzz" not in book and "a" in book
