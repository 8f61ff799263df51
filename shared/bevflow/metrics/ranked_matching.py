"""The best one-to-one matching and the runners-up: Murty's ranking, group by group.

A tracker that keeps more than one way of matching tracks to detections open
(``bevflow.tracking.hypotheses``) needs, besides the best matching, the next best ones. Murty's
method (1968) ranks the matchings of a cost matrix by solving it again with one pair forbidden and
the pairs before it forced, for each pair of the best, and so on down a heap. On a whole site
that would be hundreds of full solves per update, and almost all of them would change the best
matching far from where the choice is close. So the allowed pairs are split into their
connected groups (a track and a detection share a group when one could take the other), each
group is ranked on its own, and each runner-up returned is the best matching with one group's
choice replaced by that group's second, third, … best. Choices in two groups at once are not
ranked here: a tracker holding runners-up from update to update combines them over time.

Costs are as for ``bevflow.metrics.matching.assign_edges`` with an ``unmatched_cost`` u: the
pairs' costs plus u for every row and every column left unmatched.

>>> best, *others = ranked_matchings(np.array([0, 0, 1]), np.array([0, 1, 1]), np.array([1.0, 2.0, 1.5]),
...                                  n_rows=2, n_cols=2, unmatched_cost=2.0, count=3, within=10.0)
>>> best.rows.tolist(), best.cols.tolist(), best.extra  # 1 + 1.5
([0, 1], [0, 1], 0.0)
>>> [(m.rows.tolist(), m.cols.tolist(), m.extra) for m in others]  # 1 + 2u, 1.5 + 2u
[([0], [0], 2.5), ([1], [1], 3.0)]
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from bevflow.metrics.matching import assign_edges

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

LARGEST_GROUP = 24
"""Rows plus columns of the largest group ranked: a bigger one (a dense crowd under one gate)
keeps its best choice only, so that ranking never costs more than a few milliseconds."""

_FORBIDDEN = 1e12  # the price of a pair that may not be made, beyond any real total
_NONE = np.zeros(0, np.int64)


@dataclass(frozen=True, eq=False)
class Matching:
    """Matched (row, col) pairs, sorted by row, and how much more than the best matching they cost."""

    rows: IntArray
    cols: IntArray
    extra: float


@dataclass(frozen=True, eq=False)
class GroupChoice:
    """Another matching of one group, whose rows are ``group_rows``: its rows ``rows`` take the
    columns ``cols``, at ``extra`` more than the group's part of the best matching."""

    extra: float
    group_rows: IntArray
    rows: IntArray
    cols: IntArray


RankingMemo = dict[tuple[object, ...], list[GroupChoice]]
"""Groups' rankings by their pairs, costs and best choice (``ranked_matchings``' ``memo``)."""


def ranked_matchings(
    rows: IntArray,
    cols: IntArray,
    cost: FloatArray,
    n_rows: int,
    n_cols: int,
    unmatched_cost: float,
    count: int,
    within: float,
    memo: RankingMemo | None = None,
) -> list[Matching]:
    """The best matching of the allowed pairs (``rows[k], cols[k], cost[k]``, each pair at most
    once, every cost below 2u), then up to ``count`` − 1 runners-up costing at most ``within``
    more, cheapest first; each runner-up differs from the best in one connected group.
    ``memo``: each group's ranking by its pairs, costs and best choice, shared by calls whose
    problems repeat groups (the hypotheses of one update mostly hold the same tracks)."""
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    best_rows, best_cols = assign_edges(rows, cols, cost, n_rows, n_cols, unmatched_cost)
    best = Matching(best_rows, best_cols, 0.0)
    if count == 1 or len(rows) == 0:
        return [best]
    chosen = np.full(n_rows, -1, dtype=np.int64)
    chosen[best_rows] = best_cols
    runners_up: list[GroupChoice] = []
    lone, groups = _groups(rows, cols, n_rows, n_cols)
    # Most groups are one pair, whose one other choice is to leave it unmatched: 2u less its cost.
    lone_extra = 2.0 * unmatched_cost - cost[lone]
    for k in np.flatnonzero(lone_extra <= within).tolist():
        runners_up.append(GroupChoice(float(lone_extra[k]), rows[lone[k] : lone[k] + 1], _NONE, _NONE))
    memo = {} if memo is None else memo
    for group in groups:
        key = (rows[group].tobytes(), cols[group].tobytes(), cost[group].tobytes(), chosen[rows[group]].tobytes(),
               unmatched_cost, count, within)  # fmt: skip
        if (ranked := memo.get(key)) is None:
            ranked = memo[key] = _ranked_group(rows[group], cols[group], cost[group], chosen, unmatched_cost, count, within)
        runners_up += ranked
    runners_up.sort(key=lambda choice: choice.extra)
    out = [best]
    for choice in runners_up[: count - 1]:
        in_group = np.zeros(n_rows, dtype=bool)
        in_group[choice.group_rows] = True
        keep = ~in_group[best_rows]
        pair_rows, pair_cols = np.concatenate([best_rows[keep], choice.rows]), np.concatenate([best_cols[keep], choice.cols])
        order = np.argsort(pair_rows, kind="stable")
        out.append(Matching(pair_rows[order], pair_cols[order], choice.extra))
    return out


def _groups(rows: IntArray, cols: IntArray, n_rows: int, n_cols: int) -> tuple[IntArray, list[IntArray]]:
    """The allowed pairs split by connected group of rows and columns: the indices of the pairs
    alone in their group, and the indices of each larger group."""
    pair_label = _pair_labels(rows, n_rows + cols, n_rows + n_cols)
    size = np.bincount(pair_label)[pair_label]
    lone = np.flatnonzero(size == 1)
    shared = np.flatnonzero(size > 1)
    order = shared[np.argsort(pair_label[shared], kind="stable")]
    starts = np.flatnonzero(np.diff(pair_label[order], prepend=-1)).tolist() + [len(order)]
    return lone, [order[a:b] for a, b in zip(starts[:-1], starts[1:], strict=True)]


def _pair_labels(a: IntArray, b: IntArray, n: int) -> IntArray:
    """Each edge (a[k], b[k]) of a graph of ``n`` nodes labelled by the least node of its connected
    component: every node takes the least label of its edges' ends, then follows its label's
    label, until nothing changes (a few rounds for the short chains of people near each other)."""
    label = np.arange(n)
    while True:
        least = np.minimum(label[a], label[b])
        moved = label.copy()
        np.minimum.at(moved, a, least)
        np.minimum.at(moved, b, least)
        moved = moved[moved]
        if np.array_equal(moved, label):
            return label[a]
        label = moved


def _ranked_group(rows: IntArray, cols: IntArray, cost: FloatArray, chosen: IntArray, unmatched: float, count: int,
                  within: float) -> list[GroupChoice]:  # fmt: skip
    """Up to ``count`` − 1 matchings of one group other than its part of the best (``chosen``:
    each row's column there, −1 for none), within ``within``; none for a group of more than
    ``LARGEST_GROUP`` rows and columns."""
    row_ids, r = np.unique(rows, return_inverse=True)
    col_ids, c = np.unique(cols, return_inverse=True)
    n_r, n_c = len(row_ids), len(col_ids)
    if n_r + n_c > LARGEST_GROUP:
        return []
    # Padded square matrix: row i may stay unmatched in column n_c + i, column j in row n_r + j.
    matrix = np.full((n_r + n_c, n_c + n_r), _FORBIDDEN)
    matrix[r, c] = cost
    matrix[np.arange(n_r), n_c + np.arange(n_r)] = unmatched
    matrix[n_r + np.arange(n_c), np.arange(n_c)] = unmatched
    matrix[n_r:, n_c:] = 0.0
    in_best = chosen[row_ids]
    best_pick = np.where(in_best >= 0, np.searchsorted(col_ids, in_best), n_c + np.arange(n_r))
    best_total = float(matrix[np.arange(n_r), best_pick].sum()) + unmatched * (n_c - int((in_best >= 0).sum()))
    out: list[GroupChoice] = []
    for total, pick in _murty(matrix, n_r, count):
        if np.array_equal(pick, best_pick):
            continue
        if total - best_total > within or len(out) == count - 1:
            break
        matched = pick < n_c
        out.append(GroupChoice(total - best_total, row_ids, row_ids[matched], col_ids[pick[matched]]))
    return out


def _murty(matrix: FloatArray, n_real: int, count: int) -> list[tuple[float, IntArray]]:
    """The ``count`` cheapest assignments of the square ``matrix``, told apart by what its first
    ``n_real`` rows take, as (total, column of each real row), cheapest first."""
    first = _solve(matrix, n_real)
    if first is None:
        return []
    heap: list[tuple[float, int, IntArray, FloatArray]] = [(first[0], 0, first[1], matrix)]
    pushed, out = 1, list[tuple[float, IntArray]]()
    while heap and len(out) < count:
        total, _, pick, constrained = heapq.heappop(heap)
        out.append((total, pick))
        forced = constrained.copy()
        for i in range(n_real):
            without = forced.copy()
            without[i, pick[i]] = _FORBIDDEN
            if (solved := _solve(without, n_real)) is not None:
                heapq.heappush(heap, (solved[0], pushed, solved[1], without))
                pushed += 1
            keep = forced[i, pick[i]]
            forced[i, :] = _FORBIDDEN
            forced[:, pick[i]] = _FORBIDDEN
            forced[i, pick[i]] = keep
    return out


def _solve(matrix: FloatArray, n_real: int) -> tuple[float, IntArray] | None:
    r, c = linear_sum_assignment(matrix)
    total = float(matrix[r, c].sum())
    return None if total >= _FORBIDDEN else (total, c[:n_real].astype(np.int64))
