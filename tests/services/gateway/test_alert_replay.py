"""Where an alert message stands in the stream, and what ``since`` replays from a history."""

from __future__ import annotations

import pytest

from bevflow.schemas import CameraHealthEvent

from bevflow_services.gateway import alert_replay
from bevflow_services.gateway.alert_replay import RecentAlerts, ReplayError, missed_alerts, position
from bevflow_services.gateway.history import InMemoryHistory
from tests.services.gateway.feed import S, T0, incident


@pytest.mark.parametrize(
    ("event", "expected"),
    [
        (incident("i", T0).model_copy(update={"raised_ns": T0 + 30 * S}), T0 + 30 * S),  # raised after it began
        (incident("i", T0, end_ns=T0 + 5 * S).model_copy(update={"raised_ns": T0 + 6 * S}), T0 + 6 * S),
        (incident("i", T0, end_ns=T0 + 9 * S).model_copy(update={"raised_ns": T0}), T0 + 9 * S),  # ended by its lease
        (CameraHealthEvent(id="d", type="camera_down", camera="c", start_ns=T0), T0),  # from an older tracker
    ],
)
def test_position_is_the_latest_time_of_a_message(event, expected: int) -> None:
    assert position(event) == (expected, event.id)


def _history(n: int) -> InMemoryHistory:
    history = InMemoryHistory()
    for k in range(n):
        history.add_event(incident(f"i{k}", T0 + k * S))
    return history


def test_since_an_alert_the_history_lacks_is_refused() -> None:
    with pytest.raises(ReplayError, match="no alert 'gone' in the history"):
        missed_alerts("gone", RecentAlerts(), _history(3), None, lambda _: True)


def test_too_much_to_replay_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(alert_replay, "MAX_REPLAY", 5)
    assert [a.id for a in missed_alerts("i2", RecentAlerts(), _history(5), None, lambda _: True)] == ["i3", "i4"]
    with pytest.raises(ReplayError, match="more than 5; read them from /api/alerts"):
        missed_alerts("i2", RecentAlerts(), _history(6), None, lambda _: True)


def test_the_gateway_remembers_alerts_the_database_has_not_written_yet() -> None:
    recent = RecentAlerts(size=2)
    for k in range(3):
        recent.add(incident(f"r{k}", T0 + k * S))
    assert recent.get("r0") is None  # the oldest forgotten
    assert [a.id for a in missed_alerts("r1", recent, InMemoryHistory(), None, lambda _: True)] == ["r2"]
