"""``/api/history``: the same requests against the in-memory history and the history database
(SQLite and PostgreSQL, written by the recorder as in production)."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from bevflow.capture_time import CaptureWindow
from bevflow.schemas import Occupancy, Tracks
from bevflow.site import Site

from bevflow_services.gateway import GatewayState, create_app
from bevflow_services.gateway.history import HistoryStore, InMemoryHistory
from bevflow_services.gateway.history_db import DatabaseHistory
from bevflow_services.gateway.routes.history import _cell
from bevflow_services.recorder.recorder import Recorder
from bevflow_services.storage import Batch, HistoryDatabase
from tests.services.gateway.feed import S, T0, FakeClock, occupancy, over_capacity, tracks, violation
from tests.services.storage.databases import new_database_url

MIN = 60 * S
B = (T0 // MIN + 1) * MIN  # 2023-11-14T22:14:00Z, on a minute


@dataclass
class History:
    """A gateway over one kind of history, and a way to feed it as the live system would."""

    kind: str
    state: GatewayState
    client: TestClient
    recorder: Recorder | None

    def feed(self, *messages: object) -> None:
        for message in messages:
            self.state.apply(message)  # type: ignore[arg-type]
            if self.recorder is not None:
                if isinstance(message, Occupancy):
                    self.recorder.on_occupancy(message)
                elif isinstance(message, Tracks):
                    self.recorder.on_tracks(message)
                else:
                    self.recorder.on_event(message)  # type: ignore[arg-type]
        if self.recorder is not None:
            self.recorder.flush()


@contextmanager
def gateway_over(kind: str, site: Site, clock: FakeClock, folder: Path) -> Iterator[History]:
    """A gateway whose history is in memory (``kind`` "memory") or in a new database of ``kind``."""
    db = recorder = None
    store: HistoryStore = InMemoryHistory(retention_s=7 * 86400)
    if kind != "memory":
        db = HistoryDatabase.open(new_database_url(kind, folder))
        # The feeds' capture times run ahead of the test clock, which stands still.
        ahead = CaptureWindow(future_s=30 * 86400)
        store, recorder = DatabaseHistory(db, clock=clock, window=ahead), Recorder(db, clock=clock)
    state = GatewayState(site, store, clock=clock)
    try:
        with TestClient(create_app(site, state)) as client:
            yield History(kind, state, client, recorder)
    finally:
        if db is not None:
            db.close()


@pytest.fixture(params=["memory", "sqlite", "postgresql"])
def history(request: pytest.FixtureRequest, site: Site, clock: FakeClock, tmp_path: Path) -> Iterator[History]:
    with gateway_over(request.param, site, clock, tmp_path) as gateway:
        yield gateway


@pytest.fixture(params=["sqlite", "postgresql"])
def database(request: pytest.FixtureRequest, site: Site, clock: FakeClock, tmp_path: Path) -> Iterator[History]:
    with gateway_over(request.param, site, clock, tmp_path) as gateway:
        yield gateway


def rows(response) -> list[dict[str, str]]:
    assert response.status_code == 200, response.text
    assert response.headers["content-type"].startswith("text/csv")
    return list(csv.DictReader(io.StringIO(response.text)))


# --- occupancy -----------------------------------------------------------------------------------
def feed_occupancy(history: History) -> None:
    """Ten minutes from B, one tick a second: total is the minute number, gate the second's parity."""
    history.feed(*[occupancy(B + k * S, total=k // 60, gate=k % 2, shop=k // 120) for k in range(600)])


@pytest.mark.parametrize(
    ("query", "times_min", "totals", "total_rows"),
    [
        ("step_s=60", list(range(10)), list(range(10)), 10),
        ("step_s=120&limit=2&offset=1", [2, 4], [3, 5], 5),
        ("step_s=60&since=2023-11-14T22:15:00Z&until=2023-11-14T22:16:59Z", [1, 2], [1, 2], 2),
        ("step_s=3600", [-14], [9], 1),  # steps start on multiples of step_s since the epoch
    ],
)
def test_occupancy_rows_are_the_highest_counts_per_step(history: History, query, times_min, totals, total_rows) -> None:
    feed_occupancy(history)
    body = history.client.get(f"/api/history/occupancy?{query}").json()
    assert [(r["time_ns"] - B) // MIN for r in body["items"]] == times_min
    assert [r["total"] for r in body["items"]] == totals
    assert body["total"] == total_rows and body["step_s"] == int(query.split("&")[0].split("=")[1])
    assert all(r["zones"]["gate"] == 1 and set(r["zones"]) == {"gate", "shop"} for r in body["items"])


def test_occupancy_as_csv_has_the_same_rows(history: History) -> None:
    feed_occupancy(history)
    response = history.client.get("/api/history/occupancy?step_s=300&zone=shop&format=csv")
    assert response.headers["x-total-count"] == "3"
    assert 'filename="occupancy.csv"' in response.headers["content-disposition"]
    assert rows(response) == [  # B is 4 min past a multiple of 5 min
        {"time": "2023-11-14T22:10:00.000Z", "time_ns": str(1699999800 * S), "total": "0", "shop": "0"},
        {"time": "2023-11-14T22:15:00.000Z", "time_ns": str(1700000100 * S), "total": "5", "shop": "2"},
        {"time": "2023-11-14T22:20:00.000Z", "time_ns": str(1700000400 * S), "total": "9", "shop": "4"},
    ]


@pytest.mark.parametrize(
    ("query", "status", "message"),
    [
        ("zone=lobby", 404, "unknown zone 'lobby'"),
        ("since=2023-11-15&until=2023-11-14", 400, "is after until"),
        ("step_s=0", 422, "step_s"),
        ("format=xml", 422, "format"),
        ("limit=100001", 422, "limit"),
    ],
)
def test_bad_occupancy_requests_name_the_parameter(history: History, query, status, message) -> None:
    response = history.client.get(f"/api/history/occupancy?{query}")
    assert response.status_code == status
    assert message in response.text


# --- alerts --------------------------------------------------------------------------------------
def feed_alerts(history: History) -> None:
    history.feed(violation("v1", T0, pair=(1, 2), zone="gate"),
                 violation("v1", T0, pair=(1, 2), zone="gate", end_ns=T0 + 4 * S),
                 violation("v2", T0 + 10 * S, pair=(3, 4), zone="shop"),
                 over_capacity("c1", T0 + 20 * S, zone="gate", end_ns=T0 + 95 * S),
                 violation("v3", T0 + 40 * S, pair=(1, 5), zone=None))


@pytest.mark.parametrize(
    ("query", "ids"),
    [
        ("", ["v3", "c1", "v2", "v1"]),
        ("types=over_capacity", ["c1"]),
        ("zone=gate", ["c1", "v1"]),
        ("track=1", ["v3", "v1"]),
        ("active=false", ["c1", "v1"]),
        ("since=1700000005&until=1700000015", ["v2"]),
        ("limit=2&offset=1", ["c1", "v2"]),
    ],
)
def test_alerts_in_a_range_with_their_durations(history: History, query: str, ids: list[str]) -> None:
    feed_alerts(history)
    body = history.client.get(f"/api/history/events?{query}").json()
    assert [e["id"] for e in body["items"]] == ids
    expected = {"v1": 4.0, "c1": 75.0, "v2": None, "v3": None}
    assert {e["id"]: e["duration_s"] for e in body["items"]} == {i: expected[i] for i in ids}


@pytest.mark.parametrize(
    ("value", "cell"),
    [
        ("=1+2", "'=1+2"),
        ("+cmd", "'+cmd"),
        ("-2+3", "'-2+3"),
        ("@SUM(A1)", "'@SUM(A1)"),
        ("|calc", "'|calc"),
        ("\t=1", "'\ufffd=1"),
        ("\r=1", "'\ufffd=1"),
        ("a\rb\x00c\x1b", "a\ufffdb\ufffdc\ufffd"),
        ("-1.5", "-1.5"),  # a number stays one
        ("+2e3", "+2e3"),
        ("v1", "v1"),
        (3, 3),
        (None, ""),
    ],
)
def test_csv_cells_are_never_formulas_nor_hide_control_characters(value: object, cell: object) -> None:
    assert _cell(value) == cell


def test_an_alert_id_from_the_bus_cannot_break_a_csv_row(history: History) -> None:
    forged = ["\r=cmd|' /C calc'!A0", "|calc", "\tx"]
    history.feed(*[violation(name, T0) for name in forged])
    response = history.client.get("/api/history/events?format=csv&types=distance_violation")
    assert "\r" not in response.text and "\t" not in response.text
    assert {r["id"] for r in rows(response)} == {"'\ufffd=cmd|' /C calc'!A0", "'\ufffdx", "'|calc"}


def test_alerts_as_csv(history: History) -> None:
    feed_alerts(history)
    table = rows(history.client.get("/api/history/events?format=csv&types=distance_violation,over_capacity"))
    assert [r["id"] for r in table] == ["v3", "c1", "v2", "v1"]
    c1, v1 = table[1], table[3]
    assert (c1["zone"], c1["duration_s"], c1["peak"], c1["capacity"], c1["active"]) == ("gate", "75.0", "5", "3", "False")
    assert (v1["start"], v1["end"], v1["tracks"], v1["min_distance_m"]) == (
        "2023-11-14T22:13:20.000Z", "2023-11-14T22:13:24.000Z", "1 2", "1.2")
    assert table[0]["zone"] == "" and table[0]["end"] == "" and table[0]["duration_s"] == ""


def test_alert_types_are_checked(history: History) -> None:
    response = history.client.get("/api/history/events?types=fire")
    assert response.status_code == 400 and "types: unknown value(s) fire" in response.text


# --- tracks --------------------------------------------------------------------------------------
def feed_tracks(history: History) -> None:
    for k in range(6):
        people = {1: (0.5, 0.5), 2: (7.0, 1.0)} if k < 3 else {2: (7.0, 1.0), 3: (2.0, 2.0)}
        history.feed(tracks(T0 + k * S, people, zones={1: ["gate"], 2: ["shop"], 3: ["gate"]}))


def test_track_summaries_need_the_database(client: TestClient) -> None:
    response = client.get("/api/history/tracks")  # the in-memory history
    assert response.status_code == 404 and "--db" in response.text


@pytest.mark.parametrize(
    ("query", "ids"),
    [
        ("", [3, 2, 1]),
        ("zone=gate", [3, 1]),
        ("since=1700000004", [3, 2]),
        ("until=1700000001", [2, 1]),
        ("limit=1&offset=1", [2]),
    ],
)
def test_track_summaries(database: History, query: str, ids: list[int]) -> None:
    feed_tracks(database)
    body = database.client.get(f"/api/history/tracks?{query}").json()
    assert [t["id"] for t in body["items"]] == ids


def test_rows_a_forged_far_future_tick_stored_do_not_head_the_history(database: History) -> None:
    """A year-2262 row, stored before the bus refused such times, used to stay at the top of
    /api/history/tracks and the alert list."""
    feed_tracks(database)
    forged = Batch()
    forged.add_track_sample(tracks(2**63 - 1, {666: (1.0, 1.0)}))
    forged.add_event(violation("forged", 2**63 - 1))
    assert isinstance(database.state.history, DatabaseHistory)
    database.state.history.db.write(forged)
    assert [t["id"] for t in database.client.get("/api/history/tracks").json()["items"]] == [3, 2, 1]
    assert "forged" not in {a["id"] for a in database.client.get("/api/alerts").json()["items"]}


def test_a_track_summary_says_when_and_where(database: History) -> None:
    feed_tracks(database)
    (two,) = [t for t in database.client.get("/api/history/tracks").json()["items"] if t["id"] == 2]
    assert (two["first_ns"], two["last_ns"], two["duration_s"], two["points"]) == (T0, T0 + 5 * S, 5.0, 6)
    assert [(z["zone"], z["first"], z["last"]) for z in two["zones"]] == [
        ("shop", "2023-11-14T22:13:20.000Z", "2023-11-14T22:13:25.000Z")]
    table = rows(database.client.get("/api/history/tracks?format=csv"))
    assert [(r["id"], r["points"], r["zones"]) for r in table] == [("3", "3", "gate"), ("2", "6", "shop"), ("1", "3", "gate")]


def test_the_track_routes_read_trajectories_and_contacts_from_the_database(database: History) -> None:
    feed_tracks(database)
    path = database.client.get("/api/tracks/1").json()
    assert [p["xy"] for p in path["points"]] == [[0.5, 0.5]] * 3
    contacts = database.client.get("/api/tracks/3/contacts?distance_m=2").json()["contacts"]
    assert contacts == []
    contacts = database.client.get("/api/tracks/1/contacts?distance_m=7").json()["contacts"]
    assert [(c["track"], c["duration_s"], c["min_distance_m"]) for c in contacts] == [(2, 2.0, pytest.approx(6.519, abs=1e-3))]
