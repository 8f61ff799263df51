from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from bevflow.datasets.wildtrack import FloorArea, ViewBoxes, WildtrackDataset, load_wildtrack
from bevflow.detections import Boxes
from bevflow.evaluation.detection import clip_boxes_to_image, evaluate_detection, noisy_detections, scored_estimates
from bevflow.sim.noise import DetectorNoise, NoisyBoxes
from tests.bevflow.datasets.test_wildtrack import write_fake_wildtrack

PERFECT = DetectorNoise(truncation=False)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> WildtrackDataset:
    # 3 frames x 3 people; camera 0 sees all 9, camera 1 sees 6 (person 9 is hidden from it)
    return load_wildtrack(write_fake_wildtrack(tmp_path_factory.mktemp("wt") / "wildtrack"))


@pytest.mark.parametrize("method", ["cylinder", "nearest-point"])
def test_perfect_boxes_find_everyone_at_the_right_place(dataset: WildtrackDataset, method: str) -> None:
    result = evaluate_detection(dataset, method=method, noise=PERFECT)
    s = result.scores
    assert (s.tp, s.fp, s.fn, s.n_gt) == (9, 0, 0, 9)
    # the fake's boxes bound a 0.5 m wide cylinder, so their bottom edge lies up to 0.25 m
    # nearer the camera than the feet; a unit or pose error would be metres off
    assert s.MODA == 1.0 and s.APE < 0.3
    assert result.frame_numbers == (0, 5, 10) and result.method == method
    # two people are seen by both cameras, one by camera 0 only: 15 cylinders into 9 estimates
    assert result.views_per_estimate == pytest.approx(15 / 9)
    assert [(c.camera_id, c.boxes, c.detections, c.dropped, c.duplicates) for c in result.per_camera] == [
        ("CVLab1", 9, 9, 0, 0),
        ("CVLab2", 6, 6, 0, 0),
    ]
    assert [c.alone.tp for c in result.per_camera] == [9, 6]


def test_dropping_every_box_leaves_only_misses(dataset: WildtrackDataset) -> None:
    result = evaluate_detection(dataset, noise=DetectorNoise(drop=1.0, truncation=False))
    s = result.scores
    assert (s.tp, s.fp, s.fn) == (0, 0, 9)
    assert s.MODA == 0.0 and s.recall == 0.0 and np.isnan(s.APE)
    assert [c.dropped for c in result.per_camera] == [9, 6]


def test_false_positive_boxes_are_counted_per_camera(dataset: WildtrackDataset) -> None:
    noise = DetectorNoise(false_positives=3.0, truncation=False)
    result = evaluate_detection(dataset, method="nearest-point", noise=noise, seed=4)
    expected = [
        sum(int((n.source < 0).sum()) for n in [noisy_detections(dataset, f, noise, 4)[i] for f in dataset.frames])
        for i in range(2)
    ]
    assert [c.false_positives for c in result.per_camera] == expected
    assert sum(expected) > 0
    c = result.per_camera[0]
    assert c.detections == c.boxes + c.false_positives
    assert result.scores.tp == 9  # spurious boxes add estimates, they do not hide people


def test_a_slice_scores_exactly_its_frames_of_the_full_run(dataset: WildtrackDataset) -> None:
    noise = DetectorNoise(jitter=0.05, drop=0.3, false_positives=1.0)
    full = evaluate_detection(dataset, noise=noise, seed=7)
    head = evaluate_detection(dataset, noise=noise, seed=7, frames=slice(0, 1))
    tail = evaluate_detection(dataset, noise=noise, seed=7, frames=slice(1, None))
    assert head.frame_numbers == (0,) and tail.frame_numbers == (5, 10)
    for field in ("tp", "fp", "fn"):
        assert getattr(full.scores, field) == getattr(head.scores, field) + getattr(tail.scores, field)
    assert [c.detections for c in full.per_camera] == [
        a.detections + b.detections for a, b in zip(head.per_camera, tail.per_camera, strict=True)
    ]


def _without_person(dataset: WildtrackDataset, person: int) -> WildtrackDataset:
    """The same boxes, but ``person`` left out of the ground truth (as if standing unannotated)."""
    frames = tuple(
        dataclasses.replace(f, person_ids=f.person_ids[f.person_ids != person], feet_xy=f.feet_xy[f.person_ids != person])
        for f in dataset.frames
    )
    return dataclasses.replace(dataset, frames=frames)


def _boxed_twice(dataset: WildtrackDataset, camera: int) -> WildtrackDataset:
    """The same, but ``camera`` boxing each person twice, the second box 2 px lower."""
    def twice(view: ViewBoxes) -> ViewBoxes:
        again = view.boxes.xyxy + [0, 2, 0, 2]
        return ViewBoxes(Boxes(np.concatenate([view.boxes.xyxy, again])), np.concatenate([view.person_ids] * 2))
    frames = tuple(
        dataclasses.replace(f, views=tuple(twice(v) if i == camera else v for i, v in enumerate(f.views))) for f in dataset.frames
    )
    return dataclasses.replace(dataset, frames=frames)


def test_a_person_boxed_twice_by_one_camera_is_placed_once(dataset: WildtrackDataset) -> None:
    result = evaluate_detection(_boxed_twice(dataset, 0), noise=PERFECT)
    assert (result.scores.tp, result.scores.fp, result.scores.fn) == (9, 0, 0)
    assert [(c.detections, c.duplicates) for c in result.per_camera] == [(18, 9), (6, 0)]
    assert result.views_per_estimate == pytest.approx(15 / 9)


NARROW = FloorArea(-3.0, 2.5, -9.0, 27.0)  # ends 0.5 m before person 8 (x = 3.0 m)


@pytest.mark.parametrize(
    ("area", "annotated", "expected"),
    [
        (None, True, (9, 0, 0)),
        # an estimate just outside the area that matches a person is a person found
        (NARROW, True, (9, 0, 0)),
        # an unannotated person outside the area is neither right nor wrong
        (NARROW, False, (6, 0, 0)),
        # inside the area, an estimate of nobody annotated is a false positive
        (None, False, (6, 3, 0)),
    ],
)
def test_only_estimates_inside_the_area_or_matching_a_person_are_scored(
    dataset: WildtrackDataset, area: FloorArea | None, annotated: bool, expected: tuple[int, int, int]
) -> None:
    case = dataset if annotated else _without_person(dataset, 8)
    if area is not None:
        case = dataclasses.replace(case, area=area)
    result = evaluate_detection(case, noise=PERFECT)
    s = result.scores
    assert (s.tp, s.fp, s.fn) == expected
    assert [c.outside_area for c in result.per_camera] == ([3, 3] if area is NARROW else [0, 0])


@pytest.mark.parametrize(
    ("gt", "est", "expected"),
    [
        ([[0.0, 0.0]], [[-0.3, 0.0], [1.0, 0.0]], [True, True]),  # outside, 0.3 m from a person
        ([[0.0, 0.0]], [[-0.6, 0.0]], [False]),  # outside, beyond the 0.5 m threshold
        ([[0.0, 0.0]], [[0.1, 0.0], [-0.2, 0.0]], [True, False]),  # the person is taken by the nearer one
        ([], [[-0.1, 0.0], [0.5, 0.0]], [False, True]),
    ],
)
def test_scored_estimates_keep_the_area_and_outside_matches(gt: list, est: list, expected: list[bool]) -> None:
    area = FloorArea(0.0, 2.0, -1.0, 1.0)
    keep = scored_estimates(area, np.array(gt).reshape(-1, 2), np.array(est), 0.5)
    assert keep.tolist() == expected


def test_as_dict_puts_the_headline_numbers_on_top(dataset: WildtrackDataset) -> None:
    d = evaluate_detection(dataset, noise=PERFECT, method="cylinder").as_dict()
    assert {"MODA", "MODP", "precision", "recall", "F1", "APE", "method", "frames"} <= d.keys()
    assert d["method"] == "cylinder" and d["frames"] == 3 and d["MODA"] == 1.0
    assert [c["camera_id"] for c in d["per_camera"]] == ["CVLab1", "CVLab2"]


def test_clipping_keeps_boxes_inside_the_image_and_drops_those_outside() -> None:
    noisy = NoisyBoxes(
        boxes=Boxes(xyxy=np.array([[10.0, 10.0, 50.0, 90.0], [-20.0, 30.0, 40.0, 130.0], [200.0, 10.0, 260.0, 60.0]])),
        source=np.array([0, 1, -1]),
        truncated=np.array([False, True, False]),
    )
    clipped, changed = clip_boxes_to_image(noisy, (150, 100))
    np.testing.assert_array_equal(clipped.boxes.xyxy, [[10.0, 10.0, 50.0, 90.0], [0.0, 30.0, 40.0, 100.0]])
    assert clipped.source.tolist() == [0, 1] and clipped.truncated.tolist() == [False, True]
    assert changed == 2


def test_real_wildtrack_slice_runs_when_present() -> None:
    root = Path("/work/shared/data/wildtrack")
    if not root.is_dir():
        pytest.skip("the WILDTRACK dataset is not on this machine")
    ds = load_wildtrack(root)
    result = evaluate_detection(ds, method="nearest-point", noise=PERFECT, frames=slice(0, 3))
    # perfect annotation boxes put each person's bottom centre within centimetres of the truth
    assert result.scores.recall > 0.9 and result.scores.APE < 0.2
