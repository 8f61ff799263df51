"""Pair offsets between overlapping cameras: which cylinders pair, and the per-pair summary."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

import bevflow.calibration.consistency
from bevflow.calibration.consistency import (
    PairSamples,
    check_consistency,
    format_consistency,
    isolated_pairs,
    pair_offsets,
    summarise_pairs,
)
from bevflow.camera import FisheyeCamera
from bevflow.detections import Cylinders
from bevflow.fusion import fuse_cylinders

CAMS = [FisheyeCamera.looking_down((x, 0.0, 3.3), (512, 512)) for x in (0.0, 4.0, 8.0)]
IDS = ["west", "mid", "east"]


def test_fusion_pairs_give_one_sample_per_pair_of_members() -> None:
    seen = Cylinders(xy=[[2.0, 0.0], [2.2, 0.1], [6.0, 0.0], [6.1, 0.0], [9.0, 9.0]], camera=[0, 1, 1, 2, 2])
    samples = pair_offsets(seen, fuse_cylinders(seen, CAMS))
    pairs = sorted(zip(samples.a.tolist(), samples.b.tolist(), np.round(samples.offset, 6).tolist(), strict=True))
    assert pairs == [(0, 1, [-0.2, -0.1]), (1, 2, [-0.1, 0.0])]
    np.testing.assert_allclose(samples.position[samples.a == 0], [[2.1, 0.05]])


def test_fusion_pairs_can_leave_out_head_rebuilt_cylinders() -> None:
    seen = Cylinders(xy=[[2.0, 0.0], [2.2, 0.1]], camera=[0, 1], occluded=[False, True])
    fusion = fuse_cylinders(seen, CAMS)
    assert len(pair_offsets(seen, fusion)) == 1 and len(pair_offsets(seen, fusion, visible_only=True)) == 0


@pytest.mark.parametrize(
    ("xy", "camera", "expected"),
    [
        ([[2.0, 0.0], [2.6, 0.0]], [0, 1], [(0, 1)]),  # 0.6 m apart: beyond fusion, still one person
        ([[2.0, 0.0], [3.2, 0.0]], [0, 1], []),  # beyond the 1 m gate
        ([[2.0, 0.0], [2.3, 0.0], [2.5, 0.0]], [0, 1, 1], []),  # which of camera 1's two is it?
        ([[2.0, 0.0], [2.3, 0.0], [2.5, 0.0]], [0, 0, 1], []),  # two people of camera 0 close together
        ([[4.0, 0.0], [4.2, 0.0], [4.1, 0.3]], [0, 1, 2], [(0, 1), (0, 2), (1, 2)]),  # three cameras, one person
        ([[2.0, 0.0], [2.3, 0.0], [np.nan, np.nan]], [0, 1, 1], [(0, 1)]),  # unplaced rows are ignored
    ],
)
def test_isolated_pairs(xy: list, camera: list, expected: list) -> None:
    samples = isolated_pairs(Cylinders(xy=xy, camera=camera), gate_m=1.0)
    assert sorted(zip(samples.a.tolist(), samples.b.tolist(), strict=True)) == expected


def test_summary_reports_median_offset_and_spread() -> None:
    rng = np.random.default_rng(0)
    offsets = np.array([0.2, -0.1]) + rng.normal(0, 0.05, (400, 2))
    offsets[:20] = [3.0, 3.0]  # a few wrong pairings must not move the median much
    samples = PairSamples(np.zeros(400, np.int64), np.full(400, 2), offsets, np.zeros((400, 2)), np.arange(400))
    (row,) = summarise_pairs(samples, IDS, gate_m=1.0)
    assert (row.camera_a, row.camera_b, row.samples) == ("west", "east", 400)
    np.testing.assert_allclose(row.median_offset, [0.2, -0.1], atol=0.02)
    assert row.median_offset_m == pytest.approx(np.hypot(0.2, 0.1), abs=0.02)
    # Median distance from the centre of a 2-D Gaussian of sigma 0.05: 0.05 * sqrt(2 ln 2) = 0.059.
    assert row.spread_m == pytest.approx(0.059, abs=0.01)
    assert not row.near_gate


@pytest.mark.parametrize("pairing", ["isolated", "fusion"])
def test_check_finds_a_shifted_camera(pairing: str) -> None:
    """Camera 'mid' places everyone 0.25 m too far east: both of its pairs show it, with the sign
    of the pair's order; the west/east pair never overlaps."""
    rng = np.random.default_rng(1)
    frames = []
    for _ in range(60):
        people = np.column_stack([rng.uniform(-1, 9, 6), rng.uniform(-2, 2, 6)])
        per_camera = {}
        for i, cam in enumerate(CAMS):
            inside = np.linalg.norm(people - cam.center[:2], axis=1) < 2.6
            xy = people[inside] + rng.normal(0, 0.03, (int(inside.sum()), 2)) + ([0.25, 0.0] if i == 1 else [0.0, 0.0])
            per_camera[i] = Cylinders(xy=xy)
        frames.append(per_camera)
    rows = {(r.camera_a, r.camera_b): r for r in check_consistency(CAMS, IDS, frames, gate_m=0.8, pairing=pairing)}
    assert set(rows) == {("west", "mid"), ("mid", "east")}
    np.testing.assert_allclose(rows["west", "mid"].median_offset, [-0.25, 0.0], atol=0.03)
    np.testing.assert_allclose(rows["mid", "east"].median_offset, [0.25, 0.0], atol=0.03)
    table = format_consistency(list(rows.values()))
    assert "west / mid" in table and "0.25" in table


def test_near_gate_is_flagged() -> None:
    samples = PairSamples(np.zeros(10, np.int64), np.ones(10, np.int64), np.full((10, 2), [0.4, 0.0]), np.zeros((10, 2)), np.arange(10))
    (row,) = summarise_pairs(samples, IDS, gate_m=0.45)
    assert row.near_gate and "wider --gate" in format_consistency([row])


def test_doctests() -> None:
    assert doctest.testmod(bevflow.calibration.consistency).failed == 0
