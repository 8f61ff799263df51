"""The coverage planner: the usable-range rule, the layout search, the site file and the map."""

from __future__ import annotations

import doctest
import math

import numpy as np
import pytest

import bevflow.planning
from bevflow.planning import CameraPlan, PlanError, coverage_map, plan_layout, usable_radius
from bevflow.remap import BevGrid
from bevflow.site import dump_site, parse_site
from bevflow.sim.presets import demo_hall


@pytest.mark.parametrize(
    ("ceiling", "fov", "expected"),
    [
        (3.3, 185.0, 3.7),  # paper: 3.5 m (Table 1, in a 7 m wide room)
        (5.5, 185.0, 8.0),  # paper: 8 m
        (8.1, 185.0, 10.0),  # paper: 10 m (the cap; the width rule alone gives 13.1 m)
        (4.0, 185.0, 5.1),
        (5.5, 120.0, 6.5),  # heads at the rim must lie within 60 degrees: tan(60) x 3.8 m
        (3.0, 90.0, 1.3),
    ],
)
def test_usable_radius(ceiling: float, fov: float, expected: float) -> None:
    assert usable_radius(ceiling, fov) == expected


def test_the_width_rule_holds_at_the_rim() -> None:
    """At the radius, a person's tangential width is 56 % of the width at the centre (equidistant lens)."""
    for ceiling in (3.3, 4.5, 5.5, 6.5):
        d, D = usable_radius(ceiling), ceiling - 1.4
        assert math.atan(d / D) / (d / D) >= 0.56 > math.atan((d + 0.1) / D) / ((d + 0.1) / D)


@pytest.mark.parametrize(("ceiling", "fov", "message"), [(2.5, 185.0, "3 to 10 m"), (11.0, 185.0, "3 to 10 m"), (5.0, 30.0, "field of view")])
def test_usable_radius_refuses(ceiling: float, fov: float, message: str) -> None:
    with pytest.raises(PlanError, match=message):
        usable_radius(ceiling, fov)


def test_the_demo_hall_is_what_the_planner_proposes() -> None:
    """demo_hall(): 40 x 25 m, nine 5.5 m fisheyes with 8 m circles. The planner finds the same 3 x 3
    grid; the preset's hand-typed y rows (4.2, 12.5, 20.8) are the cell centres rounded to 0.1 m."""
    plan = plan_layout(40.0, 25.0, 5.5, 185.0)
    hall = demo_hall().site
    assert (plan.cols, plan.rows, plan.radius_m) == (3, 3, 8.0)
    assert [c.monitored_radius_m for c in hall.cameras] == [plan.radius_m] * 9
    demo_xy = np.array([c.pose.position[:2] for c in hall.cameras])
    np.testing.assert_allclose(demo_xy, plan.positions, atol=0.04)
    assert all(c.pose.position[2] == 5.5 for c in hall.cameras)


@pytest.mark.parametrize(
    ("width", "depth", "ceiling", "overlap", "grid"),
    [
        (10.0, 6.0, 5.5, 1.0, (1, 1)),  # one camera's circle holds the whole room
        (40.0, 25.0, 5.5, 1.0, (3, 3)),  # 4 x 2 misses the cell corners by 4 mm
        (40.0, 25.0, 5.5, 3.0, (5, 2)),  # 3 columns overlap by only 2.67 m
        (13.4, 7.0, 3.3, 1.0, (3, 2)),
        (100.0, 3.0, 4.0, 1.0, (11, 1)),  # a corridor: one row
    ],
)
def test_layouts(width: float, depth: float, ceiling: float, overlap: float, grid: tuple[int, int]) -> None:
    plan = plan_layout(width, depth, ceiling, overlap_m=overlap)
    assert (plan.cols, plan.rows) == grid
    assert plan.margin_m >= 0
    assert all(o is None or o >= overlap for o in plan.neighbour_overlap_m)
    # Fewer cameras would not do: every smaller grid misses a corner or the overlap.
    for cols in range(1, plan.cols * plan.rows):
        for rows in range(1, (plan.cols * plan.rows - 1) // cols + 1):
            smaller = CameraPlan(width, depth, ceiling, 185.0, plan.radius_m, overlap, cols, rows)
            assert smaller.margin_m < 0 or any(o is not None and o < overlap for o in smaller.neighbour_overlap_m)


def test_every_floor_point_is_covered() -> None:
    plan = plan_layout(23.0, 17.0, 4.2)
    count = plan.coverage(BevGrid((0.0, 0.0, 23.0, 17.0), 0.1))
    assert count.min() >= 1 and count.max() >= 2


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [({"width_m": 0.0}, "positive"), ({"overlap_m": -1.0}, "0 m or more"), ({"overlap_m": 20.0}, "whole circle")],
)
def test_plan_refuses(kwargs: dict, message: str) -> None:
    args = {"width_m": 20.0, "depth_m": 10.0, "ceiling_m": 5.5, **kwargs}
    with pytest.raises(PlanError, match=message):
        plan_layout(**args)


def test_site_file_round_trips_and_cameras_look_down() -> None:
    plan = plan_layout(30.0, 20.0, 5.5)
    site = parse_site(dump_site(plan.to_site("hall-a", (2048, 2048))))
    assert site.site == "hall-a" and site.floor == (0.0, 0.0, 30.0, 20.0)
    assert len(site.cameras) == plan.cols * plan.rows
    for config, (x, y) in zip(site.cameras, plan.positions, strict=True):
        camera = site.camera(config.id)
        np.testing.assert_allclose(camera.center, [x, y, 5.5], atol=1e-3)
        np.testing.assert_allclose(camera.nadir_pixel(), [1023.5, 1023.5], atol=1e-6)  # straight down
        rim = camera.project(np.array([[x + plan.radius_m, y, 1.7]]))  # a head at the rim is in view
        assert camera.in_image(rim).all()
        assert config.monitored_radius_m == plan.radius_m


def test_coverage_map_colours() -> None:
    plan = plan_layout(20.0, 10.0, 3.3)
    image = coverage_map(plan, pixels_per_metre=10.0, margin_m=2.0)
    assert image.ndim == 3 and image.dtype == np.uint8
    grid = BevGrid((-2.0, -2.0, 22.0, 14.0), 0.1)  # the map's own extent (legend strip on top)
    assert image.shape[:2] == grid.size[::-1]
    u, v = np.round(grid.world_to_pixels(np.array([[0.3, 0.3]]))[0]).astype(int)  # a floor corner: one camera
    assert tuple(image[v, u]) == (140, 210, 140)
    mid = (plan.positions[0] + plan.positions[1]) / 2  # between two neighbours: overlap
    u, v = np.round(grid.world_to_pixels(mid[None])[0]).astype(int)
    assert tuple(image[v, u + 3]) == (215, 170, 90)


def test_doctests() -> None:
    assert doctest.testmod(bevflow.planning).failed == 0
