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
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

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


def ranked_matchings(
    rows: IntArray,
    cols: IntArray,
    cost: FloatArray,
    n_rows: int,
    n_cols: int,
    unmatched_cost: float,
    count: int,
    within: float,
) -> list[Matching]:
    """The best matching of the allowed pairs (``rows[k], cols[k], cost[k]``, each pair at most
    once, every cost below 2u), then up to ``count`` − 1 runners-up costing at most ``within``
    more, cheapest first; each runner-up differs from the best in one connected group."""
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    best_rows, best_cols = assign_edges(rows, cols, cost, n_rows, n_cols, unmatched_cost)
    best = Matching(best_rows, best_cols, 0.0)
    if count == 1 or len(rows) == 0:
        return [best]
    chosen = np.full(n_rows, -1, dtype=np.int64)
    chosen[best_rows] = best_cols
    runners_up: list[tuple[float, IntArray, IntArray, IntArray]] = []
    for group in _groups(rows, cols, n_rows, n_cols):
        if len(group) == 1:  # most groups: the one other choice is to leave the pair unmatched
            if (extra := 2.0 * unmatched_cost - float(cost[group[0]])) <= within:
                runners_up.append((extra, rows[group], _NONE, _NONE))
            continue
        group_rows = np.unique(rows[group])
        if len(group_rows) + len(np.unique(cols[group])) > LARGEST_GROUP:
            continue
        for extra, r, c in _ranked_group(rows[group], cols[group], cost[group], chosen, unmatched_cost, count, within):
            runners_up.append((extra, group_rows, r, c))
    runners_up.sort(key=lambda item: item[0])
    out = [best]
    for extra, group_rows, r, c in runners_up[: count - 1]:
        keep = ~np.isin(best_rows, group_rows)
        pair_rows, pair_cols = np.concatenate([best_rows[keep], r]), np.concatenate([best_cols[keep], c])
        order = np.argsort(pair_rows, kind="stable")
        out.append(Matching(pair_rows[order], pair_cols[order], extra))
    return out


def _groups(rows: IntArray, cols: IntArray, n_rows: int, n_cols: int) -> list[IntArray]:
    """The allowed pairs' indices, split by connected group of rows and columns."""
    n = n_rows + n_cols
    graph = coo_matrix((np.ones(len(rows)), (rows, n_rows + cols)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    pair_label = label[rows]
    order = np.argsort(pair_label, kind="stable")
    starts = np.flatnonzero(np.diff(pair_label[order], prepend=-1))
    return np.split(order, starts[1:])


def _ranked_group(
    rows: IntArray, cols: IntArray, cost: FloatArray, chosen: IntArray, unmatched: float, count: int, within: float
) -> list[tuple[float, IntArray, IntArray]]:
    """Up to ``count`` − 1 matchings of one group other than its part of the best (``chosen``:
    each row's column there, −1 for none), as (extra cost, rows, cols), within ``within``."""
    row_ids, r = np.unique(rows, return_inverse=True)
    col_ids, c = np.unique(cols, return_inverse=True)
    n_r, n_c = len(row_ids), len(col_ids)
    # Padded square matrix: row i may stay unmatched in column n_c + i, column j in row n_r + j.
    matrix = np.full((n_r + n_c, n_c + n_r), _FORBIDDEN)
    matrix[r, c] = cost
    matrix[np.arange(n_r), n_c + np.arange(n_r)] = unmatched
    matrix[n_r + np.arange(n_c), np.arange(n_c)] = unmatched
    matrix[n_r:, n_c:] = 0.0
    in_best = chosen[row_ids]
    best_pick = np.where(in_best >= 0, np.searchsorted(col_ids, in_best), n_c + np.arange(n_r))
    best_total = float(matrix[np.arange(n_r), best_pick].sum()) + unmatched * (n_c - int((in_best >= 0).sum()))
    out: list[tuple[float, IntArray, IntArray]] = []
    for total, pick in _murty(matrix, n_r, count):
        if np.array_equal(pick, best_pick):
            continue
        if total - best_total > within or len(out) == count - 1:
            break
        matched = pick < n_c
        out.append((total - best_total, row_ids[matched], col_ids[pick[matched]]))
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
