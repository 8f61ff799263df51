"""The training renders (no torch needed): mounting heights drawn from the range asked for, people
in tight groups and cameras square to the room when asked, and shards that resume and share a
folder across seeds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bevflow.training.dataset import (
    SceneMix,
    _groups,
    _random_camera,
    _random_room,
    _spread,
    read_shards,
    render_dataset,
    render_sample,
)


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


def nearest_neighbour_m(xy: np.ndarray) -> np.ndarray:
    d = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    return d.min(axis=1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_groups_are_queues_or_huddles_of_people_half_a_metre_apart(seed: int) -> None:
    rng = np.random.default_rng(seed)
    anchors = rng.uniform(0, 50, (10, 2))  # far apart: each group stands alone
    xy = _groups(rng, anchors, 12)
    assert len(xy) >= 12
    gap = nearest_neighbour_m(xy)
    assert (gap >= 0.40).all() and (gap <= 0.72).all(), gap


def test_grouped_people_stand_closer_together_than_spread_ones() -> None:
    rng = np.random.default_rng(5)
    floor = np.stack(np.meshgrid(np.linspace(-6, 6, 40), np.linspace(-6, 6, 40)), -1).reshape(-1, 2)
    room = _random_room(rng, 4.0, floor)
    spread = _spread(np.random.default_rng(1), floor, 20, room)
    grouped = _spread(np.random.default_rng(1), floor, 20, room, grouped=0.8)
    assert len(spread) == len(grouped) == 20
    assert np.median(nearest_neighbour_m(grouped)) < 0.7 < np.median(nearest_neighbour_m(spread))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_squared_camera_is_level_and_turned_by_a_multiple_of_90_degrees(seed: int) -> None:
    R = _random_camera(np.random.default_rng(seed), 4.0, squared=1.0).R
    axes = np.abs(R[:2, :2])  # the image axes along the room's, in some order
    np.testing.assert_allclose(np.sort(axes, axis=None), [0, 0, 1, 1], atol=1e-9)
    assert np.isclose(abs(R[2, 2]), 1.0)  # looking straight down


def test_the_default_mix_draws_the_renders_of_before() -> None:
    """Shares of 0 draw nothing extra: the same rng gives the same camera with or without them."""
    plain = _random_camera(np.random.default_rng(6), 4.0)
    mixed = _random_camera(np.random.default_rng(6), 4.0, squared=0.0)
    np.testing.assert_array_equal(plain.R, mixed.R)
    assert not np.allclose(np.sort(np.abs(plain.R[:2, :2]), axis=None), [0, 0, 1, 1], atol=1e-3)  # not square


@pytest.mark.parametrize("field", ["grouped", "shifted_tiles", "squared"])
def test_a_share_outside_0_to_1_is_refused(field: str) -> None:
    with pytest.raises(ValueError, match=f"SceneMix.{field} is a share"):
        SceneMix(**{field: 1.5})


def test_a_zoomed_render_draws_the_same_scene_through_a_longer_focal_length() -> None:
    """``zoom`` scales the camera's focal length only: a model trained on such shards sees people
    ``zoom`` times larger (its exported file records the zoom)."""
    plain = render_sample(np.random.default_rng([8, 0]), size=None, heights=(3.0, 3.5))
    zoomed = render_sample(np.random.default_rng([8, 0]), size=None, heights=(3.0, 3.5), zoom=1.2)
    assert zoomed.camera_height_m == plain.camera_height_m
    assert zoomed.focal_px == pytest.approx(1.2 * plain.focal_px)
    assert zoomed.image.shape[0] > 1.15 * plain.image.shape[0]  # the whole frame, 1.2 x larger


@pytest.mark.parametrize("frame_px", [256, 700])
def test_a_frame_of_a_camera_s_size_draws_the_same_scene_sharper(frame_px: int) -> None:
    """``frame_px``: the frame a camera's sensor gives, the same people where they were, scaled."""
    plain = render_sample(np.random.default_rng([9, 0]), size=None, heights=(3.0, 4.0), min_pixels=30)
    sized = render_sample(np.random.default_rng([9, 0]), size=None, heights=(3.0, 4.0), min_pixels=30, frame_px=frame_px)
    k = frame_px / plain.image.shape[1]
    assert sized.image.shape[:2] == (frame_px, frame_px)
    assert sized.camera_height_m == plain.camera_height_m
    assert sized.focal_px == pytest.approx(k * plain.focal_px)
    assert plain.xyxy is not None and sized.xyxy is not None and len(plain.xyxy) > 2
    # Each person of the plain frame is boxed in the sharp one where the enlargement puts them.
    near = np.abs(sized.xyxy[None, :, :] - k * plain.xyxy[:, None, :]).max(axis=2).min(axis=1)
    assert np.all(near < 2.5 * k)
