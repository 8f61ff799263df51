"""Work a service repeats on a thread of its own: it goes on after a failure and stops with the block."""

from __future__ import annotations

import threading
import time

from bevflow_services.runtime import periodically


def test_a_repeated_chore_survives_its_failures_and_stops_with_the_block(caplog) -> None:
    calls: list[float] = []
    three = threading.Event()

    def chore() -> None:
        calls.append(time.monotonic())
        if len(calls) == 3:
            three.set()
        if len(calls) == 1:
            raise RuntimeError("the first call fails")

    with periodically(0.01, chore, "chore"):
        assert three.wait(5.0), f"only {len(calls)} calls in 5 s"
    made = len(calls)
    time.sleep(0.05)  # the thread is joined when the block ends: no call comes after it
    assert len(calls) == made >= 3
    assert "chore failed; trying again in 0.01 s" in caplog.text
