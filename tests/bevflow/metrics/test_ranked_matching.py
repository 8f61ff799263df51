"""Ranked matchings against every matching of small problems, tried one by one."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from bevflow.metrics import ranked_matching
from bevflow.metrics.ranked_matching import ranked_matchings

U = 1.0  # the price of a row or a column left unmatched


def _problem(seed: int, n_rows: int, n_cols: int, share: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random allowed pairs (about ``share`` of them) with costs below 2U."""
    rng = np.random.default_rng(seed)
    allowed = rng.random((n_rows, n_cols)) < share
    rows, cols = np.nonzero(allowed)
    return rows.astype(np.int64), cols.astype(np.int64), rng.uniform(-1.0, 2.0 * U - 0.01, len(rows))


def _every_matching(rows, cols, cost, n_rows: int, n_cols: int) -> dict[frozenset, float]:
    """Each matching of the allowed pairs (as a set of (row, col)) and its total cost."""
    price = {(r, c): k for r, c, k in zip(rows.tolist(), cols.tolist(), cost.tolist(), strict=True)}
    out = {}
    for size in range(min(n_rows, n_cols) + 1):
        for pairs in itertools.combinations(price, size):
            if len({r for r, _ in pairs}) == size == len({c for _, c in pairs}):
                out[frozenset(pairs)] = sum(price[p] for p in pairs) + U * (n_rows + n_cols - 2 * size)
    return out


def _pairs(matching) -> frozenset:
    return frozenset(zip(matching.rows.tolist(), matching.cols.tolist(), strict=True))


@pytest.mark.parametrize("seed", range(12))
def test_one_group_is_ranked_as_every_matching_tried(seed: int) -> None:
    rows, cols, cost = _problem(seed, 3, 3, share=1.0)  # every pair allowed: one group
    every = _every_matching(rows, cols, cost, 3, 3)
    ranked = ranked_matchings(rows, cols, cost, 3, 3, U, count=6, within=np.inf)
    best = min(every.values())
    assert every[_pairs(ranked[0])] == pytest.approx(best) and ranked[0].extra == 0.0
    expected = sorted(every.values())[1:6]
    assert [m.extra for m in ranked[1:]] == pytest.approx([c - best for c in expected])
    for m in ranked[1:]:
        assert every[_pairs(m)] - best == pytest.approx(m.extra)
    assert len({_pairs(m) for m in ranked}) == len(ranked)  # no matching twice


@pytest.mark.parametrize("seed", range(12))
def test_runners_up_change_one_group_each_and_cost_what_they_say(seed: int) -> None:
    rows, cols, cost = _problem(100 + seed, 5, 6, share=0.3)
    every = _every_matching(rows, cols, cost, 5, 6)
    ranked = ranked_matchings(rows, cols, cost, 5, 6, U, count=8, within=1.5)
    best = min(every.values())
    assert every[_pairs(ranked[0])] == pytest.approx(best)
    extras = [m.extra for m in ranked]
    assert extras == sorted(extras) and all(0 < e <= 1.5 for e in extras[1:])
    for m in ranked[1:]:
        assert every[_pairs(m)] - best == pytest.approx(m.extra)
    assert len({_pairs(m) for m in ranked}) == len(ranked)


def test_a_lone_pair_may_be_left_unmatched_and_nothing_beyond_within() -> None:
    one = (np.array([0]), np.array([0]), np.array([0.5]))
    best, other = ranked_matchings(*one, 1, 1, U, count=3, within=1.5)
    assert (best.rows.tolist(), other.rows.tolist(), other.extra) == ([0], [], 1.5)  # 2U − 0.5
    assert len(ranked_matchings(*one, 1, 1, U, count=3, within=1.4)) == 1


@pytest.mark.parametrize(
    ("rows", "count", "expected"),
    [
        pytest.param([], 3, 1, id="no pairs: the empty matching alone"),
        pytest.param([0, 1], 1, 1, id="count 1: the best alone"),
    ],
)
def test_the_best_alone(rows: list[int], count: int, expected: int) -> None:
    r = np.array(rows, np.int64)
    ranked = ranked_matchings(r, r, np.zeros(len(r)), 2, 2, U, count=count, within=np.inf)
    assert len(ranked) == expected and ranked[0].rows.tolist() == rows


def test_a_group_past_the_largest_ranked_keeps_its_best_choice(monkeypatch) -> None:
    rows, cols, cost = _problem(7, 3, 3, share=1.0)
    monkeypatch.setattr(ranked_matching, "LARGEST_GROUP", 5)
    assert len(ranked_matchings(rows, cols, cost, 3, 3, U, count=4, within=np.inf)) == 1


def test_count_below_one_is_refused() -> None:
    with pytest.raises(ValueError, match="count"):
        ranked_matchings(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), 0, 0, U, count=0, within=1.0)


@pytest.mark.parametrize(("seed", "share"), [(s, share) for s in range(6) for share in (0.05, 0.2, 0.6)])
def test_groups_are_the_connected_components_of_the_pairs(seed: int, share: float) -> None:
    rows, cols, _ = _problem(200 + seed, 30, 25, share)
    n = 30 + 25
    graph = coo_matrix((np.ones(len(rows)), (rows, 30 + cols)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    lone, groups = ranked_matching._groups(rows, cols, 30, 25)
    parts = [[int(k)] for k in lone] + [g.tolist() for g in groups]
    assert sorted(k for part in parts for k in part) == list(range(len(rows)))  # each pair once
    assert all(len(set(label[rows[part]])) == 1 for part in parts)  # a part lies in one component
    assert len({label[rows[part[0]]] for part in parts}) == len(parts)  # and no component is split
    assert all(len(group) > 1 for group in groups)


def test_a_memo_shared_by_calls_gives_each_the_rankings_it_gives_alone() -> None:
    problems = [_problem(300 + seed, 6, 6, share=0.3) for seed in range(8)]
    problems += problems[:3]  # repeated problems are read from the memo
    memo: ranked_matching.RankingMemo = {}
    for rows, cols, cost in problems:
        alone = ranked_matchings(rows, cols, cost, 6, 6, U, count=6, within=2.0)
        shared = ranked_matchings(rows, cols, cost, 6, 6, U, count=6, within=2.0, memo=memo)
        assert [(_pairs(m), m.extra) for m in shared] == [(_pairs(m), m.extra) for m in alone]
    assert memo
