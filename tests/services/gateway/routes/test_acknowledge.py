"""Acknowledging alerts on the gateway: stored with who and when (in memory, or in the history
database on either backend), listed with the alerts, and pushed to other dashboards."""

from __future__ import annotations

import pytest

from bevflow.site import Site

from bevflow_services.gateway import GatewayState
from bevflow_services.gateway.history_db import DatabaseHistory
from bevflow_services.storage import Batch, HistoryDatabase
from tests.services.gateway.access import bearer, secured_client
from tests.services.gateway.feed import S, T0, FakeClock, over_capacity, violation
from tests.services.storage.databases import database_url  # noqa: F401  (a fixture)


@pytest.fixture(params=["memory", "sqlite", "postgresql"])
def history_state(request: pytest.FixtureRequest, site: Site, clock: FakeClock, tmp_path) -> GatewayState:
    """A state whose history holds alerts dv-1 (ended) and oc-2 (active), in memory or a database."""
    alerts = [violation("dv-1", T0, end_ns=T0 + 5 * S), over_capacity("oc-2", T0 + S)]
    if request.param == "memory":
        state = GatewayState(site, clock=clock)
        for alert in alerts:
            state.apply(alert)
        return state
    from tests.services.storage.databases import new_database_url

    db = HistoryDatabase.open(new_database_url(request.param, tmp_path))
    request.addfinalizer(db.close)
    batch = Batch()
    for alert in alerts:
        batch.add_event(alert)
    db.write(batch)
    return GatewayState(site, DatabaseHistory(db), clock=clock)


def test_an_operator_acknowledges_and_every_listing_shows_who_and_when(site: Site, history_state: GatewayState,
                                                                       clock: FakeClock) -> None:
    with secured_client(site, history_state) as (client, secure):
        operator = bearer(secure.tokens["operator"])
        clock.advance(30)
        made = client.post("/api/alerts/oc-2/acknowledge", json={"note": "sent staff"}, headers=operator)
        assert made.status_code == 201
        assert made.json() == {"alert_id": "oc-2", "user": "operator", "time": "2023-11-14T22:13:50.000Z",
                               "time_ns": T0 + 30 * S, "note": "sent staff"}
        clock.advance(1)
        assert client.post("/api/alerts/oc-2/acknowledge", headers=bearer(secure.tokens["admin"])).status_code == 201

        viewer = bearer(secure.tokens["viewer"])
        listing = client.get("/api/alerts?types=distance_violation,over_capacity", headers=viewer).json()
        items = {a["id"]: a for a in listing["items"]}
        assert [(a["user"], a["note"]) for a in items["oc-2"]["acknowledgements"]] == [("operator", "sent staff"), ("admin", "")]
        assert items["dv-1"]["acknowledgements"] == []
        assert client.get("/api/violations", headers=viewer).json()["items"][0]["acknowledgements"] == []
        listed = client.get("/api/acknowledgements?ids=dv-1,oc-2", headers=viewer).json()
        assert [(a["alert_id"], a["user"]) for a in listed] == [("oc-2", "operator"), ("oc-2", "admin")]
        assert [a["user"] for a in client.get("/api/acknowledgements", headers=viewer).json()] == ["operator", "admin"]


@pytest.mark.parametrize(("who", "alert", "status"), [
    ("viewer", "oc-2", 403),
    (None, "oc-2", 401),
    ("operator", "no-such-alert", 404),
    ("operator", "dv-1", 201),  # an ended alert can still be acknowledged
])
def test_acknowledging_needs_an_operator_and_a_known_alert(site: Site, history_state: GatewayState, who, alert: str,
                                                           status: int) -> None:
    with secured_client(site, history_state) as (client, secure):
        headers = bearer(secure.tokens[who]) if who else {}
        response = client.post(f"/api/alerts/{alert}/acknowledge", headers=headers)
        assert response.status_code == status
        if status == 404:
            assert "no alert 'no-such-alert'" in response.json()["detail"]


def test_other_dashboards_hear_of_an_acknowledgement(site: Site, history_state: GatewayState) -> None:
    with secured_client(site, history_state) as (client, secure):
        with client.websocket_connect(f"/ws/acknowledgements?token={secure.tokens['viewer']}") as ws:
            client.post("/api/alerts/oc-2/acknowledge", headers=bearer(secure.tokens["operator"]))
            pushed = ws.receive_json()
            ws.close()
        assert (pushed["alert_id"], pushed["user"]) == ("oc-2", "operator")


def test_database_acknowledgements_outlive_the_gateway(site: Site, database_url: str) -> None:  # noqa: F811
    with HistoryDatabase.open(database_url) as db:
        batch = Batch()
        batch.add_event(over_capacity("oc-9", T0))
        db.write(batch)
        with secured_client(site, GatewayState(site, DatabaseHistory(db))) as (client, secure):
            client.post("/api/alerts/oc-9/acknowledge", headers=bearer(secure.tokens["operator"]))
    with HistoryDatabase.open(database_url) as reopened:
        assert [(a.event_id, a.user) for a in reopened.acknowledgements()] == [("oc-9", "operator")]


def test_an_operator_acknowledges_several_alerts_at_once(site: Site, history_state: GatewayState) -> None:
    with secured_client(site, history_state) as (client, secure):
        body = {"ids": ["oc-2", "nope", "dv-1", "oc-2"], "note": "all seen"}
        assert client.post("/api/alerts/acknowledge", json=body, headers=bearer(secure.tokens["viewer"])).status_code == 403
        made = client.post("/api/alerts/acknowledge", json=body, headers=bearer(secure.tokens["operator"]))
        assert made.status_code == 201
        assert [(a["alert_id"], a["note"]) for a in made.json()["acknowledged"]] == [("oc-2", "all seen"), ("dv-1", "all seen")]
        assert made.json()["unknown"] == ["nope"]
        listed = client.get("/api/acknowledgements?ids=dv-1,oc-2", headers=bearer(secure.tokens["viewer"])).json()
        assert [a["alert_id"] for a in listed] == ["dv-1", "oc-2"]
