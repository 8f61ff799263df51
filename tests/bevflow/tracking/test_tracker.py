"""The world tracker on scripted scenes: crossings, hand-over, activation, retirement, clutter,
variable time steps, id bookkeeping, and a thousand walkers scored with bevflow.metrics."""

from __future__ import annotations

import numpy as np
import pytest

from bevflow.camera import Camera
from bevflow.detections import Cylinders
from bevflow.metrics.matching import match_positions
from bevflow.metrics.tracking import score_tracking
from bevflow.site import Thresholds
from bevflow.tracking.tracker import Tracker, TrackerConfig, TrackTable
from tests.bevflow.tracking.test_views import CEILING, side_camera


def _run(tracker: Tracker, frames: list[Cylinders], times: list[float]) -> list[TrackTable]:
    return [tracker.update(cyl, t) for cyl, t in zip(frames, times, strict=True)]


def _ids_per_person(gt_xy: np.ndarray, outputs: list[TrackTable]) -> list[set[int]]:
    """For each person (gt_xy: frames × people × 2), the ids of the tracks matched to them."""
    seen: list[set[int]] = [set() for _ in range(gt_xy.shape[1])]
    for xy, tracks in zip(gt_xy, outputs, strict=True):
        person, track, _ = match_positions(xy, tracks.xy, 0.5)
        for p, t in zip(person, track, strict=True):
            seen[p].add(int(tracks.id[t]))
    return seen


# --- people moving --------------------------------------------------------------------------


@pytest.mark.parametrize("fps", [10.0, 2.0])
@pytest.mark.parametrize(
    ("start_a", "velocity_a", "start_b", "velocity_b"),
    [
        # Paths crossing at right angles; B passes the crossing point 0.4 s after A.
        pytest.param((-5.0, 0.0), (1.3, 0.0), (0.0, -5.72), (0.0, 1.3), id="right-angle"),
        # Head-on, passing shoulder to shoulder 0.6 m apart.
        pytest.param((-6.0, 0.0), (1.3, 0.0), (6.0, 0.6), (-1.3, 0.0), id="head-on"),
        # Shallow X: the paths meet at 20 degrees, 0.3 s apart.
        pytest.param((-6.0, -1.06), (1.3, 0.23), (-6.4, 1.13), (1.3, -0.23), id="shallow-x"),
    ],
)
def test_two_people_crossing_keep_their_ids(fps, start_a, velocity_a, start_b, velocity_b) -> None:
    times = np.arange(0, 10, 1 / fps)
    a = np.array(start_a) + times[:, None] * velocity_a
    b = np.array(start_b) + times[:, None] * velocity_b
    rng = np.random.default_rng(0)
    truth = np.stack([a, b], axis=1)
    detected = truth + rng.normal(0, 0.05, truth.shape)
    outputs = _run(Tracker(), [Cylinders(xy=xy) for xy in detected], times.tolist())
    assert _ids_per_person(truth, outputs) == [{1}, {2}]
    scores = score_tracking([(np.array([0, 1]), xy) for xy in truth], [(t.id, t.xy) for t in outputs])
    assert scores.IDSW == 0 and scores.FRAG == 0


@pytest.mark.parametrize("fps", [10.0, 2.0])
def test_person_walking_between_cameras_keeps_one_id(fps: float) -> None:
    # Camera 0 covers x < 6, camera 1 covers x > 4: fused (-1) in the overlap, and a blind spot
    # just after it where nobody sees the person for three frames.
    times = np.arange(0, 10, 1 / fps)
    xy = np.stack([times * 1.2, np.full_like(times, 2.0)], axis=1)
    camera = np.where(xy[:, 0] < 4, 0, np.where(xy[:, 0] <= 6, -1, 1))
    first_blind = int(np.argmax(xy[:, 0] > 6))
    blind = np.isin(np.arange(len(times)), [first_blind, first_blind + 1, first_blind + 2])
    frames = [
        Cylinders.empty() if hidden else Cylinders(xy=p[None], camera=[c])
        for p, c, hidden in zip(xy, camera, blind, strict=True)
    ]
    outputs = _run(Tracker(), frames, times.tolist())
    assert {i for t in outputs for i in t.id.tolist()} == {1}
    # Reported from its third detection on, through the first blind frame (coasting), back after.
    reported = [len(t) for t in outputs]
    assert reported == [0, 0] + [1] * (first_blind - 1) + [0, 0] + [1] * (len(times) - first_blind - 3)


@pytest.mark.parametrize("activate_hits", [1, 3, 5])
def test_track_is_reported_after_activate_hits_detections(activate_hits: int) -> None:
    tracker = Tracker(TrackerConfig(activate_hits=activate_hits))
    counts = [len(tracker.update(Cylinders(xy=[[0.1 * k, 0.0]]), 0.1 * k)) for k in range(8)]
    assert counts == [0] * (activate_hits - 1) + [1] * (9 - activate_hits)
    assert tracker.tracks().id.tolist() == [1]


@pytest.mark.parametrize(
    ("confirm_multi_view", "camera", "expected"),
    [
        (False, -1, [0, 0, 1, 1]),  # the paper's rule: three hits, however many cameras
        (True, -1, [1, 1, 1, 1]),  # fused from several cameras: confirmed at once
        (True, 2, [0, 0, 1, 1]),  # one camera alone still needs three hits
    ],
)
def test_multi_view_detections_may_confirm_a_track_at_once(confirm_multi_view: bool, camera: int, expected: list[int]) -> None:
    tracker = Tracker(TrackerConfig(confirm_multi_view=confirm_multi_view))
    counts = [len(tracker.update(Cylinders(xy=[[0.1 * k, 0.0]], camera=[camera]), 0.5 * k)) for k in range(4)]
    assert counts == expected


@pytest.mark.parametrize(
    ("measured", "variance_m2", "follows"),
    [
        (True, 0.01, True),  # a precise detection (σ 0.1 m) is followed closely
        (True, 1.0, False),  # an imprecise one (σ 1 m) hardly moves the track
        (False, 0.01, False),  # off: every detection gets the fixed measurement_std_m (0.2 m)
        (True, np.nan, False),  # unknown: the fixed one too
    ],
)
def test_each_detection_may_update_with_its_own_covariance(measured: bool, variance_m2: float, follows: bool) -> None:
    tracker = Tracker(TrackerConfig(activate_hits=1, measurement_from_covariance=measured))
    tracker.update(Cylinders(xy=[[0.0, 0.0]]), 0.0)
    jumped = tracker.update(Cylinders(xy=[[0.5, 0.0]], covariance=[np.eye(2) * variance_m2]), 0.1)
    moved = float(jumped.xy[0, 0])
    assert (moved > 0.4) == follows and 0.0 < moved < 0.5


@pytest.mark.parametrize(("max_misses", "report_max_misses"), [(5, 1), (3, 0), (1, 0), (5, 4)])
def test_track_is_retired_after_max_misses(max_misses: int, report_max_misses: int) -> None:
    tracker = Tracker(TrackerConfig(max_misses=max_misses, report_max_misses=report_max_misses))
    for k in range(4):
        tracker.update(Cylinders(xy=[[0.1 * k, 0.0]]), 0.1 * k)
    alive, reported = [], []
    for k in range(4, 12):
        reported.append(len(tracker.update(Cylinders.empty(), 0.1 * k)))
        alive.append(len(tracker.tracks()))
    assert alive == [1] * (max_misses - 1) + [0] * (9 - max_misses)
    assert reported == [1] * min(report_max_misses, max_misses - 1) + [0] * (8 - min(report_max_misses, max_misses - 1))


def test_coasting_track_moves_on_and_is_picked_up_again() -> None:
    tracker = Tracker()
    for k in range(10):
        last = tracker.update(Cylinders(xy=[[1.0 * 0.1 * k, 0.0]]), 0.1 * k)
    assert last.velocity[0, 0] == pytest.approx(1.0, abs=0.15)
    coasting = tracker.update(Cylinders.empty(), 1.0)
    assert coasting.misses.tolist() == [1] and coasting.detection.tolist() == [-1]
    np.testing.assert_allclose(coasting.xy, last.xy + 0.1 * last.velocity)  # predicted on
    back = tracker.update(Cylinders(xy=[[1.1, 0.0]]), 1.1)
    assert back.id.tolist() == [1] and back.misses.tolist() == [0] and back.detection.tolist() == [0]


def _sighting(xy: list[float], along: list[float], along_m: float = 3.0, across_m: float = 0.1) -> Cylinders:
    """One sighting at ``xy`` whose line of sight runs along ``along`` (a unit vector)."""
    u = np.asarray(along, dtype=float)
    n = np.array([-u[1], u[0]])
    covariance = along_m**2 * np.outer(u, u) + across_m**2 * np.outer(n, n)
    return Cylinders(xy=[xy], score=[0.0], camera=[0], covariance=covariance[None])


@pytest.mark.parametrize(
    ("needs_sighting", "sighting", "reported"),
    [
        (False, None, True),  # the default: one coasting update is reported
        (True, None, False),  # nobody seen there: the person has gone
        (True, _sighting([1.5, 0.0], [1.0, 0.0]), True),  # 1.5 m off, but along the line of sight
        (True, _sighting([0.0, 1.5], [1.0, 0.0]), False),  # 1.5 m off across it
        (True, _sighting([6.0, 0.0], [1.0, 0.0]), True),  # within 3 σ along it
        (True, _sighting([12.0, 0.0], [1.0, 0.0]), False),
    ],
)
def test_a_coasting_track_may_need_a_sighting_to_be_reported(needs_sighting: bool, sighting: Cylinders | None, reported: bool) -> None:
    tracker = Tracker(TrackerConfig(activate_hits=1, coast_needs_sighting=needs_sighting))
    for k in range(3):
        tracker.update(Cylinders(xy=[[0.0, 0.0]]), 0.1 * k)
    out = tracker.update(Cylinders.empty(), 0.3, sighting)
    assert len(out) == int(reported)
    assert len(tracker.tracks()) == 1  # reported or not, the track lives on


def test_sightings_without_a_covariance_are_refused() -> None:
    tracker = Tracker(TrackerConfig(activate_hits=1, coast_needs_sighting=True))
    tracker.update(Cylinders(xy=[[0.0, 0.0]]), 0.0)
    with pytest.raises(ValueError, match="covariance"):
        tracker.update(Cylinders.empty(), 0.1, Cylinders(xy=[[0.0, 0.0]]))


def test_false_positives_that_appear_once_never_become_tracks() -> None:
    tracker = Tracker()
    reported: set[int] = set()
    for k in range(40):
        person = [[0.1 * k, 0.0]]
        # Five spurious cylinders a frame, each 10 m from every other one, past or present.
        clutter = [[100.0 + 10 * k, 10.0 * j] for j in range(5)]
        tracks = tracker.update(Cylinders(xy=np.array(person + clutter), score=[0.9] + [1.0] * 5), 0.1 * k)
        reported.update(tracks.id.tolist())
    assert reported == {1}
    assert tracker.next_id == 2
    assert len(tracker.tracks(include_tentative=True)) <= 1 + 2 * 5  # clutter dies within two frames


def test_weak_detections_continue_a_track_but_never_start_one() -> None:
    config = TrackerConfig(weak_score=0.5, weak_gate_m=0.5)
    tracker = Tracker(config)
    for k in range(4):
        tracker.update(Cylinders(xy=[[0.1 * k, 0.0]], score=[0.9]), 0.1 * k)
    # A weak detection on the person, and a weak one alone 20 m away, repeatedly.
    for k in range(4, 10):
        tracks = tracker.update(Cylinders(xy=[[0.1 * k, 0.0], [20.0, 20.0]], score=[0.2, 0.2]), 0.1 * k)
        assert tracks.id.tolist() == [1] and tracks.detection.tolist() == [0] and tracks.misses.tolist() == [0]
    # A weak detection outside the weak gate (but inside the strong one) is not taken.
    tracks = tracker.update(Cylinders(xy=[[1.0 + 0.8, 0.0]], score=[0.2]), 1.0)
    assert tracks.misses.tolist() == [1]
    assert len(tracker.tracks(include_tentative=True)) == 1


def test_ignores_cylinders_without_a_position_or_below_min_score() -> None:
    tracker = Tracker(TrackerConfig(activate_hits=1, min_score=0.3))
    tracks = tracker.update(Cylinders(xy=[[np.nan, np.nan], [1.0, 1.0], [5.0, 5.0]], score=[1.0, 1.0, 0.1]), 0.0)
    assert tracks.detection.tolist() == [1]


# --- time -----------------------------------------------------------------------------------


def test_variable_time_steps_follow_the_true_motion() -> None:
    rng = np.random.default_rng(3)
    times = np.cumsum(rng.choice([0.05, 0.1, 0.3, 0.5, 0.7], size=40))
    velocity = np.array([1.1, -0.6])
    truth = np.array([2.0, 3.0]) + times[:, None] * velocity
    outputs = _run(Tracker(), [Cylinders(xy=p[None]) for p in truth], times.tolist())
    assert {i for t in outputs for i in t.id.tolist()} == {1}
    final = outputs[-1]
    np.testing.assert_allclose(final.velocity[0], velocity, atol=0.05)
    np.testing.assert_allclose(final.xy[0], truth[-1], atol=0.02)
    assert final.age_s[0] == pytest.approx(times[-1] - times[0])


def test_repeated_time_is_a_zero_step() -> None:
    tracker = Tracker(TrackerConfig(activate_hits=1))
    tracker.update(Cylinders(xy=[[1.0, 1.0]]), 5.0)
    tracks = tracker.update(Cylinders(xy=[[1.0, 1.0]]), 5.0)
    assert tracks.hits.tolist() == [2] and tracks.age_s.tolist() == [0.0]
    np.testing.assert_allclose(tracks.xy, [[1.0, 1.0]])
    assert np.isfinite(tracks.velocity).all()


@pytest.mark.parametrize(
    ("times", "message"),
    [
        pytest.param([1.0, 0.5], "time went backwards", id="backwards"),
        pytest.param([float("nan")], "finite", id="nan"),
        pytest.param([0.0, float("inf")], "finite", id="inf"),
    ],
)
def test_rejects_bad_times(times: list[float], message: str) -> None:
    tracker = Tracker()
    with pytest.raises(ValueError, match=message):
        for t in times:
            tracker.update(Cylinders(xy=[[0.0, 0.0]]), t)


# --- ids and state --------------------------------------------------------------------------


def _confirm_people(tracker: Tracker, xy: list[list[float]], t0: float) -> TrackTable:
    for k in range(tracker.config.activate_hits):
        tracks = tracker.update(Cylinders(xy=xy), t0 + 0.1 * k)
    return tracks


def test_ids_stay_unique_across_reset_and_continue_from_first_id() -> None:
    tracker = Tracker(first_id=100)
    assert _confirm_people(tracker, [[0, 0], [5, 5]], 0.0).id.tolist() == [100, 101]
    tracker.reset()
    assert len(tracker.tracks()) == 0 and tracker.time_s is None
    assert _confirm_people(tracker, [[0, 0]], 0.0).id.tolist() == [102]  # time may restart after reset
    restarted = Tracker(first_id=tracker.next_id)
    assert _confirm_people(restarted, [[0, 0]], 50.0).id.tolist() == [103]
    assert _confirm_people(Tracker(), [[0, 0]], 0.0).id.tolist() == [1]  # no state shared between trackers


def test_track_table_columns() -> None:
    tracker = Tracker(TrackerConfig(activate_hits=2, shape_smoothing=0.5))
    tracker.update(Cylinders(xy=[[9.0, 9.0], [0.0, 0.0]], height=[1.8, 1.6], radius=[0.3, 0.4]), 0.0)
    seen = Cylinders(xy=[[0.1, 0.0], [9.0, 9.1], [30.0, 30.0]], height=[1.7, 1.8, 1.5], radius=[0.2, 0.3, 0.3])
    tracks = tracker.update(seen, 0.5)
    order = np.argsort(tracks.detection)
    tracks = tracks[order]
    assert tracks.detection.tolist() == [0, 1]  # the third cylinder only started a tentative track
    assert tracks.id.tolist() == [2, 1]  # ids follow the order the tracks were born
    np.testing.assert_allclose(tracks.height, [1.65, 1.8])
    np.testing.assert_allclose(tracks.radius, [0.3, 0.3])
    assert tracks.hits.tolist() == [2, 2] and tracks.misses.tolist() == [0, 0]
    assert tracks.confirmed.all() and tracks.age_s.tolist() == [0.5, 0.5]
    everything = tracker.tracks(include_tentative=True)
    assert sorted(everything.id.tolist()) == [-1, 1, 2] and everything.confirmed.sum() == 2


def test_published_tables_do_not_change_afterwards() -> None:
    tracker = Tracker(TrackerConfig(activate_hits=1))
    first = tracker.update(Cylinders(xy=[[0.0, 0.0]]), 0.0)
    everything = tracker.tracks(include_tentative=True)
    tracker.update(Cylinders(xy=[[0.1, 0.0]]), 0.1)
    assert first.hits.tolist() == [1] and everything.hits.tolist() == [1]
    assert first.xy.tolist() == [[0.0, 0.0]]


def test_empty_table() -> None:
    table = TrackTable.empty()
    assert len(table) == 0 and table.xy.shape == (0, 2)
    assert len(Tracker().update(Cylinders.empty(), 0.0)) == 0


# --- configuration --------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        pytest.param({"gate_m": 0.0}, "gate_m", id="gate"),
        pytest.param({"activate_hits": 0}, "activate_hits", id="activate"),
        pytest.param({"max_misses": 0}, "max_misses", id="misses"),
        pytest.param({"measurement_std_m": -1.0}, "measurement_std_m", id="noise"),
        pytest.param({"shape_smoothing": 1.5}, "shape_smoothing", id="smoothing"),
        pytest.param({"report_max_misses": -1}, "report_max_misses", id="report"),
        pytest.param({"sighting_gate_chi2": 0.0}, "sighting_gate_chi2", id="sighting"),
        pytest.param({"lost_speed_mps": 0.0}, "lost_speed_mps", id="lost speed"),
    ],
)
def test_config_rejects_bad_values(overrides: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        TrackerConfig(**overrides)


def test_config_from_site_thresholds() -> None:
    thresholds = Thresholds(track_activate_hits=4, track_max_misses=7, track_gate_m=2.0, track_views=True)
    config = TrackerConfig.from_thresholds(thresholds, weak_score=0.4)
    assert (config.activate_hits, config.max_misses, config.gate_m, config.weak_score) == (4, 7, 2.0, 0.4)
    assert config.track_views and not TrackerConfig.from_thresholds(Thresholds()).track_views


SIDE = [side_camera(63, yaw) for yaw in (0, 120, 240)]


@pytest.mark.parametrize(
    ("track_views", "cameras", "views", "coasting_reported"),
    [
        pytest.param(None, SIDE, True, 0, id="unset, side cameras: views"),
        pytest.param(None, [CEILING], False, 1, id="unset, a ceiling camera: fused first"),
        pytest.param(None, [*SIDE, CEILING], False, 1, id="unset, side and ceiling: fused first"),
        pytest.param(False, SIDE, False, 1, id="false wins over side cameras"),
        pytest.param(True, [CEILING], True, 0, id="true wins over a ceiling camera"),
    ],
)
def test_config_takes_views_by_the_cameras_unless_the_site_says(
    track_views: bool | None, cameras: list[Camera], views: bool, coasting_reported: int
) -> None:
    config = TrackerConfig.from_thresholds(Thresholds(track_views=track_views), cameras)
    assert (config.track_views, config.report_max_misses) == (views, coasting_reported)
    assert TrackerConfig.from_thresholds(Thresholds(track_views=track_views), cameras, report_max_misses=2).report_max_misses == 2


# --- a crowd --------------------------------------------------------------------------------


def _walkers(n: int, fps: float, seconds: float, density: float, seed: int) -> np.ndarray:
    """Positions (frames, n, 2) of people walking at 1–1.6 m/s with slowly turning headings."""
    rng = np.random.default_rng(seed)
    side = np.sqrt(n / density)
    dt = 1 / fps
    xy = rng.uniform(0, side, (n, 2))
    heading = rng.uniform(0, 2 * np.pi, n)
    speed = rng.uniform(1.0, 1.6, n)
    frames = []
    for _ in range(int(seconds * fps)):
        frames.append(xy.copy())
        heading += rng.normal(0, 0.3 * np.sqrt(dt), n)
        xy = xy + dt * speed[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    return np.array(frames)


@pytest.mark.parametrize(
    ("n", "fps", "seconds", "density"),
    [
        pytest.param(1000, 10.0, 6.0, 0.02, id="1000-people-10fps"),
        pytest.param(300, 2.0, 20.0, 0.02, id="300-people-2fps"),  # 0.5-0.8 m between frames
    ],
)
def test_crowd_of_walkers_is_tracked_almost_perfectly(n: int, fps: float, seconds: float, density: float) -> None:
    truth = _walkers(n, fps, seconds, density, seed=7)
    rng = np.random.default_rng(8)
    tracker = Tracker()
    gt_frames, hyp_frames = [], []
    for k, xy in enumerate(truth):
        tracks = tracker.update(Cylinders(xy=xy + rng.normal(0, 0.05, xy.shape)), k / fps)
        gt_frames.append((np.arange(n), xy))
        hyp_frames.append((tracks.id, tracks.xy))
    warmup = tracker.config.activate_hits - 1  # nobody can be reported before their third detection
    scores = score_tracking(gt_frames[warmup:], hyp_frames[warmup:], threshold_m=0.5)
    assert scores.MOTA > 0.995
    assert scores.IDSW <= n * 0.002
    assert scores.MT == n and scores.APE < 0.08  # detections are 5 cm off, 6 cm on average
    assert len(np.unique(np.concatenate([h[0] for h in hyp_frames]))) <= n * 1.002


# --- the Mahalanobis gate ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("gate_chi2", "id_at_b"),
    [(9.21, 2), (None, 1)],
    ids=["gated by the prediction's uncertainty", "gated by distance alone"],
)
def test_a_track_whose_person_was_missed_does_not_take_a_neighbours_detection(gate_chi2, id_at_b) -> None:
    """A (track 1) stands at x = 0 and B (track 2) at x = 0.8; in the last update A is missed and
    a third person C appears at 1.6. By distance alone A's track takes B's detection and B's track
    C's (two pairs under 1.5 m cost less than a track and a detection left over); within the
    tracks' uncertainty neither pair is possible, and C gets a track of their own."""
    tracker = Tracker(TrackerConfig(activate_hits=1, gate_chi2=gate_chi2, measurement_std_m=0.1))
    for k in range(10):
        tracker.update(Cylinders(xy=[[0.0, 0.0], [0.8, 0.0]]), k * 0.25)
    last = tracker.update(Cylinders(xy=[[0.8, 0.0], [1.6, 0.0]]), 2.5)
    assert last.id[last.detection == 0].tolist() == [id_at_b]


@pytest.mark.parametrize(
    ("gate_chi2", "taken"),
    [(9.21, 1), (None, 0)],
    ids=["costed by likelihood", "costed by distance"],
)
def test_a_vague_view_beside_a_person_does_not_take_their_track(gate_chi2, taken) -> None:
    """A person seen precisely (σ 0.05 m) stands at the origin. Then two detections: theirs,
    0.12 m off and as precise, and 0.08 m off a ghost: one camera's second box of them, 0.3 m
    deep along that camera's line of sight (y). By distance the ghost is nearer; by likelihood the
    person's own detection wins: a vague detection is about as likely anywhere in its wide
    ellipse, so lying near the prediction earns it little."""
    tracker = Tracker(TrackerConfig(activate_hits=1, gate_chi2=gate_chi2))
    seen = Cylinders(xy=[[0.0, 0.0]], covariance=[0.05**2 * np.eye(2)])
    for k in range(10):
        tracker.update(seen, k * 0.25)
    ghost_and_person = Cylinders(xy=[[0.0, 0.08], [0.12, 0.0]], covariance=[np.diag([0.1**2, 0.3**2]), 0.05**2 * np.eye(2)])
    last = tracker.update(ghost_and_person, 2.5)
    assert last.detection[last.id == 1].tolist() == [taken]


def test_predicted_positions_are_where_the_tracks_will_be_without_moving_them() -> None:
    tracker = Tracker(TrackerConfig(activate_hits=2))
    for k in range(10):
        tracker.update(Cylinders(xy=[[0.1 * k, 0.0]]), 0.1 * k)  # walking along +x at 1 m/s
    tracker.update(Cylinders(xy=[[1.0, 0.0], [5.0, 5.0]]), 1.0)  # and someone new, tentative
    before = tracker.tracks(include_tentative=True).xy.copy()
    confirmed, every = tracker.predicted(1.2), tracker.predicted(1.2, include_tentative=True)
    assert (len(confirmed), len(every)) == (1, 2)
    assert 1.1 < confirmed.xy[0, 0] < 1.3
    assert confirmed.covariance is not None and (np.linalg.eigvalsh(confirmed.covariance) > 0).all()
    np.testing.assert_array_equal(tracker.tracks(include_tentative=True).xy, before)


# --- past the uncertainty gate: what nobody else took ----------------------------------------
PRECISE = 0.02  # m, σ of a very good detector's feet


def _precise(xy: list[list[float]]) -> Cylinders:
    return Cylinders(xy=xy, covariance=np.broadcast_to(PRECISE**2 * np.eye(2), (len(xy), 2, 2)).copy())


@pytest.mark.parametrize(("lost_speed_mps", "ids"), [(2.0, {1}), (None, {1, 2})], ids=["2 m/s", "off"])
def test_a_precisely_seen_person_who_turns_keeps_their_track(lost_speed_mps, ids) -> None:
    """Walking along +x at 1.2 m/s, 4 updates a second, then turning onto +y: the first step after
    the turn lands 0.42 m from the prediction, far outside the uncertainty gate of a track fed
    0.02 m positions. Nobody else is there, so the track takes it within 2 m/s × 0.25 s."""
    tracker = Tracker(TrackerConfig(activate_hits=1, lost_speed_mps=lost_speed_mps))
    path = [[0.3 * k, 0.0] for k in range(12)] + [[3.3, 0.3 * k] for k in range(1, 8)]
    seen = {int(i) for k, xy in enumerate(path) for i in tracker.update(_precise([xy]), k * 0.25).id}
    assert seen == ids


def test_past_the_uncertainty_gate_a_track_takes_no_detection_another_track_took() -> None:
    """A at x = 0 and B at x = 0.4, both still; A is missed. B's detection is 0.4 m from A's
    track, within 2 m/s × 0.25 s, but B's own track takes it first and A's track coasts."""
    tracker = Tracker(TrackerConfig(activate_hits=1))
    for k in range(10):
        tracker.update(_precise([[0.0, 0.0], [0.4, 0.0]]), k * 0.25)
    last = tracker.update(_precise([[0.4, 0.0]]), 2.5)
    assert last.id[last.detection == 0].tolist() == [2]
    assert last.misses[last.id == 1].tolist() == [1]


def _turning_walkers(n: int, fps: float, seconds: float, seed: int) -> np.ndarray:
    """Positions (frames, n, 2) of people 0.05 per m² walking at 1–1.2 m/s who turn by 90° or
    stop for a moment at random, about once every two seconds each."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, np.sqrt(n / 0.05), (n, 2))
    heading = rng.uniform(0, 2 * np.pi, n)
    speed = rng.uniform(1.0, 1.2, n)
    frames = []
    for _ in range(int(seconds * fps)):
        frames.append(xy.copy())
        turn = rng.random(n) < 0.5 / fps
        heading[turn] += rng.choice([-np.pi / 2, np.pi / 2], int(turn.sum()))
        moving = rng.random(n) >= 0.1
        xy = xy + moving[:, None] * speed[:, None] / fps * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    return np.array(frames)


@pytest.mark.parametrize(("lost_speed_mps", "idf1_above", "idf1_below"), [(2.0, 0.9, 1.01), (None, 0.0, 0.5)],
                         ids=["2 m/s", "off"])  # fmt: skip
def test_precisely_seen_walkers_who_turn_and_stop_keep_their_ids(lost_speed_mps, idf1_above, idf1_below) -> None:
    """200 people at 4 fps placed within 0.02 m. With the last pass IDF1 is 0.96–0.98 (seeds 3
    and 5); with the uncertainty gate alone turns and stops give new ids all the time (0.31)."""
    n, fps = 200, 4.0
    truth = _turning_walkers(n, fps, 20.0, seed=3)
    rng = np.random.default_rng(4)
    tracker = Tracker(TrackerConfig(lost_speed_mps=lost_speed_mps))
    gt_frames, hyp_frames = [], []
    for k, xy in enumerate(truth):
        tracks = tracker.update(_precise((xy + rng.normal(0, PRECISE, xy.shape)).tolist()), k / fps)
        gt_frames.append((np.arange(n), xy))
        hyp_frames.append((tracks.id, tracks.xy))
    warmup = tracker.config.activate_hits - 1
    idf1 = score_tracking(gt_frames[warmup:], hyp_frames[warmup:], threshold_m=0.5).IDF1
    assert idf1_above < idf1 < idf1_below
