from __future__ import annotations

import numpy as np
import pytest

from bevflow.detections import Cylinders
from bevflow.fusion import with_position_covariance
from bevflow.live.site_tracker import SiteTracker
from bevflow.site import Site, parse_site

SITE = """
site: hall
cameras:
  - {id: west, image_size: [1024, 1024], intrinsics: {fx: 300, fy: 300, cx: 511.5, cy: 511.5}, pose: {position: [0, 0, 4]}}
  - {id: east, image_size: [1024, 1024], intrinsics: {fx: 300, fy: 300, cx: 511.5, cy: 511.5}, pose: {position: [6, 0, 4]}}
zones:
  - {id: middle, polygon: [[2, -3], [4, -3], [4, 3], [2, 3]], capacity: 1}
thresholds: {violation_min_duration_s: 1.0, capacity_hysteresis: 0}
"""
S = 1_000_000_000
T0 = 1_700_000_000 * S


@pytest.fixture()
def site():
    return parse_site(SITE)


def holding(site: Site, hypotheses: int, views: bool = False) -> Site:
    """``site`` with its tracker holding ``hypotheses`` ways of matching open, taking the views
    itself or (``views`` False) the fused people."""
    changes = {"track_hypotheses": hypotheses, "track_views": views}
    return site.model_copy(update={"thresholds": site.thresholds.model_copy(update=changes)})


def seen(*xy: tuple[float, float]) -> Cylinders:
    return Cylinders(xy=np.array(xy, dtype=np.float64).reshape(-1, 2))


@pytest.mark.parametrize("views", [True, False], ids=["tracks take the views", "views fused first"])
@pytest.mark.parametrize("hypotheses", [1, 5])
def test_a_person_seen_by_two_cameras_is_one_track_seen_by_both(site, hypotheses: int, views: bool) -> None:
    tracker = SiteTracker(holding(site, hypotheses, views))
    for k in range(4):
        step = tracker.step(T0 + k * S // 10, {"west": seen((3.0, 0.0)), "east": seen((3.1, 0.05))})
    assert [t.cameras for t in step.tracks.tracks] == [["west", "east"]]
    assert len(step.fusion.fused) == 1  # what the tick reports of the instant, either way
    (track,) = step.tracks.tracks
    assert track.xy == pytest.approx((3.05, 0.025), abs=0.05)
    assert track.zones == ["middle"]
    assert step.occupancy.total == 1 and step.occupancy.zones[0].count == 1


def test_two_people_too_close_for_long_enough_raise_one_violation_and_over_capacity(site) -> None:
    tracker = SiteTracker(site)
    events = []
    for k in range(25):  # 2.5 s at 10 Hz, both standing 1 m apart inside a zone of capacity 1
        step = tracker.step(T0 + k * S // 10, {"west": seen((2.5, 0.0), (3.5, 0.0))})
        events += step.events
    types = [e.type for e in events]
    assert types.count("distance_violation") == 1 and types.count("over_capacity") == 1
    violation = next(e for e in events if e.type == "distance_violation")
    assert violation.min_distance_m == pytest.approx(1.0, abs=0.05) and violation.zone == "middle"
    assert step.tracks.violations == [tuple(sorted(violation.tracks))]


@pytest.mark.parametrize("hypotheses", [1, 5])
def test_first_id_continues_a_previous_run(site, hypotheses: int) -> None:
    tracker = SiteTracker(holding(site, hypotheses), first_id=500)
    for k in range(3):
        step = tracker.step(T0 + k * S // 10, {"east": seen((5.0, 1.0))})
    assert [t.id for t in step.tracks.tracks] == [500] and tracker.tracker.next_id == 501


def test_a_tick_without_cameras_is_valid(site) -> None:
    step = SiteTracker(site).step(T0, {})
    assert step.tracks.tracks == [] and step.occupancy.total == 0


def test_cameras_are_listed_in_site_order_whatever_order_they_report_in(site) -> None:
    tracker = SiteTracker(site)
    for k in range(4):
        step = tracker.step(T0 + k * S // 10, {"east": seen((3.1, 0.05)), "west": seen((3.0, 0.0))})
    assert [t.cameras for t in step.tracks.tracks] == [["west", "east"]]
    np.testing.assert_array_equal(step.fusion.assignment, [0, 0])


def test_cylinders_carrying_their_covariance_track_exactly_as_bare_ones(site) -> None:
    rng = np.random.default_rng(5)
    people = rng.uniform([-1.0, -3.0], [7.0, 3.0], (12, 2))
    cameras = [site.camera(c) for c in site.camera_ids]
    bare, carried = SiteTracker(site), SiteTracker(site)
    for k in range(8):
        per_camera = {
            c: Cylinders(xy=people + 0.1 * k + rng.normal(0.0, 0.05, people.shape), camera=np.full(len(people), i),
                         occluded=rng.random(len(people)) < 0.2)
            for i, c in enumerate(site.camera_ids)
        }
        expected = bare.step(T0 + k * S // 10, per_camera)
        got = carried.step(T0 + k * S // 10, {c: with_position_covariance(p, cameras) for c, p in per_camera.items()})
        assert got.tracks == expected.tracks and got.occupancy == expected.occupancy
        np.testing.assert_array_equal(got.fusion.assignment, expected.fusion.assignment)
    assert len(got.tracks.tracks) == len(people)
