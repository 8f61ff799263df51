"""Rendered rim tiles (no torch needed): cut as the detector cuts frames, with every person's box
upright inside its tile, and shards that resume."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bevflow.detect.tiles import TileLayout, tile_affine
from bevflow.training.tile_samples import read_tile_shards, render_tiles, write_tile_shards


def test_a_frame_gives_one_tile_per_sector_with_boxes_inside_it() -> None:
    tiles = render_tiles(np.random.default_rng(3), 96, zoom=(1.0, 1.0), heights=(3.0, 3.5))
    assert len(tiles) == TileLayout().tiles
    assert all(t.image.shape == (96, 96, 3) for t in tiles)
    boxes = np.concatenate([t.xyxy for t in tiles])
    assert len(boxes) > 0, "no person in any tile: the scene drew no one"
    assert (boxes[:, :2] >= -0.5).all() and (boxes[:, 2:] <= 95.5).all() and (boxes[:, 2:] > boxes[:, :2]).all()


@pytest.mark.parametrize("theta", [0.0, math.pi / 4, math.pi, 1.9 * math.pi])
def test_the_tile_map_puts_the_circle_centre_below_the_tile_and_its_sector_above(theta: float) -> None:
    layout, n, centre, radius = TileLayout(), 128, (400.0, 300.0), 250.0
    m, back, offset = tile_affine(theta, centre, radius, layout, n)
    assert m[:, :2] @ np.array(centre) + m[:, 2] == pytest.approx(offset)
    assert offset[1] > n  # the centre lies below the tile
    # The point on the radius at angle theta, half a radius out, lands in the middle column.
    up = back @ np.array([0.0, -1.0])  # the tile's "up" in the frame
    point = np.array(centre) + 0.5 * radius * up
    u, v = m[:, :2] @ point + m[:, 2]
    assert u == pytest.approx(n / 2) and 0 <= v < n


def test_shards_resume_and_read_back_every_tile(tmp_path: Path) -> None:
    write_tile_shards(tmp_path, frames=2, input_px=64, seed=1, per_shard=1)
    first = sorted(p.stat().st_mtime_ns for p in tmp_path.glob("*.npz"))
    write_tile_shards(tmp_path, frames=2, input_px=64, seed=1, per_shard=1)  # nothing left to do
    assert sorted(p.stat().st_mtime_ns for p in tmp_path.glob("*.npz")) == first
    images, boxes = read_tile_shards(tmp_path)
    assert images.shape == (2 * TileLayout().tiles, 64, 64, 3) and len(boxes) == len(images)
    assert all(b.shape[1] == 5 for b in boxes)
