from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bevflow.alert_lease import BURST, LEASE_S, MAX_OPEN
from bevflow.schemas import CameraHealthEvent, Detections2D, FrameHeader, OpenAlerts, TrackState, Tracks, ZoneOccupancy

from bevflow_services.gateway.history import EventQuery
from bevflow_services.gateway.state import GatewayState
from tests.services.gateway.feed import S, T0, FakeClock, occupancy, over_capacity, tracks, violation


def test_tracks_become_the_latest_and_enter_the_history(state: GatewayState) -> None:
    for k in range(3):
        assert state.apply(tracks(T0 + k * S, {1: (float(k), 0.0), 2: (5.0, 5.0)}))
    assert state.tracks is not None and state.tracks.time_ns == T0 + 2 * S
    path = state.history.trajectory(1)
    assert path is not None
    assert path.times_ns.tolist() == [T0, T0 + S, T0 + 2 * S]
    assert path.xy[:, 0].tolist() == [0.0, 1.0, 2.0]


@pytest.mark.parametrize(
    "message",
    [
        Tracks(site="elsewhere", time_ns=T0),
        occupancy(T0, 1).model_copy(update={"site": "elsewhere"}),
        Detections2D(camera="nope", seq=0, capture_ns=T0),
        FrameHeader(camera="nope", seq=0, capture_ns=T0, width=10, height=10),
        CameraHealthEvent(id="x", type="camera_down", camera="nope", start_ns=T0),
    ],
    ids=["tracks-other-site", "occupancy-other-site", "detections-unknown-camera", "frame-unknown-camera", "event-unknown-camera"],
)
def test_messages_for_another_site_or_camera_are_ignored_and_counted(state: GatewayState, message) -> None:
    assert state.apply(message) is False
    assert state.ignored == 1
    assert state.tracks is None and state.occupancy is None and state.active_alerts() == []


@pytest.mark.parametrize(
    "message",
    [
        tracks(T0, {1: (0.0, 0.0)}, zones={1: ["gate", "\tforged"]}),
        occupancy(T0, 1).model_copy(update={"zones": [ZoneOccupancy(id="=cmd|' /C calc'!A0", count=1)]}),
        violation("v1", T0).model_copy(update={"zone": "nowhere"}),
    ],
    ids=["tracks", "occupancy", "alert"],
)
def test_messages_naming_a_zone_the_site_does_not_have_are_ignored(state: GatewayState, message) -> None:
    assert state.apply(message) is False and state.ignored == 1
    assert state.tracks is None and state.occupancy is None and state.history.events(EventQuery(), 10) == ([], 0)


def test_tracks_older_than_the_latest_are_ignored(state: GatewayState) -> None:
    state.apply(tracks(T0 + 2 * S, {1: (0.0, 0.0)}))
    assert state.apply(tracks(T0 + S, {1: (9.0, 9.0)})) is False
    assert state.tracks is not None and state.tracks.time_ns == T0 + 2 * S


def test_ticks_older_than_the_live_window_are_ignored(state: GatewayState, clock: FakeClock) -> None:
    clock.advance(3600)
    assert state.apply(tracks(T0 - S, {1: (9.0, 9.0)})) is False
    assert state.apply(occupancy(T0 - S, 9)) is False
    assert state.ignored == 2 and state.tracks is None and state.occupancy is None
    assert state.apply(tracks(T0 + S, {1: (1.0, 1.0)})) and state.apply(occupancy(T0 + S, 1))


def test_active_alerts_follow_start_and_end_messages_with_the_same_id(state: GatewayState) -> None:
    state.apply(violation("v1", T0))
    state.apply(over_capacity("c1", T0 + S))
    assert [e.id for e in state.active_alerts()] == ["v1", "c1"]
    state.apply(violation("v1", T0, end_ns=T0 + 3 * S))
    assert [e.id for e in state.active_alerts()] == ["c1"]
    stored, total = state.history.events(EventQuery(), 10)
    assert total == 2 and stored[1].end_ns == T0 + 3 * S  # the end replaced the start in the history


@pytest.mark.parametrize("renewed", [False, True], ids=["forged", "renewed-by-the-tracker"])
def test_an_open_alert_nobody_renews_ends_by_itself(state: GatewayState, clock: FakeClock, renewed: bool) -> None:
    state.apply(violation("v1", T0))
    for _ in range(4):
        clock.advance(LEASE_S / 3)
        if renewed:
            assert state.apply(OpenAlerts(site="hall", time_ns=clock.now, ids=["v1", "unknown"]))
        ended = state.end_lapsed_alerts()
    assert [e.id for e in state.active_alerts()] == (["v1"] if renewed else [])
    assert [(e.id, e.end_ns) for e in ended] == ([] if renewed else [("v1", T0)])  # ended at its last renewal
    stored, _ = state.history.events(EventQuery(active=True), 10)
    assert [e.id for e in stored] == (["v1"] if renewed else [])


def test_a_flood_of_forged_alerts_is_refused_beyond_the_rate_and_ends_by_itself(state: GatewayState,
                                                                                clock: FakeClock) -> None:
    flood = 3 * BURST
    accepted = sum(state.apply(violation(f"forged-{k}", T0)) for k in range(flood))
    assert accepted == BURST and state.ignored == flood - BURST
    clock.advance(1.0)
    assert state.apply(violation("real", T0 + S))  # the bucket refills at its rate
    clock.advance(LEASE_S)
    state.apply(OpenAlerts(site="hall", time_ns=clock.now, ids=["real"]))
    clock.advance(1.0)
    assert len(state.end_lapsed_alerts()) == BURST
    assert [e.id for e in state.active_alerts()] == ["real"]


def test_camera_up_ends_the_cameras_open_down_alert(state: GatewayState) -> None:
    state.apply(CameraHealthEvent(id="down-north", type="camera_down", camera="north", start_ns=T0))
    state.apply(CameraHealthEvent(id="down-south", type="camera_down", camera="south", start_ns=T0))
    state.apply(CameraHealthEvent(id="up-north", type="camera_up", camera="north", start_ns=T0 + S))
    assert [e.id for e in state.active_alerts()] == ["down-south"]
    assert [c.state for c in state.camera_health()] == ["unknown", "down"]


def test_camera_messages_update_health_with_the_gateway_clock(state: GatewayState, clock: FakeClock) -> None:
    state.apply(Detections2D(camera="north", seq=0, capture_ns=T0))
    clock.advance(2.0)
    state.apply(Detections2D(camera="north", seq=3, capture_ns=T0 + S))
    clock.advance(1.0)
    north, south = state.camera_health()
    assert (north.state, north.received, north.dropped, north.age_s) == ("up", 2, 2, 1.0)
    assert south.state == "unknown"
    clock.advance(10.0)
    assert state.camera_health()[0].state == "down"


def test_services_come_and_go(state: GatewayState, clock: FakeClock) -> None:
    state.service_up("tracker", "host-1")
    clock.advance(1.0)
    state.service_up("ingest", "host-2")
    state.service_up("tracker", "host-1")  # a repeated announcement keeps the first time
    assert [(s.name, s.instance, s.since_ns) for s in state.services()] == [
        ("ingest", "host-2", T0 + S),
        ("tracker", "host-1", T0),
    ]
    state.service_down("tracker", "host-1")
    assert [s.name for s in state.services()] == ["ingest"]


def test_tracks_age_uses_the_gateway_clock(state: GatewayState, clock: FakeClock) -> None:
    assert state.tracks_age_s() is None
    state.apply(tracks(T0, {}))
    clock.advance(2.5)
    assert state.tracks_age_s() == 2.5


def test_a_message_of_another_kind_is_a_bug(state: GatewayState) -> None:
    with pytest.raises(TypeError, match="TrackState"):
        state.apply(TrackState(id=1, xy=(0.0, 0.0)))  # type: ignore[arg-type]


def test_tracks_the_history_refuses_are_ignored_not_raised(state: GatewayState) -> None:
    repeated_id = Tracks(site="hall", time_ns=T0, tracks=[TrackState(id=1, xy=(0.0, 0.0)), TrackState(id=1, xy=(1.0, 0.0))])
    assert state.apply(repeated_id) is False
    assert (state.ignored, state.tracks) == (1, None)
    assert state.apply(tracks(T0 + S, {1: (0.0, 0.0)}))


ALERT_TIMES = st.one_of(st.integers(0, 2**63 - 1), st.sampled_from([0, 1, T0, 2**63 - 1]))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(alerts=st.lists(st.tuples(st.sampled_from(["a", "b", "c"]) | st.text(min_size=1, max_size=8), ALERT_TIMES,
                                 st.none() | ALERT_TIMES, st.floats(0, 30)), max_size=40),
       renewed=st.sets(st.sampled_from(["a", "b", "c"])))
def test_forged_alerts_with_any_times_end_by_themselves(site, alerts, renewed) -> None:
    """Forged alerts, with start and end times anywhere from 1970 to 2262, repeated ids, gaps:
    the open ones stay bounded, only renewed ones outlive the lease, and nothing raises."""
    clock = FakeClock()
    state = GatewayState(site, clock=clock)
    for alert_id, start_ns, end_ns, gap_s in alerts:
        state.apply(violation(alert_id, start_ns, end_ns=end_ns))
        clock.advance(gap_s)
        assert len(state.active_alerts()) <= MAX_OPEN
    for _ in range(3):
        clock.advance(LEASE_S / 2)
        state.apply(OpenAlerts(site="hall", time_ns=T0, ids=sorted(renewed)))
        state.end_lapsed_alerts()
    assert {e.id for e in state.active_alerts()} <= renewed
    assert {e.id for e in state.history.events(EventQuery(active=True), 1000)[0]} <= renewed
