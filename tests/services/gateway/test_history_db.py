"""``DatabaseHistory`` answers like ``InMemoryHistory`` for the same stream, on both backends."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from bevflow.alert_lease import LEASE_S
from bevflow.capture_time import CaptureWindow
from bevflow.schemas import TrackState, Tracks
from bevflow.site import parse_site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.history import EventQuery, InMemoryHistory
from bevflow_services.gateway.history_db import DatabaseHistory, history_store
from bevflow_services.gateway.main import add_arguments
from bevflow_services.recorder.recorder import Recorder
from bevflow_services.runtime import UserError
from bevflow_services.storage import HistoryDatabase, RetentionPolicy
from tests.services.gateway.feed import S, SITE_YAML, T0, FakeClock, occupancy, tracks, violation
from tests.services.storage.databases import damaged_sqlite_history
from tests.services.storage.databases import database_url  # noqa: F401  (a fixture)

MS = 1_000_000


@pytest.fixture
def db(database_url: str):  # noqa: F811
    with HistoryDatabase.open(database_url) as opened:
        yield opened


def random_walks(seed: int = 7, ticks: int = 120, people: int = 12) -> list[Tracks]:
    """People wandering in a 6 m square at 5 Hz, coming and going, so that some come close."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 6, size=(people, 2))
    stream = []
    for k in range(ticks):
        xy = np.clip(xy + rng.normal(0, 0.15, size=xy.shape), 0, 6)
        present = [i for i in range(people) if (k // 30 + i) % 4 != 0]  # a quarter absent at a time
        stream.append(Tracks(site="hall", time_ns=T0 + k * 200 * MS,
                             tracks=[TrackState(id=i + 1, xy=(float(xy[i, 0]), float(xy[i, 1]))) for i in present]))
    return stream


def test_trajectories_and_contacts_match_the_in_memory_history(db: HistoryDatabase) -> None:
    memory = InMemoryHistory(track_period_s=1.0)
    recorder = Recorder(db, track_period_s=1.0, clock=lambda: T0 + 30 * S)
    for tick in random_walks():
        memory.add_tracks(tick)
        recorder.on_tracks(tick)
    recorder.flush()
    stored = DatabaseHistory(db)
    compared = 0
    for track in range(1, 13):
        expected, got = memory.trajectory(track), stored.trajectory(track)
        np.testing.assert_array_equal(got.times_ns, expected.times_ns)
        np.testing.assert_allclose(got.xy, expected.xy, atol=1e-6)  # memory keeps float32
        for limit_m, window in [(1.0, (None, None)), (2.5, (None, None)), (2.0, (T0 + 5 * S, T0 + 15 * S))]:
            want = memory.contacts(track, limit_m, *window)
            have = stored.contacts(track, limit_m, *window)
            assert [(c.track, c.first_ns, c.last_ns, c.duration_s, c.closest_ns) for c in have] == \
                   [(c.track, c.first_ns, c.last_ns, c.duration_s, c.closest_ns) for c in want]
            assert [c.min_distance_m for c in have] == pytest.approx([c.min_distance_m for c in want], abs=1e-5)
            compared += len(want)
    assert compared > 20  # the walk does bring people together
    assert stored.trajectory(99) is None and stored.contacts(99, 2.0) is None


def test_it_reads_occupancy_and_alerts_and_writes_nothing_itself(db: HistoryDatabase) -> None:
    stored = DatabaseHistory(db)
    stored.add_occupancy(occupancy(T0, 3))
    stored.add_event(violation("v1", T0))
    assert stored.occupancy() == [] and stored.events(EventQuery(), 10) == ([], 0)
    recorder = Recorder(db, clock=lambda: T0)
    recorder.on_occupancy(occupancy(T0, 3, gate=2))
    recorder.on_event(violation("v1", T0, zone="gate"))
    recorder.flush()
    (sample,) = stored.occupancy()
    assert (sample.time_ns, sample.total, sample.zones) == (T0, 3, {"gate": 2, "shop": 0})
    assert [e.id for e in stored.events(EventQuery(zone="gate", track=1), 10)[0]] == ["v1"]
    assert stored.acknowledge("v1", "ann", T0 + S).user == "ann"
    assert [a.user for a in stored.acknowledgements("v1")] == ["ann"]
    assert stored.retention_ns == 365 * 86400 * S  # the default, before a recorder saved its own
    db.save_retention(RetentionPolicy(fine_s=3600, occupancy_s=30 * 86400))
    assert stored.retention_ns == 30 * 86400 * S


def test_the_gateway_keeps_history_in_memory_unless_given_a_database(tmp_path: Path) -> None:
    assert isinstance(history_store(None, 60.0), InMemoryHistory)
    store = history_store(str(tmp_path / "h.db"), 60.0)
    assert isinstance(store, DatabaseHistory)
    store.close()
    with pytest.raises(UserError, match="--db: .*use a SQLite file path"):
        history_store("mysql://db/history", 60.0)


def test_the_gateway_has_a_db_option() -> None:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    assert parser.parse_args(["--db", "postgresql://db/h"]).db == "postgresql://db/h"
    assert parser.parse_args([]).db is None


def test_occupancy_without_a_start_is_the_last_day_not_the_whole_database(db: HistoryDatabase) -> None:
    assert DatabaseHistory(db).occupancy() == []
    recorder = Recorder(db, clock=lambda: T0 + 3 * 86400 * S, window=CaptureWindow(past_s=4 * 86400))
    for day in range(3):
        recorder.on_occupancy(occupancy(T0 + day * 86400 * S, day + 1))
    recorder.on_occupancy(occupancy(T0 + 2 * 86400 * S - 10 * S, 9))
    recorder.flush()
    stored = DatabaseHistory(db, open_range_s=86400)
    assert [s.total for s in stored.occupancy()] == [2, 9, 3]  # the range includes both ends
    assert [s.total for s in stored.occupancy(until_ns=T0 + 86400 * S)] == [1, 2]
    assert [s.total for s in stored.occupancy(since_ns=T0)] == [1, 2, 9, 3]


def test_a_restarted_gateway_does_not_serve_forged_alerts_as_active_for_ever(db: HistoryDatabase) -> None:
    """After a flood of forged alerts, /api/alerts?active=true listed 99,120 active alerts, even
    after a gateway restart: nothing ended them."""
    recorder = Recorder(db, clock=lambda: T0)
    for k in range(500):
        recorder.on_event(violation(f"forged-{k}", T0))
    recorder.flush()
    restarted = DatabaseHistory(db, clock=lambda: T0 + int(LEASE_S * S) + S)  # no renewal came
    assert restarted.events(EventQuery(active=True), 10) == ([], 0)
    assert restarted.events(EventQuery(active=False), 10)[1] == 500


def test_a_damaged_database_answers_503_in_one_line_and_the_live_data_goes_on(tmp_path: Path) -> None:
    site = parse_site(SITE_YAML)
    path = damaged_sqlite_history(tmp_path / "history.db")
    state = GatewayState(site, DatabaseHistory(HistoryDatabase.open(str(path))), clock=FakeClock())
    state.apply(tracks(T0, {7: (1.0, 1.0)}))
    with TestClient(create_app(site, state), raise_server_exceptions=False) as client:
        for url in ("/api/tracks/5", "/api/history/occupancy?since=1700000000&step_s=60"):
            response = client.get(url)
            assert response.status_code == 503, (url, response.text)
            assert "is damaged" in response.json()["detail"] and "\n" not in response.json()["detail"]
        assert [t["id"] for t in client.get("/api/tracks").json()["items"]] == [7]
