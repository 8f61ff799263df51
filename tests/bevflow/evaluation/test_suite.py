from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from bevflow.detections import Boxes, Cylinders
from bevflow.evaluation.suite import (
    DEFAULT_NOISE,
    SimulatedSequence,
    SuiteResult,
    SuiteRow,
    camera_sets,
    detect,
    ground_truth,
    hidden_share,
    paper_presets,
    run_suite,
    scored_tracks,
    simulate,
    track,
    unseen_share,
)
from bevflow.evaluation.tables import format_suite, format_table2, format_table3
from bevflow.metrics.tracking import score_tracking
from bevflow.sim.noise import DetectorNoise
from bevflow.sim.presets import table1_sequence
from bevflow.site import MONITORED_EDGE_MARGIN_M
from bevflow.sim.views import CameraRig, CameraView

PAPER_KEYS = {"seq", "cameras", "method", "MOTA", "MT", "PT", "ML", "FRAG", "FRAG_ratio", "P", "R", "F1", "APE", "IDF1"}


# --- a hand-made sequence: one camera of seq6 (5.5 m up, 8 m circle centred at (8, 8)) -------------
def hand_made(feet_per_frame: list[list[tuple[float, float]]], ids_per_frame: list[list[int]]) -> SimulatedSequence:
    preset = table1_sequence(6)
    camera = preset.site.camera("cam1")
    views = []
    for feet, ids in zip(feet_per_frame, ids_per_frame, strict=True):
        xy = np.asarray(feet, dtype=np.float64).reshape(-1, 2)
        px = camera.project(np.column_stack([xy, np.zeros(len(xy))]))
        boxes = Boxes(xyxy=np.column_stack([px - 20.0, px + 20.0]).reshape(-1, 4))
        n = len(xy)
        views.append([CameraView(0, boxes, np.asarray(ids, np.int64), np.ones(n), np.zeros(n, bool), xy)])
    times = [k * 100_000_000 for k in range(len(feet_per_frame))]
    ids = [np.asarray(i, np.int64) for i in ids_per_frame]
    feet = [np.asarray(f, np.float64).reshape(-1, 2) for f in feet_per_frame]
    return SimulatedSequence(preset, times, ids, feet, views)


def seq6_rig() -> CameraRig:
    preset = table1_sequence(6)
    return CameraRig([preset.site.camera("cam1")], [8.0])


@pytest.mark.parametrize(
    ("number", "expected"),
    [(1, [("cam1", "cam2"), ("cam1",), ("cam2",)]), (5, [("cam1", "cam2"), ("cam1",), ("cam2",)]), (6, [("cam1",)]), (7, [("cam1",)])],
)
def test_camera_sets_are_all_cameras_then_each_alone(number: int, expected: list[tuple[str, ...]]) -> None:
    assert camera_sets(table1_sequence(number)) == expected


@pytest.mark.parametrize(
    ("scale", "expected"),
    [(1.0, [1610, 654, 750, 1083, 837, 334, 578]), (0.1, [161, 65, 75, 108, 84, 33, 58]), (1e-6, [1, 1, 1, 1, 1, 1, 1])],
)
def test_frames_scale_shortens_every_sequence(scale: float, expected: list[int]) -> None:
    assert [p.scene.frames for p in paper_presets(scale)] == expected


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"name": "papers"}, "unknown suite"),
        ({"frames_scale": 0.0}, "frames_scale"),
        ({"frames_scale": math.nan}, "frames_scale"),
        ({"methods": ["centre"]}, "methods"),
        ({"methods": []}, "methods"),
        ({"seed": -1}, "seed"),
        ({"sequences": [8]}, "1 to 7"),
    ],
)
def test_bad_settings_raise_one_clear_error(kwargs: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        run_suite(**{"name": "paper", "frames_scale": 0.01, **kwargs})


def test_ground_truth_counts_a_return_to_the_area_as_a_new_track() -> None:
    # Person 7 walks out of the 8 m circle (centre (8, 8)) and back; person 9 stays inside.
    seq = hand_made(
        [[(8.0, 8.0), (9.0, 9.0)], [(17.0, 8.0), (9.0, 9.0)], [(8.5, 8.0), (9.0, 9.0)]],
        [[7, 9], [7, 9], [7, 9]],
    )
    gt = ground_truth(seq, seq6_rig())
    assert [ids.tolist() for ids, _ in gt] == [[1, 2], [2], [3, 2]]
    assert gt[1][1].tolist() == [[9.0, 9.0]]


def boxed_first_only(view: CameraView, in_sight: list[int]) -> CameraView:
    """``view`` with only its first person boxed, and ``in_sight`` the people the camera can see."""
    return CameraView(0, view.boxes[:1], view.person_ids[:1], view.visible_fraction[:1], view.lower_occluded[:1],
                      view.feet_xy[:1], in_sight_ids=np.asarray(in_sight, np.int64))  # fmt: skip


def test_unseen_share_counts_people_in_sight_that_no_camera_boxes() -> None:
    seq = hand_made([[(8.0, 8.0), (9.0, 9.0)], [(8.0, 8.0)]], [[1, 2], [1]])
    # Person 2 is in sight in frame 0 but too hidden for a box: 1 of the 3 person-frames is unseen.
    seq = replace(seq, views=[[boxed_first_only(seq.views[0][0], [1, 2])], seq.views[1]])
    assert unseen_share(seq, seq6_rig(), [0]) == pytest.approx(1 / 3)
    assert hidden_share(seq, seq6_rig(), [0]) == 0.0


@pytest.mark.parametrize(
    ("in_sight", "gt_ids", "hidden"),
    [
        ([1, 2], [[1, 2], [1, 2], [1, 2]], 0.0),  # partly hidden (no box) but in sight: counted
        ([1], [[1, 2], [1], [1, 2]], 1 / 6),  # wholly hidden in frame 1: left out, keeps its track id
    ],
)
def test_ground_truth_holds_only_people_in_sight_of_a_camera(in_sight: list[int], gt_ids: list[list[int]], hidden: float) -> None:
    seq = hand_made([[(8.0, 8.0), (9.0, 9.0)]] * 3, [[1, 2]] * 3)
    seq = replace(seq, views=[seq.views[0], [boxed_first_only(seq.views[1][0], in_sight)], seq.views[2]])
    assert [ids.tolist() for ids, _ in ground_truth(seq, seq6_rig(), [0])] == gt_ids
    assert hidden_share(seq, seq6_rig(), [0]) == pytest.approx(hidden)
    assert unseen_share(seq, seq6_rig(), [0]) == pytest.approx(0.0 if len(in_sight) == 1 else 1 / 6)


def test_the_simulator_reports_people_too_hidden_for_a_box_as_in_sight() -> None:
    (preset,) = paper_presets(0.1, [5])
    seq = simulate(preset)
    boxed = sum(len(v.person_ids) for views in seq.views for v in views)
    in_sight = sum(len(v.in_sight_ids) for views in seq.views for v in views)
    for views in seq.views:
        for v in views:
            assert set(v.person_ids.tolist()) <= set(v.in_sight_ids.tolist())
    assert in_sight > boxed  # seq5 (occlusion 5) has people glimpsed but under a quarter visible


def test_cameras_report_people_up_to_their_reporting_radius_as_the_projector_keeps_them() -> None:
    (preset,) = paper_presets(0.1, [1])
    seq = simulate(preset)
    centres = [preset.site.camera(c).center[:2] for c in preset.site.camera_ids]
    reach = [float(np.linalg.norm(v.feet_xy - centres[v.camera_index], axis=1).max()) for views in seq.views for v in views if len(v)]
    radius = preset.site.cameras[0].monitored_radius_m
    assert radius < max(reach) <= radius + MONITORED_EDGE_MARGIN_M


# seq6's circle: centre (8, 8), radius 8 m, so x = 0 is its left edge
@pytest.mark.parametrize(
    ("track_x", "inside_x", "outside_x", "scored"),
    [
        (4.0, [], [], True),  # inside, nobody there: a false positive
        (0.1, [], [-0.1], False),  # inside, of someone just outside the edge: not annotated
        (-0.1, [0.1], [], True),  # outside, of someone just inside: found
        (-0.3, [], [], False),  # outside, nobody there: nobody annotated it
        (-0.3, [], [-0.2], False),
        (0.05, [0.3], [-0.1], False),  # of the nearer person, who stands outside
        (0.05, [0.1], [-0.3], True),
    ],
)
def test_tracks_are_scored_inside_the_area_and_where_they_match_someone_inside(
    track_x: float, inside_x: list[float], outside_x: list[float], scored: bool
) -> None:
    gt = (np.arange(len(inside_x)), np.array([[x, 8.0] for x in inside_x]).reshape(-1, 2))
    hyp = (np.array([7]), np.array([[track_x, 8.0]]))
    ids, xy = scored_tracks(seq6_rig(), gt, hyp, np.array([[x, 8.0] for x in outside_x]).reshape(-1, 2))
    assert ids.tolist() == ([7] if scored else []) and len(xy) == len(ids)


def test_perfect_detections_of_one_walker_miss_only_the_frames_before_the_track_is_confirmed() -> None:
    frames = 20
    feet = [[(6.0 + 0.12 * k, 8.0)] for k in range(frames)]  # 1.2 m/s across the circle
    seq = hand_made(feet, [[4]] * frames)
    cylinders = [[Cylinders(xy=np.asarray(f))] for f in feet]
    hyp = track(seq, ["cam1"], cylinders)
    scores = score_tracking(ground_truth(seq, seq6_rig()), hyp)
    # The tracker confirms a track on its 3rd detection (the paper's rule): frames 0 and 1 are misses.
    assert [len(ids) for ids, _ in hyp[:4]] == [0, 0, 1, 1]
    assert (scores.fn, scores.fp, scores.IDSW) == (2, 0, 0)
    assert scores.MOTA == pytest.approx(1 - 2 / frames)


def test_detect_draws_the_noise_once_per_camera_and_frame() -> None:
    (preset,) = paper_presets(0.02, [1])
    seq = simulate(preset)
    clean = detect(seq, DetectorNoise(), 0, ["bbox-center", "cylinder"])
    lost = detect(seq, DetectorNoise(drop=1.0), 0, ["cylinder"])
    boxes = sum(len(v.boxes) for views in seq.views for v in views)
    assert boxes > 0
    assert sum(len(c) for per_frame in clean["cylinder"].cylinders for c in per_frame) == boxes
    assert sum(len(c) for per_frame in lost["cylinder"].cylinders for c in per_frame) == 0
    # Every method places the same boxes: one error per box of a real person, in the same order.
    for c in range(2):
        assert len(clean["cylinder"].box_error[c]) == len(clean["bbox-center"].box_error[c]) == len(clean["cylinder"].box_truth[c])
    # The cylinder is the better feet estimate: the box centre lies far outward from a 3.3 m ceiling.
    assert np.nanmean(clean["cylinder"].box_error[0]) < 0.5 * np.nanmean(clean["bbox-center"].box_error[0])


@pytest.fixture(scope="module")
def small_run() -> SuiteResult:
    return run_suite("paper", frames_scale=0.03, sequences=[2, 6])


def test_rows_come_in_sequence_camera_set_method_order(small_run: SuiteResult) -> None:
    keys = [(r.seq, r.cameras, r.method) for r in small_run.rows]
    methods = ["cylinder", "bbox-center", "nearest-point"]
    expected = [(2, cams, m) for cams in [("cam1", "cam2"), ("cam1",), ("cam2",)] for m in methods]
    assert keys == expected + [(6, ("cam1",), m) for m in methods]


def test_records_hold_the_paper_columns_with_mt_pt_ml_as_fractions(small_run: SuiteResult) -> None:
    payload = json.loads(json.dumps(small_run.as_dict()))
    assert payload["noise"] == {"jitter": 0.03, "drop": 0.05, "false_positives": 0.02, "truncation": True}
    for record, row in zip(payload["rows"], small_run.rows, strict=True):
        assert PAPER_KEYS <= record.keys()
        assert record["cameras"] == list(row.cameras)
        assert record["MT"] + record["PT"] + record["ML"] == pytest.approx(1.0)
        assert record["MT"] == pytest.approx(row.scores.MT / row.scores.n_gt_ids)
        assert 0 <= record["P"] <= 1 and 0 <= record["R"] <= 1 and 0 <= record["APE"] <= 0.5


def test_same_seed_same_rows_other_seed_other_noise(small_run: SuiteResult) -> None:
    again = run_suite("paper", frames_scale=0.03, sequences=[6])
    other = run_suite("paper", frames_scale=0.03, sequences=[6], seed=5)
    first = [r.record() for r in small_run.rows if r.seq == 6]
    assert [r.record() for r in again.rows] == first
    assert [r.record() for r in other.rows] != first


def test_parallel_run_gives_the_serial_rows(small_run: SuiteResult) -> None:
    parallel = run_suite("paper", frames_scale=0.03, sequences=[2, 6], processes=2)
    assert [r.record() for r in parallel.rows] == [r.record() for r in small_run.rows]


def test_the_default_noise_is_the_issue_s() -> None:
    assert DEFAULT_NOISE == DetectorNoise(jitter=0.03, drop=0.05, false_positives=0.02, truncation=True)


# --- tables -----------------------------------------------------------------------------------------
def fake_row(seq: int, cameras: tuple[str, ...], method: str, mota: float, box_ape: float) -> SuiteRow:
    scores = score_tracking([(np.array([1]), np.array([[0.0, 0.0]]))], [(np.array([1]), np.array([[0.1, 0.0]]))])
    return SuiteRow(seq, cameras, method, replace(scores, MOTA=mota), box_ape=box_ape, unseen=0.0)


def test_table2_lists_the_cylinder_rows_only() -> None:
    rows = [fake_row(3, ("cam1", "cam2"), "cylinder", 0.987, 0.1), fake_row(3, ("cam1", "cam2"), "bbox-center", 0.123, 0.5)]
    text = format_table2(rows)
    assert "0.987" in text and "0.123" not in text
    assert "cam1+cam2" in text.splitlines()[2]


def test_table3_puts_the_methods_side_by_side_with_the_box_error_ratio() -> None:
    rows = [fake_row(4, ("cam2",), m, 0.9, ape) for m, ape in (("cylinder", 0.1), ("bbox-center", 0.45), ("nearest-point", 0.2))]
    line = format_table3(rows).splitlines()[-1]
    assert line.split()[:2] == ["4", "cam2"]
    assert line.split()[-4:] == ["0.450", "0.200", "0.100", "4.5"]


def test_format_suite_states_the_noise() -> None:
    result = SuiteResult("paper", (fake_row(6, ("cam1",), "cylinder", 1.0, 0.1),), DEFAULT_NOISE, 0, 0.5)
    head = format_suite(result).splitlines()[0]
    assert "x0.5" in head and "jitter 0.03" in head and "drop 0.05" in head and "false positives 0.02" in head
