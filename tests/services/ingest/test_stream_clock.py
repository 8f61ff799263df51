"""Capture times from stream timestamps: the camera's spacing, never later than arrival, re-anchored
when the stream's clock drifts or jumps."""

from __future__ import annotations

import logging

import pytest

from bevflow_services.ingest.stream_clock import StreamClock

MS = 1_000_000
LIVE, FILE = True, False


@pytest.mark.parametrize(
    ("follow_arrivals", "frames", "stamps", "reanchors"),
    [
        # (stream time ms or None, arrival ms) per frame; the stamps expected, in ms.
        pytest.param(LIVE, [(0, 1000), (40, 1050), (80, 1075), (120, 1130)], [1000, 1040, 1075, 1115], 0,
                     id="jittery arrivals keep the camera's spacing, anchored by the quickest frame"),
        pytest.param(LIVE, [(0, 500), (40, 500), (80, 500), (120, 520)], [500, 500, 500, 520], 0,
                     id="frames buffered while the stream opened are not stamped after they arrived"),
        pytest.param(FILE, [(0, 1000), (40, 1001), (80, 1002)], [1000, 1040, 1080], 0,
                     id="a file decoded ahead of time keeps its anchor (the reader waits for each stamp)"),
        pytest.param(LIVE, [(0, 0), (1000, 1000), (2000, 4500)], [0, 1000, 4500], 1,
                     id="a stream clock 2.5 s behind the wall clock is re-anchored"),
        pytest.param(LIVE, [(0, 0), (1000, 1000), (2000, 3900)], [0, 1000, 2000], 0,
                     id="1.9 s behind is within the bound"),
        pytest.param(LIVE, [(0, 0), (40, 40), (0, 80)], [0, 40, 80], 1,
                     id="timestamps going backwards re-anchor"),
        pytest.param(LIVE, [(0, 0), (3_600_000, 40), (3_600_040, 80)], [0, 40, 80], 1,
                     id="timestamps jumping an hour ahead re-anchor"),
        pytest.param(LIVE, [(None, 10), (None, 50)], [10, 50], 0,
                     id="a stream without timestamps is stamped on arrival"),
    ],
)
def test_capture_times_follow_the_stream_clock(follow_arrivals, frames, stamps, reanchors) -> None:
    clock = StreamClock("cam", follow_arrivals=follow_arrivals)
    got = [clock.stamp(None if pts is None else pts * MS, now * MS) for pts, now in frames]
    assert got == [s * MS for s in stamps]
    assert all(isinstance(s, int) for s in got)
    assert clock.reanchors == reanchors


def test_re_anchoring_is_logged_once(caplog: pytest.LogCaptureFixture) -> None:
    clock = StreamClock("rtsp://cam/stream1")
    with caplog.at_level(logging.WARNING):
        for pts, now in [(0, 0), (40, 40), (0, 80), (40, 120), (0, 160)]:
            clock.stamp(pts * MS, now * MS)
    assert clock.reanchors == 2
    assert len(caplog.records) == 1 and "rtsp://cam/stream1" in caplog.text and "backwards" in caplog.text
