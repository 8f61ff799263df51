"""The recorder's durability promise, end to end: a real recorder process on a real Zenoh session
(loopback, explicit endpoints), SIGKILLed in the middle of a stream and started again.

This test plays the tracker: it publishes occupancy and tracks ticks at 20 Hz (each tick with
its own capture second, so every stored row is exactly one published tick) and alerts through a
``CachedPublication``, as the tracker does. Alerts start and end before the kill, across it, while
the recorder is down, and after it restarts. Then it checks the database:

- every tick published while a recorder was running is stored, except those published in the
  last second before the kill (the recorder runs with its defaults: a commit every 0.25 s);
- every alert is stored exactly once, in its final state, those published while the recorder
  was down included.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from bevflow.schemas import DistanceViolation, Event, Occupancy, OverCapacity, TrackState, Tracks, ZoneOccupancy

from bevflow_services import bus
from bevflow_services.launcher import free_port
from bevflow_services.storage import EventFilter, HistoryDatabase
from tests.services.storage.databases import database_url  # noqa: F401  (a fixture)

pytestmark = pytest.mark.e2e

S = 1_000_000_000
TICK_S = 0.05
COMMIT_S = 0.25  # the recorder's default
START_TIMEOUT_S = 60.0


@dataclass
class Stream:
    """What the fake tracker published, and when (wall-clock seconds)."""

    session: object
    keys: bus.Keys
    t0_ns: int
    ticks: list[tuple[int, float]] = field(default_factory=list)  # (capture ns, published at)
    events: dict[str, Event] = field(default_factory=dict)  # final state of each alert id
    open_events: list[Event] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.occupancy = bus.Publication(self.session, self.keys.occupancy, bus.JsonCodec(Occupancy))
        self.tracks = bus.Publication(self.session, self.keys.tracks, bus.JsonCodec(Tracks))
        self.alerts = bus.CachedPublication(self.session, self.keys.events, bus.JsonCodec(Event, "Event"))

    def tick(self) -> None:
        k = len(self.ticks)
        t = self.t0_ns + k * S
        self.occupancy.put(Occupancy(site=self.keys.site, time_ns=t, total=k % 50,
                                     zones=[ZoneOccupancy(id="entrance", count=k % 7)]))
        self.tracks.put(Tracks(site=self.keys.site, time_ns=t, tracks=[TrackState(id=1, xy=(k * 0.1, 0.0))]))
        self.ticks.append((t, time.time()))
        if k % 4 == 0:  # an alert starts every fourth tick and ends six ticks later
            kind = DistanceViolation(id=f"v{k}", start_ns=t, zone="entrance", tracks=[1, 2], min_distance_m=1.0, limit_m=2.0) \
                if k % 8 == 0 else OverCapacity(id=f"c{k}", start_ns=t, capacity=10, peak=12)
            self._alert(kind)
            self.open_events.append(kind)
        while self.open_events and (t - self.open_events[0].start_ns) >= 6 * S:
            self._alert(self.open_events.pop(0).model_copy(update={"end_ns": t}))

    def end_all(self) -> None:
        t = self.t0_ns + len(self.ticks) * S
        while self.open_events:
            self._alert(self.open_events.pop(0).model_copy(update={"end_ns": t}))

    def _alert(self, event: Event) -> None:
        self.alerts.put(event)
        self.events[event.id] = event

    def run_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.tick()
            time.sleep(TICK_S)

    def run_until(self, condition, timeout_s: float) -> float:
        """Keep publishing until ``condition()``; returns the wall time it first held."""
        deadline = time.monotonic() + timeout_s
        while not condition():
            assert time.monotonic() < deadline, "the recorder did not come up in time"
            self.tick()
            time.sleep(TICK_S)
        return time.time()


def start_recorder(url: str, endpoint: str, site_id: str, log: Path) -> subprocess.Popen[bytes]:
    argv = [sys.executable, "-m", "bevflow_services.recorder.main", "--site", "example-hall", "--site-id", site_id,
            "--mode", "peer", "--connect", endpoint, "--no-shared-memory", "--db", url]
    with log.open("ab") as out:
        return subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT, start_new_session=True,
                                # The stream's capture times run 20 times faster than the clock.
                                env={**os.environ, "PYTHONUNBUFFERED": "1", "BEVFLOW_CLOCK_FUTURE_S": "3600"})


def recorder_alive(live: bus.LiveServices, process: subprocess.Popen[bytes], log: Path):
    instance = bus.default_instance_id().rsplit("-", 1)[0] + f"-{process.pid}"

    def check() -> bool:
        if process.poll() is not None:
            raise AssertionError(f"the recorder exited with {process.returncode}:\n{log.read_text()[-2000:]}")
        return bus.LiveService("recorder", instance) in live.current()

    return check


def test_a_killed_recorder_loses_at_most_the_last_second_and_no_alert(database_url: str, tmp_path: Path) -> None:  # noqa: F811
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    site_id = f"durability-{os.getpid()}-{time.monotonic_ns() % 10**9}"
    log = tmp_path / "recorder.log"
    session = bus.open_session(bus.BusConfig(listen=(endpoint,), timestamping=True, shared_memory=False))
    keys = bus.Keys(site_id)
    live = bus.LiveServices(session, keys)
    stream = Stream(session, keys, t0_ns=time.time_ns() // S * S)
    first = second = None
    try:
        first = start_recorder(database_url, endpoint, site_id, log)
        up_1 = stream.run_until(recorder_alive(live, first, log), START_TIMEOUT_S)
        stream.run_for(2.5)
        killed_at = time.time()
        os.killpg(first.pid, signal.SIGKILL)
        first.wait()
        stream.run_for(1.0)  # the recorder is down: ticks go nowhere, alerts wait in the cache

        second = start_recorder(database_url, endpoint, site_id, log)
        up_2 = stream.run_until(recorder_alive(live, second, log), START_TIMEOUT_S)
        stream.run_for(1.5)
        stream.end_all()
        time.sleep(4 * COMMIT_S)
        os.killpg(second.pid, signal.SIGTERM)
        assert second.wait(30) == 0, log.read_text()[-2000:]
    finally:
        for process in (first, second):
            if process is not None and process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
        live.close()
        stream.alerts.close()
        session.close()

    with HistoryDatabase.open(database_url) as db:
        stored_ticks = {p.time_ns for p in db.occupancy()}
        stored_points = {int(t) for t in db.trajectory(1)[0]}
        events, total = db.events(EventFilter(), limit=10_000)
        counts = db.row_counts()

    recording = [(t, at) for t, at in stream.ticks if up_1 <= at <= killed_at or at >= up_2]
    lost = [(t, at) for t, at in recording if t not in stored_ticks]
    lost_points = [(t, at) for t, at in recording if t not in stored_points]
    down = [e for e in stream.events.values() if killed_at < _published_at(stream, e) < up_2]
    kind = "postgresql" if database_url.startswith("postgresql") else "sqlite"
    print(f"\n[{kind}] ticks published while a recorder ran: {len(recording)}, while none did: "
          f"{len(stream.ticks) - len(recording)}; lost at the kill: {len(lost)} occupancy, {len(lost_points)} positions "
          f"(published at most {max([killed_at - at for _, at in lost + lost_points], default=0.0):.2f} s before it); "
          f"alerts: {len(stream.events)} published ({len(down)} of them ended or raised while no recorder ran), "
          f"{total} stored")

    assert all(killed_at - 1.0 < at <= killed_at for _, at in lost + lost_points), "lost more than the last second"
    assert not [t for t, at in recording if at >= up_2 and t not in stored_ticks], "lost ticks after the restart"
    assert counts["occupancy"] == 2 * len(stored_ticks)  # the site total and one zone per stored tick
    # Every alert exactly once, in its final state, those raised or ended while the recorder was down included.
    assert total == len(events) == len(stream.events) == counts["events"]
    assert {e.id: e for e in events} == stream.events
    assert down, "the stream had no alert while the recorder was down: the test proves nothing"


def _published_at(stream: Stream, event: Event) -> float:
    """Wall time of the tick that published this alert's final state."""
    t = event.end_ns if event.end_ns is not None else event.start_ns
    return next((at for tick, at in stream.ticks if tick == t), float("inf"))
