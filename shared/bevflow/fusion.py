"""Merging the cylinders that several overlapping cameras see of one person (the paper's section 3.6).

Two cylinders of different cameras are the same person when their feet are closer than
``distance_m`` (0.45 m in the paper) on the floor. Two cylinders of the same camera never are: a
detector that reports two boxes has seen two people.

Chains are cut, not followed: if A ~ B and B ~ C but A and C are farther apart than ``distance_m``,
A and C cannot be one person, so a group must be a *clique*, every pair of its members within
``distance_m`` (complete linkage). Groups are grown greedily from the closest pair up, so in the
chain above B joins whichever of A and C is nearer. The common case, every candidate group already
a clique of distinct cameras, is settled in one vectorised pass; only tangled groups go through the
greedy loop. Candidate pairs come from a k-d tree, never from all pairs, so the cost follows the
number of cylinders, whatever the number of cameras.

A person's fused position is a weighted mean of the members' feet. A monocular fit's error grows
at least linearly with the camera's distance (its pixel footprint on the floor does), so the
inverse-variance weight falls as 1 / range², range being the 3D distance from the camera centre to
the feet; it is multiplied by the fit's score (its best IoU) so a poor fit counts less. Height and
radius are averaged with the same weights; score is the best member's; ``occluded`` holds only when
every view was occluded.

>>> from bevflow.camera import FisheyeCamera
>>> cams = [FisheyeCamera.looking_down((x, 0.0, 3.3), (512, 512)) for x in (0.0, 4.0)]
>>> seen = Cylinders(xy=[[2.0, 0.0], [2.1, 0.0]], camera=[0, 1])
>>> fuse_cylinders(seen, cams).n_views.tolist()
[2]
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from bevflow.camera import Camera
from bevflow.detections import Cylinders

IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class Fusion:
    """``fused``: one row per person, ``camera`` the single camera that saw them or −1 when fused
    from several. ``assignment`` (len(input),): the fused row of each input cylinder, −1 for inputs
    with non-finite feet (dropped). ``n_views`` (len(fused),): how many cameras saw each person."""

    fused: Cylinders
    assignment: IntArray
    n_views: IntArray


def fuse_cylinders(cylinders: Cylinders, cameras: Sequence[Camera], distance_m: float = 0.45) -> Fusion:
    """Merge the cylinders of different cameras whose feet are closer than ``distance_m``.
    ``cylinders.camera`` indexes ``cameras``."""
    if distance_m <= 0:
        raise ValueError(f"distance_m must be > 0, got {distance_m}")
    camera = cylinders.camera
    bad = (camera < 0) | (camera >= len(cameras))
    if bad.any():
        raise ValueError(
            f"cylinder camera index {int(camera[bad][0])} does not name one of the {len(cameras)} cameras "
            "(fuse per-camera cylinders, before any earlier fusion)"
        )
    keep = np.flatnonzero(np.isfinite(cylinders.xy).all(axis=1))
    assignment = np.full(len(cylinders), -1, dtype=np.int64)
    if len(keep) == 0:
        return Fusion(fused=Cylinders.empty(), assignment=assignment, n_views=np.zeros(0, dtype=np.int64))

    rows = cylinders[keep]
    labels = _group(rows.xy, rows.camera, distance_m)
    # Number the people in the order their first cylinder arrived.
    _, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    person = rank[inverse]
    assignment[keep] = person
    fused, n_views = _merge(rows, person, len(order), _reliability(rows, cameras))
    return Fusion(fused=fused, assignment=assignment, n_views=n_views)


def _reliability(rows: Cylinders, cameras: Sequence[Camera]) -> NDArray[np.float64]:
    centres = np.array([c.center for c in cameras])[rows.camera]
    feet = np.concatenate([rows.xy, np.zeros((len(rows), 1))], axis=1)
    range_sq = np.maximum(((feet - centres) ** 2).sum(axis=1), 1e-6)
    return np.maximum(rows.score, 1e-6) / range_sq


def _group(xy: NDArray[np.float64], camera: IntArray, distance_m: float) -> IntArray:
    """A group label per row: cliques of distinct cameras, all pairs closer than ``distance_m``."""
    n = len(xy)
    pairs = cKDTree(xy).query_pairs(distance_m, output_type="ndarray")
    if len(pairs):
        gap = np.linalg.norm(xy[pairs[:, 0]] - xy[pairs[:, 1]], axis=1)
        usable = (camera[pairs[:, 0]] != camera[pairs[:, 1]]) & (gap < distance_m)
        pairs, gap = pairs[usable], gap[usable]
    if len(pairs) == 0:
        return np.arange(n)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    size = np.bincount(labels, minlength=labels.max() + 1)
    edges = np.bincount(labels[pairs[:, 0]], minlength=len(size))
    # Without same-camera pairs in the graph, a component with every pair linked is a clique of
    # distinct cameras: it is one person as it stands.
    tangled = np.flatnonzero(edges < size * (size - 1) // 2)
    if len(tangled):
        labels = labels.copy()
        in_tangled = np.isin(labels[pairs[:, 0]], tangled)
        _split_greedily(labels, camera, pairs[in_tangled], gap[in_tangled])
    return labels


def _split_greedily(labels: IntArray, camera: IntArray, pairs: IntArray, gap: NDArray[np.float64]) -> None:
    """Relabel the rows of tangled components in place: start from singletons and join groups along
    pairs in order of distance, when the cameras are distinct and every cross pair is linked."""
    nodes = np.unique(pairs)
    fresh = labels.max() + 1 + np.arange(len(nodes))
    labels[nodes] = fresh  # every tangled row alone, under a label no clean component uses
    members = {int(label): [int(node)] for label, node in zip(fresh, nodes)}
    linked = {(int(a), int(b)) for a, b in pairs} | {(int(b), int(a)) for a, b in pairs}
    for k in np.argsort(gap, kind="stable"):
        a, b = int(labels[pairs[k, 0]]), int(labels[pairs[k, 1]])
        if a == b:
            continue
        group_a, group_b = members[a], members[b]
        if {int(camera[i]) for i in group_a} & {int(camera[j]) for j in group_b}:
            continue
        if all((i, j) in linked for i in group_a for j in group_b):
            group_a.extend(group_b)
            labels[group_b] = a
            del members[b]


def _merge(rows: Cylinders, person: IntArray, n_people: int, weight: NDArray[np.float64]) -> tuple[Cylinders, IntArray]:
    n_views = np.bincount(person, minlength=n_people).astype(np.int64)
    total = np.bincount(person, weights=weight, minlength=n_people)

    def mean(values: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.bincount(person, weights=weight * values, minlength=n_people) / total

    score = np.full(n_people, -np.inf)
    np.maximum.at(score, person, rows.score)
    visible = np.zeros(n_people, dtype=bool)
    np.logical_or.at(visible, person, ~rows.occluded)
    camera = np.full(n_people, -1, dtype=np.int64)
    alone = n_views[person] == 1
    camera[person[alone]] = rows.camera[alone]
    fused = Cylinders(
        xy=np.stack([mean(rows.xy[:, 0]), mean(rows.xy[:, 1])], axis=1),
        height=mean(rows.height),
        radius=mean(rows.radius),
        camera=camera,
        score=score,
        occluded=~visible,
    )
    return fused, n_views
