from __future__ import annotations

import asyncio
import math

import pytest

from bevflow_services.benchmarks.gateway import _read_response, measure


@pytest.mark.parametrize(
    ("raw", "status", "left"),
    [
        (b"HTTP/1.1 200 OK\r\ncontent-length: 5\r\n\r\nhelloNEXT", 200, b"NEXT"),
        (b"HTTP/1.1 404 Not Found\r\nContent-Length: 0\r\n\r\nNEXT", 404, b"NEXT"),
        (b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n3\r\nabc\r\n2\r\nde\r\n0\r\n\r\nNEXT", 200, b"NEXT"),
    ],
)
def test_one_response_is_read_exactly(raw: bytes, status: int, left: bytes) -> None:
    async def scenario() -> tuple[int, bytes]:
        reader = asyncio.StreamReader()
        reader.feed_data(raw)
        reader.feed_eof()
        return await _read_response(reader), await reader.read()

    assert asyncio.run(scenario()) == (status, left)


def test_a_short_run_against_a_real_gateway() -> None:
    result = measure(rest_rate=40.0, rest_duration_s=1.0, subscribers=3, fanout_duration_s=1.5, people=5, alert_hz=5.0)
    rest, ws = result["rest"], result["websocket"]
    assert rest["requests"] == 40 and rest["errors"] == 0
    assert 0 < rest["p50_ms"] <= rest["p99_ms"] <= rest["max_ms"]
    # 5 alerts a second start (and the previous one ends): 10 messages a second, to every subscriber.
    assert ws["subscribers"] == 3 and 10 <= ws["alert_messages"] <= 20
    assert ws["undelivered"] == 0 and ws["deliveries"] == 3 * ws["alert_messages"]
    assert ws["deliveries_per_subscriber_min"] == ws["deliveries_per_subscriber_max"] == ws["alert_messages"]
    assert math.isfinite(ws["p99_ms"]) and 0 <= ws["p50_ms"] <= ws["p99_ms"]
