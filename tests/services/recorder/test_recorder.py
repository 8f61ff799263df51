"""``Recorder`` without a bus: messages in, rows out, and what happens when the database is down."""

from __future__ import annotations

from pathlib import Path

import pytest

from bevflow.alert_lease import BURST, LEASE_S
from bevflow.schemas import OpenAlerts

from bevflow_services.recorder.recorder import Recorder
from bevflow_services.storage import Batch, EventFilter, HistoryDatabase, StorageUnavailable
from tests.services.gateway.feed import S, T0, occupancy, tracks, violation

MS = 1_000_000
NOW = T0 + 99 * S  # the recorder's clock: the feed's capture times are live


def now() -> int:
    return NOW


@pytest.fixture
def db(tmp_path: Path):
    with HistoryDatabase.open(str(tmp_path / "h.db")) as opened:
        yield opened


class FlakyDatabase:
    """A database whose next ``failures`` writes fail as an unreachable server's would."""

    def __init__(self, db: HistoryDatabase, failures: int) -> None:
        self.db, self.failures = db, failures

    def write(self, batch: Batch, recorded_ns: int | None = None) -> None:
        if self.failures > 0:
            self.failures -= 1
            raise StorageUnavailable("database: connection refused")
        self.db.write(batch, recorded_ns)

    def __getattr__(self, name: str):
        return getattr(self.db, name)


def test_a_flush_writes_what_arrived_since_the_last_one(db: HistoryDatabase) -> None:
    recorder = Recorder(db, clock=now)
    recorder.on_occupancy(occupancy(T0, 3, gate=1))
    recorder.on_occupancy(occupancy(T0 + 500 * MS, 5, gate=0))
    recorder.on_event(violation("v1", T0))
    for t_ms in (0, 100, 1000, 1900, 2000):
        recorder.on_tracks(tracks(T0 + t_ms * MS, {1: (t_ms / 1000, 0.0)}))
    assert recorder.pending() == 1 * 3 + 1 + 3  # occupancy rows (site, gate, shop), alert, positions
    assert recorder.flush() == 7 and recorder.pending() == 0 and recorder.flush() == 0
    assert [(p.total, p.zones["gate"]) for p in db.occupancy()] == [(5, 1)]
    assert ((db.trajectory(1)[0] - T0) // MS).tolist() == [0, 1000, 2000]
    assert db.events(EventFilter(), 10)[0][0].id == "v1"
    (recorded,), = db.backend.query("SELECT recorded_ns FROM events")
    assert recorded == T0 + 99 * S


def test_a_failed_flush_keeps_its_rows_for_the_next_one(db: HistoryDatabase) -> None:
    recorder = Recorder(FlakyDatabase(db, failures=2), clock=now)  # type: ignore[arg-type]
    recorder.on_occupancy(occupancy(T0, 3))
    recorder.on_event(violation("v1", T0))
    for _ in range(2):
        with pytest.raises(StorageUnavailable):
            recorder.flush()
    recorder.on_occupancy(occupancy(T0 + 200 * MS, 2))  # arrives while the database is down
    recorder.on_event(violation("v1", T0, end_ns=T0 + S))
    recorder.flush()
    assert [p.total for p in db.occupancy()] == [3]
    assert db.event("v1").end_ns == T0 + S
    assert recorder.counts["failed_flushes"] == 2 and recorder.counts["flushes"] == 1


def test_a_long_outage_drops_the_oldest_samples_but_never_an_alert(db: HistoryDatabase) -> None:
    recorder = Recorder(FlakyDatabase(db, failures=10), max_pending_rows=6, clock=now)  # type: ignore[arg-type]
    for k in range(10):
        recorder.on_occupancy(occupancy(T0 + k * S, k))
        recorder.on_event(violation(f"v{k}", T0 + k * S))
        with pytest.raises(StorageUnavailable):
            recorder.flush()
    recorder.flush()
    assert [p.total for p in db.occupancy()] == [8, 9]  # six rows: the last two seconds
    assert db.events(EventFilter(), 100)[1] == 10
    assert recorder.counts["dropped_rows"] == 10 * 3 - 6


def test_a_restarted_recorder_resumes_sampling_after_the_stored_positions(db: HistoryDatabase) -> None:
    first = Recorder(db, clock=now)
    first.on_tracks(tracks(T0 + 100 * MS, {1: (0.0, 0.0)}))
    first.flush()
    second = Recorder(db, clock=now)  # killed and started again within the same second
    second.on_tracks(tracks(T0 + 600 * MS, {1: (1.0, 0.0)}))
    second.on_tracks(tracks(T0 + 1100 * MS, {1: (2.0, 0.0)}))
    second.flush()
    assert ((db.trajectory(1)[0] - T0) // MS).tolist() == [100, 1100]


def test_a_stored_position_beyond_the_clock_does_not_stop_recording(db: HistoryDatabase) -> None:
    """A forged tick at 2**63 - 1 ns, stored before the bus refused such times, used to make every
    restarted recorder resume sampling after it: no position was ever stored again."""
    forged = Batch()
    forged.add_track_sample(tracks(2**63 - 1, {666: (0.0, 0.0)}))
    db.write(forged)
    recorder = Recorder(db, clock=now)
    recorder.on_tracks(tracks(T0, {1: (1.0, 0.0)}))
    recorder.flush()
    assert (db.trajectory(1)[0] == [T0]).all()


@pytest.mark.parametrize(
    ("time_ns", "stored"),
    [
        (NOW + 4 * S, True),  # the bus refuses what lies further ahead (tests/services/test_bus.py)
        (NOW - 3600 * S + S, True),
        (NOW - 3600 * S - S, False),  # older than the live hour
        (0, False),
    ],
)
def test_capture_times_older_than_the_live_window_are_counted_not_stored(db: HistoryDatabase, time_ns: int,
                                                                 stored: bool) -> None:
    recorder = Recorder(db, clock=now)
    recorder.on_tracks(tracks(time_ns, {1: (1.0, 0.0)}))
    recorder.on_occupancy(occupancy(time_ns, 3))
    assert recorder.pending() == (1 + 3 if stored else 0)
    assert recorder.counts["outside_window"] == (0 if stored else 2)


def test_a_flood_of_alerts_is_refused_beyond_the_rate_and_what_got_in_ends_by_itself(db: HistoryDatabase) -> None:
    """10,000 forged alerts a second for 10 s used to be stored, all active for ever."""
    clock = [NOW]
    recorder = Recorder(db, clock=lambda: clock[0])
    for second in range(10):
        clock[0] = NOW + second * S
        for k in range(10_000):
            recorder.on_event(violation(f"forged-{second}-{k}", T0))
    clock[0] = NOW + 10 * S
    recorder.on_event(violation("real", T0))  # the rate refills: a real alert after the flood gets in
    recorder.flush()
    stored = db.row_counts()["events"]
    assert stored <= BURST + 11 * 100 and recorder.counts["events_refused"] == 100_001 - stored
    recorder.on_open_alerts(OpenAlerts(site="hall", time_ns=T0, ids=["real"]))
    clock[0] += int(LEASE_S * S)
    recorder.flush()  # the renewal is written at the recorder's clock
    clock[0] += 2 * S
    assert recorder.end_lapsed_alerts() == stored - 1
    assert [e.id for e in db.events(EventFilter(active=True), 10)[0]] == ["real"]


def test_messages_naming_a_zone_the_site_does_not_have_are_not_stored(db: HistoryDatabase) -> None:
    recorder = Recorder(db, clock=now, zones=frozenset({"gate", "shop"}))
    recorder.on_tracks(tracks(T0, {1: (0.0, 0.0)}, zones={1: ["\rforged"]}))
    recorder.on_occupancy(occupancy(T0, 1).model_copy(update={"zones": []}))  # the site total alone is fine
    recorder.on_event(violation("v1", T0).model_copy(update={"zone": "|forged"}))
    assert recorder.counts["unknown_zones"] == 2 and recorder.pending() == 1
