from __future__ import annotations

import numpy as np
import pytest

from bevflow.detections import Boxes
from bevflow.sim.noise import (
    DEFAULT_FALSE_POSITIVE_SIZE,
    DetectorNoise,
    apply_detector_noise,
    side_view_visible_boxes,
    view_rng,
)

IMAGE = (1920, 1080)


def spread_boxes(n: int, seed: int = 0) -> Boxes:
    """n non-overlapping boxes of varied size (truncation has nothing to cut)."""
    rng = np.random.default_rng(seed)
    w = rng.uniform(20, 200, n)
    h = rng.uniform(60, 500, n)
    x0 = np.arange(n) * 250.0
    return Boxes(xyxy=np.stack([x0, np.full(n, 100.0), x0 + w, 100.0 + h], 1))


@pytest.mark.parametrize("jitter", [0.01, 0.02, 0.1])
def test_jitter_moves_each_edge_with_sigma_proportional_to_box_size(jitter: float) -> None:
    boxes = spread_boxes(4000)
    out = apply_detector_noise(boxes, DetectorNoise(jitter=jitter, truncation=False), view_rng(3, 0, 0), IMAGE)
    assert out.source.tolist() == list(range(4000))
    moved = out.boxes.xyxy - boxes.xyxy
    scale = np.stack([boxes.width, boxes.height, boxes.width, boxes.height], 1)
    measured = (moved / scale).std(axis=0)
    # 4000 samples: the std of a std estimate is sigma/sqrt(2n) ~ 1.1 %
    np.testing.assert_allclose(measured, jitter, rtol=0.05)
    assert np.abs((moved / scale).mean(axis=0)).max() < 4 * jitter / np.sqrt(4000)


@pytest.mark.parametrize("drop", [0.0, 0.1, 0.5, 1.0])
def test_drop_removes_boxes_with_the_given_probability(drop: float) -> None:
    boxes = spread_boxes(50)
    kept = [len(apply_detector_noise(boxes, DetectorNoise(drop=drop), view_rng(1, f, 2), IMAGE).boxes) for f in range(200)]
    rate = 1.0 - np.sum(kept) / (50 * 200)
    tolerance = 4 * np.sqrt(drop * (1 - drop) / (50 * 200)) + 1e-12
    assert abs(rate - drop) <= tolerance


@pytest.mark.parametrize("mean", [0.0, 0.5, 3.0])
def test_false_positives_are_poisson_inside_the_image_with_real_box_sizes(mean: float) -> None:
    boxes = spread_boxes(5)
    sizes = {(round(w, 6), round(h, 6)) for w, h in zip(boxes.width, boxes.height, strict=True)}
    counts = []
    for frame in range(1000):
        out = apply_detector_noise(boxes, DetectorNoise(false_positives=mean, truncation=False), view_rng(0, frame, 1), IMAGE)
        fake = out.boxes[out.source == -1]
        counts.append(len(fake))
        assert np.all(out.source[:5] == np.arange(5))
        assert np.all((fake.xyxy[:, :2] >= 0) & (fake.xyxy[:, 2:] <= IMAGE))
        assert {(round(w, 6), round(h, 6)) for w, h in zip(fake.width, fake.height, strict=True)} <= sizes
    assert abs(np.mean(counts) - mean) <= 4 * np.sqrt(mean / 1000) + 1e-12
    assert abs(np.var(counts) - mean) <= 0.2 * mean + 1e-12  # Poisson: variance = mean


def test_false_positives_in_an_empty_view_use_the_default_size() -> None:
    out = apply_detector_noise(Boxes.empty(), DetectorNoise(false_positives=20.0), view_rng(0, 0, 0), IMAGE)
    assert len(out.boxes) > 0 and np.all(out.source == -1)
    np.testing.assert_allclose(out.boxes.width, DEFAULT_FALSE_POSITIVE_SIZE[0] * IMAGE[1])
    np.testing.assert_allclose(out.boxes.height, DEFAULT_FALSE_POSITIVE_SIZE[1] * IMAGE[1])


def test_same_seed_frame_view_gives_the_same_boxes_and_others_differ() -> None:
    boxes = spread_boxes(30)
    noise = DetectorNoise(jitter=0.05, drop=0.3, false_positives=2.0)

    def run(seed: int, frame: int, view: int) -> np.ndarray:
        return apply_detector_noise(boxes, noise, view_rng(seed, frame, view), IMAGE).boxes.xyxy

    np.testing.assert_array_equal(run(4, 17, 3), run(4, 17, 3))
    for other in [(5, 17, 3), (4, 18, 3), (4, 17, 2)]:
        a, b = run(4, 17, 3), run(*other)
        assert a.shape != b.shape or not np.array_equal(a, b)


def test_one_setting_does_not_reshuffle_the_others_random_numbers() -> None:
    boxes = spread_boxes(40)
    jitter_only = apply_detector_noise(boxes, DetectorNoise(jitter=0.05), view_rng(2, 9, 0), IMAGE)
    with_drop = apply_detector_noise(boxes, DetectorNoise(jitter=0.05, drop=0.5), view_rng(2, 9, 0), IMAGE)
    assert 0 < len(with_drop.boxes) < 40
    np.testing.assert_array_equal(with_drop.boxes.xyxy, jitter_only.boxes.xyxy[with_drop.source])


def test_perfect_detector_returns_the_input() -> None:
    boxes = Boxes(xyxy=np.array([[10.0, 20.0, 50.0, 140.0], [30.0, 40.0, 80.0, 200.0]]), confidence=np.array([0.9, 0.4]))
    out = apply_detector_noise(boxes, DetectorNoise(truncation=False), view_rng(0, 0, 0), IMAGE)
    np.testing.assert_array_equal(out.boxes.xyxy, boxes.xyxy)
    np.testing.assert_array_equal(out.boxes.confidence, boxes.confidence)
    assert out.source.tolist() == [0, 1] and not out.truncated.any()


BACK = [100.0, 100.0, 140.0, 300.0]  # the person farther away: box bottom higher in the image


@pytest.mark.parametrize(
    ("occluders", "expected_bottom"),
    [
        ([], 300.0),
        ([[95.0, 200.0, 145.0, 400.0]], 200.0),  # in front, covers the lower part: cut to its top
        ([[95.0, 200.0, 145.0, 290.0]], 300.0),  # bottom higher than ours: it stands behind
        ([[130.0, 200.0, 170.0, 400.0]], 300.0),  # covers only a quarter of our width
        ([[115.0, 200.0, 170.0, 400.0]], 200.0),  # covers 62.5 % of our width
        ([[95.0, 310.0, 145.0, 400.0]], 300.0),  # starts below our feet: no overlap
        ([[95.0, 50.0, 145.0, 400.0]], 160.0),  # would hide everything: 30 % of the height stays
        ([[95.0, 250.0, 145.0, 400.0], [90.0, 220.0, 150.0, 380.0]], 220.0),  # highest top edge wins
    ],
)
def test_side_view_truncation_cuts_the_feet_edge_at_the_nearer_occluder(occluders: list, expected_bottom: float) -> None:
    boxes = Boxes(xyxy=np.array([BACK, *occluders]))
    visible = side_view_visible_boxes(boxes)
    np.testing.assert_allclose(visible[0], [100.0, 100.0, 140.0, expected_bottom])
    nearest = int(np.argmax(boxes.xyxy[:, 3]))
    np.testing.assert_array_equal(visible[nearest], boxes.xyxy[nearest])  # nobody stands in front of it
    out = apply_detector_noise(boxes, DetectorNoise(), view_rng(0, 0, 0), IMAGE)
    np.testing.assert_allclose(out.boxes.xyxy[0], visible[0])
    assert out.truncated[0] == (expected_bottom != 300.0)


def test_callers_visible_extent_replaces_the_inferred_one() -> None:
    boxes = Boxes(xyxy=np.array([BACK, [95.0, 200.0, 145.0, 400.0]]))
    visible = np.array([[100.0, 100.0, 130.0, 250.0], [95.0, 200.0, 145.0, 400.0]])
    out = apply_detector_noise(boxes, DetectorNoise(), view_rng(0, 0, 0), IMAGE, visible=visible)
    np.testing.assert_array_equal(out.boxes.xyxy, visible)
    assert out.truncated.tolist() == [True, False]
    off = apply_detector_noise(boxes, DetectorNoise(truncation=False), view_rng(0, 0, 0), IMAGE, visible=visible)
    np.testing.assert_array_equal(off.boxes.xyxy, boxes.xyxy)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"jitter": -0.1}, "jitter"),
        ({"jitter": float("nan")}, "jitter"),
        ({"drop": 1.5}, "drop"),
        ({"drop": -0.01}, "drop"),
        ({"false_positives": -1.0}, "false_positives"),
    ],
)
def test_invalid_settings_are_rejected(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        DetectorNoise(**kwargs)


def test_negative_seed_is_rejected() -> None:
    with pytest.raises(ValueError, match="seed"):
        view_rng(-1, 0, 0)
