"""Companions: close pairs that arrived together."""

from __future__ import annotations

import pytest

from bevflow.analytics.companions import Companions

S = 1_000_000_000


def judge(ticks: list[tuple[list[int], list[tuple[int, int]]]], window_s: float = 3.0) -> Companions:
    """Feed one tick a second: (ids present, close pairs)."""
    companions = Companions(window_s)
    for second, (ids, pairs) in enumerate(ticks):
        companions.update(second * S, ids, pairs)
    return companions


TOGETHER = ([1, 2], [(1, 2)])
APART = ([1, 2], [])


@pytest.mark.parametrize(
    ("ticks", "expected", "window_s"),
    [
        pytest.param([TOGETHER] * 6, True, 3.0, id="close from the first tick and after: came together"),
        pytest.param([TOGETHER] * 2, True, 3.0, id="still being judged: counted as companions"),
        pytest.param([TOGETHER, APART, APART, APART, APART], False, 3.0, id="met at the door, then apart"),
        pytest.param([TOGETHER] * 4 + [APART] * 10, True, 3.0, id="companions stay companions when they part"),
        pytest.param([APART] * 5 + [TOGETHER] * 10, False, 3.0, id="strangers who meet later never are"),
        pytest.param([([1], [])] * 5 + [TOGETHER] * 10, True, 3.0, id="2 arrives beside 1: judged from 2's arrival"),
        pytest.param([TOGETHER] * 3 + [APART] + [TOGETHER] * 3, True, 5.0, id="apart one tick of six"),
        pytest.param([TOGETHER] * 3 + [APART] + [TOGETHER] * 3, False, 3.0, id="apart one tick of four"),
    ],
)
def test_who_came_together(ticks: list[tuple[list[int], list[tuple[int, int]]]], expected: bool, window_s: float) -> None:
    assert judge(ticks, window_s).are_companions(1, 2) is expected
    assert judge(ticks, window_s).are_companions(2, 1) is expected


def test_strangers_keeps_only_the_pairs_that_are_not_companions() -> None:
    companions = judge([([1, 2, 3], [(1, 2)])] * 5 + [([1, 2, 3], [(1, 2), (2, 3)])] * 6)
    assert companions.strangers([(1, 2), (2, 3)]).tolist() == [[2, 3]]


def test_a_zero_window_turns_the_rule_off() -> None:
    companions = judge([TOGETHER] * 5, window_s=0.0)
    assert companions.strangers([(1, 2)]).tolist() == [[1, 2]]


def test_ids_unseen_for_a_while_are_forgotten() -> None:
    companions = judge([TOGETHER] * 5 + [([3], [])] * 12)
    assert not companions.are_companions(1, 2)
