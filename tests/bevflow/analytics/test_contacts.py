from __future__ import annotations

import math

import pytest

from bevflow.analytics.contacts import contacts
from bevflow.analytics.trajectories import TrackHistory

S = 1_000_000_000

# Positions at t = 0..5 s (None: not tracked then). Track 1 stands at the origin.
SCENE: dict[int, list[tuple[float, float] | None]] = {
    1: [(0.0, 0.0)] * 6,
    2: [(5.0, 0.0), (3.0, 0.0), (1.5, 0.0), (1.0, 0.0), (1.8, 0.0), (4.0, 0.0)],  # walks up to 1 and back
    3: [(0.0, 1.9), (0.0, 1.9), None, None, None, None],  # beside 1, then leaves
    4: [(3.0, 4.0)] * 6,  # always 5 m away
    5: [None, None, None, None, (1.0, 1.0), (1.5, 1.5)],  # arrives late, close for one sample
}


@pytest.fixture(scope="module")
def history() -> TrackHistory:
    h = TrackHistory(sample_period_s=1.0)
    for k in range(6):
        present = {i: p[k] for i, p in SCENE.items() if p[k] is not None}
        h.update(k * S, list(present), list(present.values()))
    return h


def table(found: list) -> list[tuple[int, float, float, float, float, float]]:
    """(other track, first s, last s, duration s, min distance m, closest s), distance rounded to 1e-6."""
    return [
        (c.track, c.first_ns / S, c.last_ns / S, c.duration_s, round(c.min_distance_m, 6), c.closest_ns / S)
        for c in found
    ]


@pytest.mark.parametrize(
    ("track", "limit", "window", "expected"),
    [
        pytest.param(
            1,
            2.0,
            (None, None),
            [(3, 0, 1, 2.0, 1.9, 0), (2, 2, 4, 3.0, 1.0, 3), (5, 4, 4, 1.0, round(math.sqrt(2), 6), 4)],
            id="everyone who came within 2 m of track 1",
        ),
        pytest.param(
            1, 2.0, (3 * S, None), [(2, 3, 4, 2.0, 1.0, 3), (5, 4, 4, 1.0, round(math.sqrt(2), 6), 4)], id="since 3 s"
        ),
        pytest.param(1, 2.0, (None, 3 * S), [(3, 0, 1, 2.0, 1.9, 0), (2, 2, 3, 2.0, 1.0, 3)], id="until 3 s"),
        pytest.param(1, 1.2, (None, None), [(2, 3, 3, 1.0, 1.0, 3)], id="tighter limit"),
        pytest.param(
            2,
            2.0,
            (None, None),
            [(1, 2, 4, 3.0, 1.0, 3), (5, 4, 4, 1.0, round(math.hypot(0.8, 1.0), 6), 4)],
            id="seen from the other side",
        ),
        pytest.param(4, 2.0, (None, None), [], id="nobody came near track 4"),
    ],
)
def test_contacts(history: TrackHistory, track: int, limit: float, window: tuple, expected: list) -> None:
    found = contacts(history, track, limit, start_ns=window[0], end_ns=window[1])
    assert table(found) == expected
    assert all(c.limit_m == limit for c in found)


def test_last_sample_counts_for_no_time() -> None:
    h = TrackHistory(sample_period_s=0)
    h.update(0, [1, 2], [[0, 0], [5, 0]])
    h.update(2 * S, [1, 2], [[0, 0], [1, 0]])
    assert table(contacts(h, 1, 2.0)) == [(2, 2, 2, 0.0, 1.0, 2)]


def test_unknown_track_and_bad_limit(history: TrackHistory) -> None:
    with pytest.raises(KeyError, match="no history for track 99"):
        contacts(history, 99, 2.0)
    with pytest.raises(ValueError, match="limit_m"):
        contacts(history, 1, 0.0)
