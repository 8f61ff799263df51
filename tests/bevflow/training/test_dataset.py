"""The training renders (no torch needed): mounting heights drawn from the range asked for, and
shards that resume and share a folder across seeds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bevflow.training.dataset import read_shards, render_dataset, render_sample


@pytest.mark.parametrize("heights", [(3.0, 5.0), (7.5, 10.0)])
def test_cameras_hang_within_the_heights_asked_for(heights: tuple[float, float]) -> None:
    rng = np.random.default_rng(7)
    drawn = [render_sample(rng, size=96, max_people=3, heights=heights).camera_height_m for _ in range(4)]
    assert all(heights[0] <= h <= heights[1] for h in drawn), drawn


def test_shards_of_two_seeds_share_a_folder_and_a_rerun_writes_nothing(tmp_path: Path) -> None:
    assert render_dataset(tmp_path, 2, seed=4, shard_size=1, heights=(3.0, 4.0)) == 2
    assert render_dataset(tmp_path, 1, seed=5, shard_size=1) == 1
    assert render_dataset(tmp_path, 2, seed=4, shard_size=1, heights=(3.0, 4.0)) == 0  # resumed: all there
    assert sorted(p.name for p in tmp_path.glob("*.npz")) == [
        "shard-0004-00000.npz", "shard-0004-00001.npz", "shard-0005-00000.npz"]
    _images, _owners, heights = read_shards(tmp_path)
    assert len(heights) == 3 and (heights[:2] <= 4.0).all()  # seed 4's shards come first
