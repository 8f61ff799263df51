"""Crowd surges: more people, all for one area, for a while; nothing changes outside one."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from bevflow.analytics.zones import points_in_polygons
from bevflow.sim.scene import Door, Scene, SceneConfig
from bevflow.sim.surge import Surge, extra_people, surge_area

CORNER = ((0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0))
HALL = SceneConfig(
    floor=(0.0, 0.0, 16.0, 10.0),
    entries=(Door(0.0, 2.0, 1.5), Door(16.0, 8.0, 1.5)),
    identities=None,
    people=8,
    group_fraction=0.0,
    goals_per_visit=(1, 2),
    absence_s=(1.0, 3.0),
    frames=900,
    seed=3,
)


@pytest.mark.parametrize(
    ("surge", "t", "active"),
    [
        (Surge(10.0, 20.0, CORNER), 9.9, False),
        (Surge(10.0, 20.0, CORNER), 10.0, True),
        (Surge(10.0, 20.0, CORNER), 20.0, False),
        (Surge(10.0, 20.0, CORNER, every_s=30.0), 41.0, True),
        (Surge(10.0, 20.0, CORNER, every_s=30.0), 51.0, False),
    ],
)
def test_a_surge_is_active_in_its_window(surge: Surge, t: float, active: bool) -> None:
    assert surge.active(t) is active
    assert extra_people((surge,), t) == (surge.extra if active else 0)
    assert (surge_area((surge,), t) is surge) is active


@pytest.mark.parametrize(
    "kwargs",
    [
        {"start_s": 20.0, "end_s": 10.0, "area": CORNER},
        {"start_s": 0.0, "end_s": 10.0, "area": CORNER[:2]},
        {"start_s": 0.0, "end_s": 10.0, "area": CORNER, "extra": -1},
        {"start_s": 0.0, "end_s": 10.0, "area": CORNER, "share": 1.5},
        {"start_s": 0.0, "end_s": 10.0, "area": CORNER, "every_s": 5.0},
    ],
)
def test_bad_surges_are_refused(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        Surge(**kwargs)


def in_corner(config: SceneConfig) -> tuple[np.ndarray, np.ndarray]:
    """People present and people in the corner, once a second."""
    present, corner = [], []
    for frame in Scene(config).run():
        if frame.index % 10 == 0:
            present.append(len(frame.person_ids))
            corner.append(int(points_in_polygons(frame.feet_xy, [np.array(CORNER)]).sum()))
    return np.array(present), np.array(corner)


def test_a_surge_fills_its_area_and_empties_again() -> None:
    surge = Surge(10.0, 40.0, CORNER, extra=8, stay_s=(10.0, 20.0))
    present, corner = in_corner(replace(HALL, surges=(surge,)))
    assert present[:10].max() == 8 and present[20:40].max() == 16  # eight more people while it lasts
    assert corner[30:45].max() >= 6 > corner[:10].max()  # they gather in the corner
    assert present[-5:].max() == 8 and corner[-10:].max() <= 2  # and leave after


def test_a_scene_runs_as_before_outside_any_surge() -> None:
    never = Surge(1000.0, 1100.0, CORNER, extra=5)
    plain = [f.feet_xy for f in Scene(HALL).run()]
    with_surge = [f.feet_xy for f in Scene(replace(HALL, surges=(never,))).run()]
    assert all(np.array_equal(a, b) for a, b in zip(plain, with_surge, strict=True))
