"""Tracks that take each camera's views themselves (``TrackerConfig.track_views``): one view per
camera and track, information-weighted updates, births only from the views no track took."""

from __future__ import annotations

import numpy as np
import pytest

from bevflow.camera import Camera, FisheyeCamera, PinholeCamera, rotation_from_ypr
from bevflow.detections import Cylinders
from bevflow.metrics.tracking import score_tracking
from bevflow.tracking.hypotheses import online_tracker
from bevflow.tracking.tracker import Tracker, TrackerConfig
from bevflow.tracking.views import LEFTOVER_LOG_DET, fuse_views, leftover_cost, side_views_only, slot_rows


def _along(axis: int, long_m: float = 0.5, short_m: float = 0.05) -> np.ndarray:
    """A view's covariance long along ``axis`` (its camera's line of sight) and short across it."""
    variances = [short_m**2, short_m**2]
    variances[axis] = long_m**2
    return np.diag(variances)


def _views(*rows: tuple[int, float, float, int], score: float = 1.0) -> Cylinders:
    """Views as (camera, x, y, axis of the line of sight)."""
    camera, x, y, axis = (np.array(column) for column in zip(*rows, strict=True))
    return Cylinders(xy=np.stack([x, y], axis=1), camera=camera.astype(np.int64), score=np.full(len(rows), score),
                     covariance=np.array([_along(int(a)) for a in axis]))  # fmt: skip


def _mean_of_views(views: Cylinders) -> Cylinders:
    """A stand-in for fusion: every view left over is one new person, at their mean, as uncertain
    as the most precise of them."""
    covariance = views.covariance[np.argmin(np.linalg.det(views.covariance))][None] if views.covariance is not None else None
    return Cylinders(xy=views.xy.mean(axis=0, keepdims=True), camera=[-1], score=[1.0], covariance=covariance)


def _tracker(**overrides: object) -> Tracker:
    config = TrackerConfig(track_views=True, activate_hits=1, **overrides)  # type: ignore[arg-type]
    return Tracker(config, fuse=_mean_of_views)


@pytest.mark.parametrize(
    ("xy", "axes", "owner", "expected_xy"),
    [
        pytest.param([[1.0, 2.0]], [0], [0], [[1.0, 2.0]], id="one view"),
        # Each camera is precise across its line of sight: the feet are where the two lines cross.
        pytest.param([[0.3, 0.0], [0.0, 0.3]], [0, 1], [0, 0], [[0.0, 0.0]], id="two cameras at right angles"),
        pytest.param([[0.0, 0.0], [2.0, 2.0]], [0, 0], [1, 0], [[2.0, 2.0], [0.0, 0.0]], id="two tracks"),
    ],
)
def test_views_are_fused_by_their_information(xy, axes, owner, expected_xy) -> None:
    covariance = np.array([_along(a) for a in axes])
    tracks, fused, fused_covariance = fuse_views(np.array(xy), covariance, np.array(owner), n_tracks=3)
    assert tracks.tolist() == sorted(set(owner))
    np.testing.assert_allclose(fused, expected_xy, atol=0.01)
    assert np.all(np.linalg.eigvalsh(fused_covariance) <= np.linalg.eigvalsh(covariance).max(axis=1).max() + 1e-12)


def test_a_pair_at_the_gates_edge_costs_two_leftovers() -> None:
    assert 9.21 + LEFTOVER_LOG_DET == pytest.approx(2 * leftover_cost(9.21))
    assert slot_rows(np.array([0, 2]), np.array([1, 3]), n_cameras=4).tolist() == [1, 11]


@pytest.mark.parametrize(
    ("second_xy", "tracks"),
    [
        # 0.4 m along camera 0's line of sight, where its views are 0.5 m long: the same person.
        pytest.param((0.42, 0.0), 1, id="a second box along the line of sight"),
        # 0.4 m across it, where its views are 0.05 m wide: someone else beside them.
        pytest.param((0.02, 0.4), 2, id="someone beside them"),
    ],
)
def test_a_cameras_second_view_of_a_person_starts_nobody(second_xy: tuple[float, float], tracks: int) -> None:
    """Two cameras see a person at the origin; then camera 0 gives a second view near them. The
    track takes one view of each camera; the second is left over, and starts a track only outside
    the track's gate."""
    tracker = _tracker()
    for k in range(3):
        tracker.update(_views((0, 0.0, 0.0, 0), (1, 0.0, 0.0, 1)), k * 0.25)
    tracker.update(_views((0, 0.02, 0.0, 0), (0, *second_xy, 0), (1, 0.0, 0.01, 1)), 0.75)
    key = int(tracker.tracks().key[0])  # the person's own track, the oldest
    assert tracker.view_keys().tolist() == [key, -1, key]
    assert len(tracker.tracks()) == tracks


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        pytest.param({"track_views": True, "gate_chi2": None}, "gate_chi2", id="no gate"),
    ],
)
def test_config_rejects_views_without_what_they_need(overrides: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        TrackerConfig(**overrides)


def test_views_need_a_fusion_to_start_tracks_and_refuse_fused_detections() -> None:
    with pytest.raises(ValueError, match="fuse"):
        Tracker(TrackerConfig(track_views=True))
    with pytest.raises(ValueError, match="camera >= 0"):
        _tracker().update(Cylinders(xy=[[0.0, 0.0]], camera=[-1]), 0.0)


@pytest.mark.parametrize("hypotheses", [1, 5])
def test_walkers_seen_by_two_cameras_keep_their_ids(hypotheses: int) -> None:
    """Twenty people walking in a 10 m square at 4 fps, each seen by two cameras whose views are
    long along their own line of sight (x for one, y for the other) and noisy along it."""
    rng = np.random.default_rng(3)
    n, fps = 20, 4.0
    xy = rng.uniform(0.0, 10.0, (n, 2))
    velocity = rng.normal(0.0, 0.6, (n, 2))
    tracker = online_tracker(TrackerConfig(track_views=True, hypotheses=hypotheses), fuse=_fuse_nearby)
    gt, found = [], []
    for k in range(40):
        xy = xy + velocity / fps
        views = []
        for camera, axis in ((0, 0), (1, 1)):
            noise = rng.normal(0.0, 0.05, (n, 2))
            noise[:, axis] *= 6.0  # 0.3 m along the line of sight
            views.append(Cylinders(xy=xy + noise, camera=np.full(n, camera), covariance=np.broadcast_to(_along(axis, 0.3), (n, 2, 2))))
        tracks = tracker.update(Cylinders.merge(views), k / fps)
        gt.append((np.arange(n), xy.copy()))
        found.append((tracks.id, tracks.xy))
    scores = score_tracking(gt[3:], found[3:], threshold_m=0.5)
    assert scores.MOTA > 0.97 and scores.IDSW <= 1
    assert scores.APE < 0.1  # each view 0.3 m off along its line of sight, the two fused much less


def _fuse_nearby(views: Cylinders) -> Cylinders:
    """A small stand-in for fusion: views within 0.8 m of the first left are one person."""
    people, left = [], np.ones(len(views), dtype=bool)
    while left.any():
        first = np.flatnonzero(left)[0]
        group = left & (np.linalg.norm(views.xy - views.xy[first], axis=1) < 0.8)
        people.append(views.xy[group].mean(axis=0))
        left &= ~group
    return Cylinders(xy=np.array(people).reshape(-1, 2), camera=np.full(len(people), -1), score=np.ones(len(people)))


def side_camera(tilt_deg: float, yaw_deg: float = 0.0) -> PinholeCamera:
    """A pinhole 3 m up whose optical axis lies ``tilt_deg`` from straight down."""
    rotation = rotation_from_ypr(yaw_deg, tilt_deg, 0.0)
    return PinholeCamera(K=np.array([[800.0, 0.0, 640.0], [0.0, 800.0, 360.0], [0.0, 0.0, 1.0]]), R=rotation,
                         t=-rotation @ np.array([0.0, 0.0, 3.0]), dist=np.zeros(5), image_size=(1280, 720))  # fmt: skip


CEILING = FisheyeCamera.looking_down(position=(0.0, 0.0, 3.3), image_size=(1024, 1024))


@pytest.mark.parametrize(
    ("cameras", "side"),
    [
        pytest.param([side_camera(63, yaw) for yaw in (0, 90, 180, 270)], True, id="four side cameras (CMC2)"),
        pytest.param([side_camera(46)], True, id="just past 45 degrees"),
        pytest.param([side_camera(44)], False, id="just short of 45 degrees"),
        pytest.param([CEILING], False, id="a ceiling fisheye"),
        pytest.param([side_camera(70), CEILING], False, id="side and ceiling cameras"),
        pytest.param([], False, id="no cameras"),
    ],
)
def test_a_site_takes_views_where_every_camera_is_a_side_view(cameras: list[Camera], side: bool) -> None:
    assert side_views_only(cameras) is side
