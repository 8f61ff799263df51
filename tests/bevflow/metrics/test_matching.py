"""Gated Hungarian matching of floor positions, against hand-worked cases and brute force."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from bevflow.metrics import matching
from bevflow.metrics.matching import assign_edges, match_positions

NAN = float("nan")


@pytest.mark.parametrize(
    ("gt", "est", "threshold", "pairs", "distances"),
    [
        pytest.param([], [], 0.5, [], [], id="both-empty"),
        pytest.param([[0, 0]], [], 0.5, [], [], id="no-estimates"),
        pytest.param([], [[0, 0]], 0.5, [], [], id="no-ground-truth"),
        pytest.param([[0, 0]], [[0.3, 0.4]], 0.5, [(0, 0)], [0.5], id="exactly-at-threshold-matches"),
        pytest.param([[0, 0]], [[0.3, 0.41]], 0.5, [], [], id="just-beyond-threshold"),
        pytest.param(
            [[0, 0], [5, 0]], [[5.1, 0], [0, 0.2], [9, 9]], 0.5, [(0, 1), (1, 0)], [0.2, 0.1], id="order-free"
        ),
        # Nearest-first would give A the shared estimate and leave B alone; Hungarian keeps both.
        pytest.param(
            [[0, 0], [0.9, 0]], [[0.45, 0], [1.3, 0]], 0.5, [(0, 0), (1, 1)], [0.45, 0.4], id="max-cardinality"
        ),
        # Both pairings are allowed; the one with the least total distance wins.
        pytest.param(
            [[0, 0], [1, 0]], [[0.9, 0], [0.1, 0]], 2.0, [(0, 1), (1, 0)], [0.1, 0.1], id="min-total-distance"
        ),
        pytest.param([[0, 0]], [[NAN, NAN], [0, 0.1]], 0.5, [(0, 1)], [0.1], id="nan-estimate-ignored"),
        pytest.param([[0, 0], [NAN, NAN]], [[0, 0.1]], 0.5, [(0, 0)], [0.1], id="nan-gt-ignored"),
        pytest.param([[0, 0], [0, 0]], [[0, 0]], 0.5, [(0, 0)], [0.0], id="one-estimate-for-two"),
    ],
)
def test_match_positions_hand_worked(gt, est, threshold, pairs, distances) -> None:
    gt_idx, est_idx, dist = match_positions(np.array(gt, float), np.array(est, float), threshold)
    assert list(zip(gt_idx.tolist(), est_idx.tolist(), strict=True)) == pairs
    np.testing.assert_allclose(dist, distances, atol=1e-12)


@pytest.mark.parametrize(
    ("gt", "est"),
    [
        pytest.param(np.zeros((2, 3)), np.zeros((1, 2)), id="gt-three-columns"),
        pytest.param(np.zeros((2, 2)), np.zeros(4), id="est-flat"),
    ],
)
def test_match_positions_rejects_bad_shapes(gt, est) -> None:
    with pytest.raises(ValueError, match="shape"):
        match_positions(gt, est)


def _brute_force(gt: np.ndarray, est: np.ndarray, threshold: float) -> tuple[int, float]:
    """Best (number of matches, total distance) by trying every injection of gt into est ∪ {none}."""
    best = (0, 0.0)
    d = np.linalg.norm(gt[:, None] - est[None], axis=2)
    options = list(range(len(est))) + [None] * len(gt)
    for choice in set(itertools.permutations(options, len(gt))):
        pairs = [(i, j) for i, j in enumerate(choice) if j is not None]
        if any(d[i, j] > threshold for i, j in pairs):
            continue
        key = (len(pairs), -sum(d[i, j] for i, j in pairs))
        if key > (best[0], -best[1]):
            best = (len(pairs), -key[1])
    return best


@pytest.mark.parametrize("seed", range(25))
def test_match_positions_is_optimal_on_random_clusters(seed: int) -> None:
    rng = np.random.default_rng(seed)
    gt = rng.uniform(0, 1.5, size=(rng.integers(0, 5), 2))
    est = rng.uniform(0, 1.5, size=(rng.integers(0, 5), 2))
    gt_idx, est_idx, dist = match_positions(gt, est, 0.6)
    assert len(set(gt_idx.tolist())) == len(gt_idx) and len(set(est_idx.tolist())) == len(est_idx)
    assert np.all(dist <= 0.6)
    n_best, total_best = _brute_force(gt, est, 0.6)
    assert len(dist) == n_best
    assert dist.sum() == pytest.approx(total_best, abs=1e-9)


def test_assign_edges_splits_components_and_solves_each() -> None:
    # Component 1: rows 0, 1 and columns 0, 1 (a 2x2 choice); component 2: row 3 - column 5 alone.
    rows = np.array([0, 0, 1, 3])
    cols = np.array([0, 1, 0, 5])
    cost = np.array([0.1, 0.2, 0.1, 0.7])
    r, c = assign_edges(rows, cols, cost, 4, 6)
    assert r.tolist() == [0, 1, 3]
    assert c.tolist() == [1, 0, 5]


def _reference_cost(d: np.ndarray, gate: float, unmatched_cost: float | None) -> tuple[int, float]:
    """(pairs, objective) of the optimum, from a dense solve of the textbook padded problem:
    [[C, diag(u)], [diag(u), 0]], with forbidden entries priced out."""
    n_r, n_c = d.shape
    u = unmatched_cost if unmatched_cost is not None else 1e4  # more than all pairs together
    big = 1e9
    square = np.zeros((n_r + n_c, n_r + n_c))
    square[:n_r, :n_c] = np.where(d <= gate, d, big)
    square[:n_r, n_c:] = np.where(np.eye(n_r, dtype=bool), u, big)
    square[n_r:, :n_c] = np.where(np.eye(n_c, dtype=bool), u, big)
    r, c = linear_sum_assignment(square)
    real = (r < n_r) & (c < n_c)
    return int(real.sum()), float(square[r, c].sum())


@pytest.mark.parametrize("unmatched_cost", [None, 0.3])
@pytest.mark.parametrize("dense_limit", [0, 10**9], ids=["sparse-solver", "dense-solver"])
@pytest.mark.parametrize("seed", range(3))
def test_both_solvers_find_the_optimum(monkeypatch, dense_limit: int, seed: int, unmatched_cost) -> None:
    monkeypatch.setattr(matching, "DENSE_LIMIT", dense_limit)
    rng = np.random.default_rng(seed)
    gt = rng.uniform(0, 8, (300, 2))
    est = np.concatenate([gt[:250] + rng.normal(0, 0.3, (250, 2)), rng.uniform(0, 8, (40, 2))])
    rows, cols, dist = matching.gated_pairs(gt, est, 0.5)
    r, c = assign_edges(rows, cols, dist, len(gt), len(est), unmatched_cost)
    assert len(np.unique(r)) == len(r) and len(np.unique(c)) == len(c)
    d = np.linalg.norm(gt[:, None] - est[None], axis=2)
    assert np.all(d[r, c] <= 0.5)
    n_pairs, objective = _reference_cost(d, 0.5, unmatched_cost)
    u = unmatched_cost if unmatched_cost is not None else 1e4
    ours = d[r, c].sum() + u * (len(gt) - len(r)) + u * (len(est) - len(r))
    assert len(r) == n_pairs
    assert ours == pytest.approx(objective, abs=1e-6)


@pytest.mark.parametrize(
    ("unmatched_cost", "pairs"),
    [
        # Edges A-X 0.0, A-Y 1.0, B-X 1.0. Most pairs: A-Y and B-X (cost 2.0). With u = 0.6,
        # A-X alone costs 0 + 2 × 0.6 for B and Y left over = 1.2 < 2.0.
        pytest.param(None, [(0, 1), (1, 0)], id="most-pairs"),
        pytest.param(0.6, [(0, 0)], id="priced-misses"),
        pytest.param(1.1, [(0, 1), (1, 0)], id="misses-dearer-than-pairs"),
    ],
)
def test_assign_edges_unmatched_cost(unmatched_cost, pairs) -> None:
    r, c = assign_edges(np.array([0, 0, 1]), np.array([0, 1, 0]), np.array([0.0, 1.0, 1.0]), 2, 2, unmatched_cost)
    assert list(zip(r.tolist(), c.tolist(), strict=True)) == pairs


def test_assign_edges_rejects_too_small_unmatched_cost() -> None:
    with pytest.raises(ValueError, match="half the largest cost"):
        assign_edges(np.array([0]), np.array([0]), np.array([1.0]), 1, 1, unmatched_cost=0.5)


@pytest.mark.parametrize("seed", range(10))
def test_sparse_solver_is_optimal_on_small_clusters(monkeypatch, seed: int) -> None:
    monkeypatch.setattr(matching, "DENSE_LIMIT", 0)
    test_match_positions_is_optimal_on_random_clusters(seed)
