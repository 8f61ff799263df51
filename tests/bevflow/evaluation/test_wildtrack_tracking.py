from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from bevflow.datasets.wildtrack import ViewBoxes, WildtrackDataset, WildtrackFrame
from bevflow.detections import Boxes, Cylinders
from bevflow.evaluation.detection import evaluate_detection
from bevflow.evaluation.wildtrack_tracking import WILDTRACK_TRACKER, evaluate_tracking, track_and_match
from bevflow.sim.noise import DetectorNoise
from tests.bevflow.datasets.test_wildtrack import fake_cameras, person_box

PERFECT = DetectorNoise(truncation=False)
FRAMES = 8
STARTS = {1: (0.0, -2.0), 2: (0.0, 0.0), 3: (0.0, 2.0)}  # person -> feet at frame 0, walking along +x
HIDDEN = (1, 4)  # (person, frame index): no camera sees them then
GHOST = (2, (6.0, -3.0))  # (frame index, floor point): a box of nobody, in the first camera only


def walkers(step_m: float, hidden: tuple[int, int] | None = HIDDEN, ghost: tuple | None = GHOST) -> WildtrackDataset:
    """Three people walking ``step_m`` per annotated frame (0.5 s apart, frame numbers 0, 5, ...)
    past the two fake cameras, each seen by both; optionally one person hidden in one frame and a
    one-frame false box."""
    cameras = fake_cameras()
    frames = []
    for k in range(FRAMES):
        ids = np.array(list(STARTS), dtype=np.int64)
        feet = np.array([(x + step_m * k, y) for x, y in STARTS.values()])
        views = []
        for cam in cameras:
            seen = [i for i, pid in enumerate(ids) if (int(pid), k) != hidden]
            rows = [person_box(cam, feet[i]) for i in seen]
            view_ids = [int(ids[i]) for i in seen]
            if ghost is not None and k == ghost[0] and cam is cameras[0]:
                rows.append(person_box(cam, np.array(ghost[1])))
                view_ids.append(-1)
            views.append(ViewBoxes(Boxes(xyxy=np.array(rows, dtype=np.float64)), np.array(view_ids, dtype=np.int64)))
        frames.append(WildtrackFrame(frame=5 * k, person_ids=ids, feet_xy=feet, views=tuple(views)))
    return WildtrackDataset(
        root=Path("synthetic"), camera_ids=("CVLab1", "CVLab2"), cameras=tuple(cameras), view_numbers=(0, 1),
        frames=tuple(frames),
    )


@pytest.mark.parametrize(
    ("tracker", "bridged"),
    [
        # nobody is seen where the hidden person stands (no box at all): not reported that frame
        (WILDTRACK_TRACKER, False),
        (dataclasses.replace(WILDTRACK_TRACKER, coast_needs_sighting=False), True),
    ],
)
def test_tracking_bridges_a_hidden_frame_and_rejects_a_one_frame_ghost(tracker, bridged: bool) -> None:  # noqa: ANN001
    result = evaluate_tracking(walkers(0.7), tracker, noise=PERFECT)
    n = 3 * FRAMES
    det = result.detection.scores
    assert (det.tp, det.fp, det.fn) == (n - 1, 1, 1)  # per frame: the hidden person missed, the ghost counted
    s = result.scores
    # tracked: both cameras see each person from the first frame, which confirms their track at
    # once; the hidden frame is bridged by the predicted position 0.5 s on (or the track waits
    # unreported and picks the person up again), and the ghost (one camera, one frame) never
    # becomes a track
    missed = 0 if bridged else 1
    assert (s.tp, s.fp, s.fn, s.IDSW, s.FRAG) == (n - missed, 0, missed, 0, missed)
    assert s.MODA == pytest.approx(1.0 - missed / n) and (s.MT, s.PT, s.ML) == (3, 0, 0) and result.tracks == 3
    # one update late, the hidden frame is bridged either way: the person was found again after it
    late = result.settled
    assert (late.tp, late.fp, late.fn, late.IDSW, late.FRAG) == (n, 0, 0, 0, 0) and late.APE < 0.1


@pytest.mark.parametrize("step_m", [0.0, 0.3, 0.7, 1.0])
def test_one_identity_per_walker_at_two_frames_per_second(step_m: float) -> None:
    s = evaluate_tracking(walkers(step_m, hidden=None, ghost=None), noise=PERFECT).scores
    assert (s.IDSW, s.FRAG, s.fp, s.fn) == (0, 0, 0, 0)
    assert s.IDF1 == 1.0


def test_the_tracker_predicts_with_real_frame_times() -> None:
    # the same frames stamped 10x closer in time: to the tracker people now move 14 m/s, which its
    # motion model does not follow: with a fixed measurement noise it keeps losing them, with each
    # detection's own covariance it keeps them but reports them far behind; with the dataset's
    # times it follows all, closely
    ds = walkers(0.7, hidden=None, ghost=None)
    for measured in (False, True):
        tracker = dataclasses.replace(WILDTRACK_TRACKER, measurement_from_covariance=measured)
        right = evaluate_tracking(ds, noise=PERFECT, tracker=tracker).scores
        wrong = evaluate_tracking(dataclasses.replace(ds, seconds_per_frame_number=0.01), noise=PERFECT, tracker=tracker).scores
        assert (right.fp, right.fn) == (0, 0) and right.APE < 0.1
        if measured:
            assert wrong.APE > 3 * right.APE
        else:
            assert wrong.fn > 10 and wrong.MOTA < 0.5


def test_a_finished_detection_run_is_tracked_as_it_is() -> None:
    ds = walkers(0.7)
    detection = evaluate_detection(ds, noise=PERFECT, frames=slice(2, None))
    result = evaluate_tracking(ds, detection=detection)
    assert result.detection is detection and result.scores.frames == FRAMES - 2
    assert result.tracker == WILDTRACK_TRACKER


def test_as_dict_has_tracking_keys_on_top_and_keeps_detection_moda() -> None:
    result = evaluate_tracking(walkers(0.7), noise=PERFECT)
    d = result.as_dict()
    assert {"MOTA", "IDF1", "IDSW", "MT", "ML", "FRAG", "MODA", "MODP", "APE", "method", "frames"} <= d.keys()
    assert d["MODA"] == result.detection.scores.MODA == pytest.approx(1 - 2 / 24)
    assert d["tracked_MODA"] == d["tracked"]["MODA"] == result.scores.MODA
    assert d["settled"]["MODA"] == result.settled.MODA and {"MOTA", "IDF1", "fp", "fn"} <= d["settled"].keys()
    assert d["IDSW"] == 0 and d["tracker"]["activate_hits"] == 2 and d["seconds_per_frame_number"] == 0.1


def test_tracks_outside_the_area_count_only_when_they_match_someone() -> None:
    ids, xy = np.array([1]), np.array([[0.0, 0.0]])
    fused = [Cylinders(xy=np.array([[0.1, 0.0], [-5.0, 0.0]]), camera=np.array([0, 1]))] * 3  # one view each
    area = dataclasses.replace(walkers(0.0).area, x_min=0.15)  # the person's own track lies just outside
    _, hyp = track_and_match([(ids, xy)] * 3, fused, [0.0, 0.5, 1.0], area, WILDTRACK_TRACKER)
    assert [len(h[0]) for h in hyp] == [0, 1, 1]  # confirmed from the 2nd frame; the far track never scored
    np.testing.assert_allclose(hyp[2][1], [[0.1, 0.0]], atol=1e-9)
    _, late = track_and_match([(ids, xy)] * 3, fused, [0.0, 0.5, 1.0], area, WILDTRACK_TRACKER, settled=True)
    assert [h[0].tolist() for h in late] == [[1], [1], [1]]  # its first frame too, under the id it got


@pytest.mark.parametrize(
    ("call", "error"),
    [
        (lambda ds: evaluate_tracking(ds, detection=evaluate_detection(ds, noise=PERFECT), noise=PERFECT), TypeError),
        (lambda ds: track_and_match([], [Cylinders.empty()], [0.0], ds.area, WILDTRACK_TRACKER), ValueError),
        (lambda ds: track_and_match([(np.zeros(0, np.int64), np.zeros((0, 2)))], [Cylinders.empty()], [0.0], ds.area,
                                    WILDTRACK_TRACKER, sightings=[]), ValueError),  # fmt: skip
        (lambda ds: evaluate_tracking(ds, detection=dataclasses.replace(evaluate_detection(ds, noise=PERFECT), fused=())), ValueError),
    ],
)
def test_misuse_raises(call, error: type[Exception]) -> None:
    with pytest.raises(error):
        call(walkers(0.7, hidden=None, ghost=None))
