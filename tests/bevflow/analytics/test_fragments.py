"""Contact fragments of one person joined; fleeting contacts left out."""

from __future__ import annotations

import pytest

from bevflow.analytics.fragments import TrackSpan, actionable, merge_fragments
from bevflow.schemas import Contact

S = 1_000_000_000


def contact(track: int, first_s: int, last_s: int, closest_m: float = 1.0) -> Contact:
    return Contact(track=track, first_ns=first_s * S, last_ns=last_s * S, duration_s=float(last_s - first_s),
                   min_distance_m=closest_m, closest_ns=first_s * S, limit_m=2.0)


def span(first_s: float, last_s: float, first_x: float, last_x: float) -> TrackSpan:
    return TrackSpan(int(first_s * S), int(last_s * S), (first_x, 0.0), (last_x, 0.0))


@pytest.mark.parametrize(
    ("spans", "expected"),
    [
        pytest.param({7: span(0, 10, 0, 5), 9: span(11, 30, 5.5, 9)}, [(7, [7, 9], 17.0)], id="found again nearby: joined"),
        pytest.param({7: span(0, 10, 0, 5), 9: span(15, 30, 5.5, 9)}, [(7, [], 8.0), (9, [], 9.0)], id="gap too long"),
        pytest.param({7: span(0, 10, 0, 5), 9: span(11, 30, 8.0, 9)}, [(7, [], 8.0), (9, [], 9.0)], id="too far"),
        pytest.param({7: span(0, 10, 0, 5), 9: span(5, 30, 5.0, 9)}, [(7, [], 8.0), (9, [], 9.0)], id="overlapping: two people"),
        pytest.param({9: span(11, 30, 5.5, 9)}, [(7, [], 8.0), (9, [], 9.0)], id="no span: kept as is"),
    ],
)
def test_merge_fragments(spans: dict[int, TrackSpan], expected: list[tuple]) -> None:
    found = merge_fragments([contact(9, 11, 20), contact(7, 2, 10)], spans)
    assert [(c.track, c.tracks, c.duration_s) for c in found] == expected


def test_a_chain_of_three_fragments_keeps_the_closest_approach() -> None:
    spans = {1: span(0, 10, 0, 5), 2: span(11, 20, 5, 6), 3: span(21, 40, 6, 9)}
    (joined,) = merge_fragments([contact(1, 0, 10, 1.5), contact(2, 11, 20, 0.6), contact(3, 21, 25, 1.2)], spans)
    assert (joined.tracks, joined.first_ns, joined.last_ns, joined.min_distance_m, joined.closest_ns) == ([1, 2, 3], 0, 25 * S, 0.6, 11 * S)


@pytest.mark.parametrize(("shortest", "kept"), [(0.0, [1, 2]), (2.0, [2]), (9.0, [])])
def test_actionable_drops_fleeting_contacts(shortest: float, kept: list[int]) -> None:
    assert [c.track for c in actionable([contact(1, 0, 1), contact(2, 0, 5)], shortest)] == kept
