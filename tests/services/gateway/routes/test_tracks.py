from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from bevflow_services.gateway.state import GatewayState
from tests.services.gateway.feed import S, T0, tracks


def _walk(state: GatewayState) -> None:
    """Track 2 walks along x towards track 1 and stops 0.5 m from it; track 3 stays far away."""
    for k in range(6):
        people = {1: (0.0, 0.0), 2: (max(0.5, 5.0 - k), 0.0), 3: (20.0, 3.0)}
        near = [(1, 2)] if k >= 4 else []
        state.apply(tracks(T0 + k * S, people, near, zones={1: ["gate"], 2: ["gate"] if k >= 2 else []}))


def test_tracks_now_lists_the_latest_tick_by_id(client: TestClient, state: GatewayState) -> None:
    _walk(state)
    body = client.get("/api/tracks").json()
    assert [t["id"] for t in body["items"]] == [1, 2, 3]
    assert body["items"][1]["xy"] == [0.5, 0.0]
    assert (body["total"], body["time_ns"], body["violations"]) == (3, T0 + 5 * S, [[1, 2]])


@pytest.mark.parametrize(
    ("query", "ids", "total"),
    [("zone=gate", [1, 2], 2), ("zone=shop", [], 0), ("limit=2", [1, 2], 3), ("limit=2&offset=2", [3], 3), ("offset=5", [], 3)],
)
def test_tracks_now_filters_and_pages(client: TestClient, state: GatewayState, query: str, ids: list[int], total: int) -> None:
    _walk(state)
    body = client.get(f"/api/tracks?{query}").json()
    assert [t["id"] for t in body["items"]] == ids and body["total"] == total


def test_tracks_before_any_tick(client: TestClient) -> None:
    assert client.get("/api/tracks").json() == {"time_ns": None, "time": None, "items": [], "total": 0, "limit": 100, "offset": 0, "violations": []}


def test_one_track_has_its_state_now_and_its_trajectory(client: TestClient, state: GatewayState) -> None:
    _walk(state)
    body = client.get("/api/tracks/2").json()
    assert (body["id"], body["active"], body["current"]["xy"]) == (2, True, [0.5, 0.0])
    assert [p["xy"][0] for p in body["points"]] == [5.0, 4.0, 3.0, 2.0, 1.0, 0.5]
    assert [p["time_ns"] for p in body["points"]] == [T0 + k * S for k in range(6)]
    recent = client.get("/api/tracks/2?last_s=1").json()
    assert [p["xy"][0] for p in recent["points"]] == [1.0, 0.5]


def test_a_track_that_left_keeps_its_trajectory(client: TestClient, state: GatewayState) -> None:
    _walk(state)
    state.apply(tracks(T0 + 6 * S, {1: (0.0, 0.0)}))
    body = client.get("/api/tracks/3").json()
    assert (body["active"], body["current"], len(body["points"])) == (False, None, 6)


def test_contacts_of_a_track(client: TestClient, state: GatewayState) -> None:
    _walk(state)
    body = client.get("/api/tracks/1/contacts?min_duration_s=0").json()
    assert (body["track"], body["limit_m"]) == (1, 2.0)  # the site's social distance by default
    # Track 2 is closer than 2 m from k = 4 (1.0 m) on; held until the next sample, so 1 s of contact.
    assert [(c["track"], (c["first_ns"] - T0) // S, c["min_distance_m"], c["duration_s"]) for c in body["contacts"]] == [(2, 4, 0.5, 1.0)]


@pytest.mark.parametrize(
    ("query", "tracks_in_contact"),
    [("distance_m=3.5&min_duration_s=0", [2]), ("distance_m=30&min_duration_s=0", [2, 3]), ("distance_m=0.4&min_duration_s=0", []),
     ("min_duration_s=2", []), ("", []), ("until=1700000003&min_duration_s=0", [])],  # default: the site's 2 s minimum
)
def test_contacts_filters(client: TestClient, state: GatewayState, query: str, tracks_in_contact: list[int]) -> None:
    _walk(state)
    body = client.get(f"/api/tracks/1/contacts?{query}").json()
    assert [c["track"] for c in body["contacts"]] == tracks_in_contact


@pytest.mark.parametrize("path", ["/api/tracks/42", "/api/tracks/42/contacts"])
def test_an_unknown_track_is_404_naming_it(client: TestClient, state: GatewayState, path: str) -> None:
    _walk(state)
    response = client.get(path)
    assert response.status_code == 404
    assert "track 42" in response.json()["detail"]


def test_contacts_join_the_fragments_of_one_person_found_again_under_a_new_id(client: TestClient, state: GatewayState) -> None:
    """Person 5 stands 1 m from track 1 for 4 s, is lost, and comes back as 6 at the same place."""
    for k in range(10):
        people = {1: (0.0, 0.0), **({5: (1.0, 0.0)} if k < 4 else {6: (1.1, 0.1)} if k > 4 else {})}
        state.apply(tracks(T0 + k * S, people))
    merged = client.get("/api/tracks/1/contacts").json()["contacts"]
    assert [(c["track"], c["tracks"], c["duration_s"]) for c in merged] == [(5, [5, 6], 8.0)]
    apart = client.get("/api/tracks/1/contacts?merge=false").json()["contacts"]
    assert [(c["track"], c["duration_s"]) for c in apart] == [(5, 4.0), (6, 4.0)]


def test_polling_where_everyone_is_is_audited_once_per_spell(site, state: GatewayState) -> None:
    from bevflow.units import NS_PER_S
    from tests.services.gateway.access import bearer, secured_client

    now = [T0]
    with secured_client(site, state) as (client, secure):
        secure.access.clock = lambda: now[0]
        polls = [("viewer", 0), ("viewer", 1), ("viewer", 590), ("operator", 591), ("viewer", 1200), ("viewer", 1790)]
        for role, at_s in polls:
            now[0] = T0 + at_s * NS_PER_S
            assert client.get("/api/tracks", headers=bearer(secure.tokens[role])).status_code == 200
        rows, _ = secure.access.store.audit_log(limit=50)  # newest first
    # A poll within ten minutes of the viewer's own last one continues its spell: 590 s (589 s
    # after 1 s) and 1790 s do; 1200 s comes 610 s after the viewer's poll at 590 s, though only
    # 609 s after someone else's.
    assert [(e.user, e.action, (e.time_ns - T0) // NS_PER_S) for e in reversed(rows)] == [
        ("viewer", "live_tracks", 0), ("operator", "live_tracks", 591), ("viewer", "live_tracks", 1200)]
