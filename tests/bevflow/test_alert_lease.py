"""``OpenAlertLeases``: which open alerts a receiver holds, and how each ends when nobody renews it."""

from __future__ import annotations

import pytest

from bevflow.alert_lease import LEASE_S, OpenAlertLeases
from bevflow.schemas import OverCapacity

S = 1_000_000_000
LEASE_NS = int(LEASE_S * S)


def alert(alert_id: str, start_ns: int = 0, end_ns: int | None = None, peak: int = 5) -> OverCapacity:
    return OverCapacity(id=alert_id, start_ns=start_ns, end_ns=end_ns, capacity=3, peak=peak)


@pytest.mark.parametrize(
    ("start_ns", "opened_ns", "renewals_ns", "now_ns", "end_ns"),
    [
        (0, 10 * S, [], 10 * S + LEASE_NS, None),  # exactly one lease: not over
        (0, 10 * S, [], 10 * S + LEASE_NS + 1, 10 * S),  # ends when it arrived
        (0, 10 * S, [40 * S], 40 * S + LEASE_NS + 1, 40 * S),  # ends at its last renewal
        (0, 10 * S, [40 * S], 10 * S + LEASE_NS + 1, None),  # renewed: still open
        (90 * S, 10 * S, [], 10 * S + LEASE_NS + 1, 90 * S),  # started after its last renewal: ends at its start
    ],
    ids=["lease-not-over", "never-renewed", "renewed-then-silent", "renewed", "start-after-renewal"],
)
def test_an_open_alert_ends_at_its_last_renewal_once_its_lease_is_over(
        start_ns: int, opened_ns: int, renewals_ns: list[int], now_ns: int, end_ns: int | None) -> None:
    leases = OpenAlertLeases()
    assert leases.opened(alert("a", start_ns), opened_ns)
    for renewed_ns in renewals_ns:
        leases.renew(["a", "unknown"], renewed_ns)
    lapsed = leases.lapsed(now_ns)
    assert [(e.id, e.end_ns) for e in lapsed] == ([] if end_ns is None else [("a", end_ns)])
    assert ("a" in leases) == (end_ns is None)
    assert lapsed == [] or lapsed[0].model_copy(update={"end_ns": None}) == alert("a", start_ns)  # all else as it came


def test_an_update_replaces_the_alert_and_restarts_its_lease_in_its_place() -> None:
    leases = OpenAlertLeases(lease_s=10.0)
    leases.opened(alert("a"), 0)
    leases.opened(alert("b"), 0)
    leases.opened(alert("a", peak=9), 8 * S)
    assert [(e.id, e.peak) for e in leases.held()] == [("a", 9), ("b", 5)]
    assert [e.id for e in leases.live(11 * S)] == ["a"]
    assert [e.id for e in leases.held()] == ["a", "b"]  # live does not let go of the lapsed
    assert [(e.id, e.end_ns) for e in leases.lapsed(11 * S)] == [("b", 0)]
    assert [(e.id, e.end_ns) for e in leases.lapsed(19 * S)] == [("a", 8 * S)]
    assert len(leases) == 0


def test_a_closed_alert_is_not_held_and_a_renewal_does_not_bring_it_back() -> None:
    leases = OpenAlertLeases()
    leases.opened(alert("a"), 0)
    leases.closed("a")
    leases.closed("never-opened")
    leases.renew(["a"], S)
    assert "a" not in leases and leases.lapsed(10 * LEASE_NS) == []


@pytest.mark.parametrize(
    ("event", "room"),
    [
        (alert("new"), False),
        (alert("held-0", peak=7), True),  # an update of an alert held
        (alert("new", end_ns=5), True),  # an ended alert takes no room
    ],
    ids=["new-open", "update", "ended"],
)
def test_no_more_than_max_open_alerts_are_held(event: OverCapacity, room: bool) -> None:
    leases = OpenAlertLeases(max_open=3)
    for k in range(3):
        assert leases.opened(alert(f"held-{k}"), 0)
    assert leases.room_for(event) is room
    if event.end_ns is None:
        assert leases.opened(event, 0) is room
    assert len(leases) == 3
