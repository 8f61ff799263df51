"""Ready-made sites and crowds: the paper's seven evaluation sequences and a demo hall.

``table1_sequence(n)`` mirrors row n of the paper's Table 1: scenario, cameras and their heights,
monitored radius, frames (at 10 fps, which the paper does not give), identities and occlusion
level. The paper's footage is not public, so the rooms are ours; what Table 1 fixes is kept.

The occlusion level (1–5) is the paper's judgement of a sequence. Here it sets how many static
occluders stand in the monitored area and how close together people walk:

======  ========  ===================  ==============  ===============  ==============
level   pillars   shelves / counters   groups (share)  goal area (×r)   standing still
======  ========  ===================  ==============  ===============  ==============
1       0         0                    0.0             0.85             0.0
2       1         0                    0.2             0.85             0.1
3       1         1                    0.3             0.8              0.15
4       2         1                    0.4             0.7              0.2
5       2         2                    0.5             0.6              0.25
======  ========  ===================  ==============  ===============  ==============

Goals are drawn in discs of that fraction of each camera's monitored radius, so a smaller goal
area crowds the same identities closer together (and closer to the occluders). Pillars reach the
ceiling; shelves are 1.5–1.8 m, counters 1.1 m.

``demo_hall()`` is the live demo's default: a 40 × 25 m hall, nine ceiling fisheyes at 5.5 m with
overlapping 8 m circles, three zones with capacities (gate, corridor, shop), pillars, shelves and
counters, and about 50 people at a time, some in groups. A boarding surge brings 25 more people to
queue at the gate from minute 1 to minute 4 of every ten, so the gate goes over capacity and the
hall crowded, and both end again.

>>> p = table1_sequence(6)
>>> [c.height_m for c in p.site.cameras], p.scene.frames, p.scene.identities
([5.5], 334, 6)
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TypedDict, Unpack

import numpy as np

from bevflow.camera import FisheyeCamera
from bevflow.sim.scene import Door, GoalArea, Obstacles, Pillar, SceneConfig, Shelf
from bevflow.sim.surge import Surge
from bevflow.sim.views import CameraRig, RigOptions
from bevflow.site import CameraConfig, Intrinsics, Pose, Site, Thresholds, Zone

FPS = 10.0
FOV_DEG = 185.0
# A mild, realistic departure from the ideal equidistant lens (k1..k4 of OpenCV's fisheye model):
# the rim is compressed a little, part of the way toward an equisolid lens (k1 = −1/24).
LENS_DISTORTION = (-0.02, 0.0015, 0.0, 0.0)


@dataclass(frozen=True)
class Table1Row:
    scenario: int
    heights_m: tuple[float, ...]
    radius_m: float
    frames: int
    identities: int
    occlusion: int


TABLE1: dict[int, Table1Row] = {
    1: Table1Row(1, (3.3, 3.3), 3.5, 1610, 3, 1),
    2: Table1Row(1, (3.3, 3.3), 3.5, 654, 5, 2),
    3: Table1Row(1, (3.3, 3.3), 3.5, 750, 5, 3),
    4: Table1Row(1, (3.3, 3.3), 3.5, 1083, 4, 4),
    5: Table1Row(1, (3.3, 3.3), 3.5, 837, 5, 5),
    6: Table1Row(2, (5.5,), 8.0, 334, 6, 2),
    7: Table1Row(3, (8.1,), 10.0, 578, 13, 4),
}

# level → (pillars, shelves, group fraction, goal-area radius factor, standing fraction)
OCCLUSION_LEVELS: dict[int, tuple[int, int, float, float, float]] = {
    1: (0, 0, 0.0, 0.85, 0.0),
    2: (1, 0, 0.2, 0.85, 0.1),
    3: (1, 1, 0.3, 0.8, 0.15),
    4: (2, 1, 0.4, 0.7, 0.2),
    5: (2, 2, 0.5, 0.6, 0.25),
}


class SceneChanges(TypedDict, total=False):
    """The scene settings ``Preset.with_scene`` changes."""

    frames: int | None
    seed: int
    people: int | None
    identities: int | None


@dataclass(frozen=True)
class Preset:
    """A site (cameras, zones) and the crowd that walks in it. ``sequence`` is the Table 1 row
    it mirrors, if any."""

    name: str
    site: Site
    scene: SceneConfig
    sequence: int | None = None
    scenario: int | None = None
    occlusion_level: int | None = None

    def obstacles(self) -> Obstacles:
        return Obstacles(self.scene.pillars, self.scene.shelves)

    def rig(self, **options: Unpack[RigOptions]) -> CameraRig:
        """The cameras of the site looking at the scene's obstacles."""
        return CameraRig.from_site(self.site, self.obstacles(), **options)

    def with_scene(self, **changes: Unpack[SceneChanges]) -> Preset:
        """The same preset with some scene settings changed (e.g. ``frames=50, seed=3``)."""
        return replace(self, scene=replace(self.scene, **changes))


def table1_sequence(number: int, seed: int | None = None) -> Preset:
    """Row ``number`` (1–7) of the paper's Table 1 as a preset; ``seed`` defaults to the row."""
    if number not in TABLE1:
        raise ValueError(f"Table 1 has sequences 1 to 7, not {number}")
    row = TABLE1[number]
    pillars, shelves, groups, goal_factor, standing = OCCLUSION_LEVELS[row.occlusion]
    if row.scenario == 1:
        # Two 3.3 m cameras whose 3.5 m circles overlap by 0.6 m, in a 13.4 × 7 m room.
        centres = [(3.5, 3.5), (9.9, 3.5)]
        floor = (0.0, 0.0, 13.4, 7.0)
        doors: tuple[Door, ...] = (Door(0.0, 3.5, 1.2), Door(13.4, 3.5, 1.2), Door(6.7, 0.0, 1.6))
        pillar_slots = [Pillar(5.0, 2.0, 0.25, row.heights_m[0]), Pillar(8.4, 5.0, 0.25, row.heights_m[0])]
        shelf_slots = [Shelf(10.8, 4.7, 12.4, 5.3, 1.1), Shelf(1.6, 1.6, 3.0, 2.1, 1.5)]
        size = (1280, 1280)
    else:
        r, h = row.radius_m, row.heights_m[0]
        centres = [(r, r)]
        floor = (0.0, 0.0, 2 * r, 2 * r)
        doors = (Door(0.0, r, 1.6), Door(2 * r, r, 1.6), Door(r, 0.0, 1.6), Door(r, 2 * r, 1.6))
        pillar_slots = [Pillar(1.42 * r, 1.2 * r, 0.35, h + 1.0), Pillar(0.7 * r, 0.55 * r, 0.35, h + 1.0)]
        shelf_slots = [Shelf(r - 0.6 * r, r + 0.3 * r, r - 0.6 * r + 2.0, r + 0.3 * r + 0.6, 1.8)]
        size = (2048, 2048)
    cameras = [
        _fisheye(f"cam{i + 1}", (x, y, h), size, yaw_deg=90.0 * i, radius=row.radius_m)
        for i, ((x, y), h) in enumerate(zip(centres, row.heights_m, strict=True))
    ]
    goal_r = goal_factor * row.radius_m
    scene = SceneConfig(
        floor=floor,
        pillars=tuple(pillar_slots[:pillars]),
        shelves=tuple(shelf_slots[:shelves]),
        entries=doors,
        goal_areas=tuple(GoalArea(_disc(c, goal_r)) for c in centres),
        identities=row.identities,
        goals_per_visit=(4, 10),  # long visits and short absences: people are in view most of the time
        absence_s=(3.0, 12.0),
        standing_fraction=standing,
        group_fraction=groups,
        fps=FPS,
        frames=row.frames,
        seed=number if seed is None else seed,
    )
    monitored = Zone(id="monitored", name="monitored area", polygon=_disc_union(centres, row.radius_m))
    site = Site(site=f"seq{number}", cameras=cameras, zones=[monitored], floor=floor)
    return Preset(f"seq{number}", site, scene, sequence=number, scenario=row.scenario, occlusion_level=row.occlusion)


def table1(seed: int | None = None) -> list[Preset]:
    return [table1_sequence(n, seed) for n in TABLE1]


def demo_hall(seed: int = 0, people: int = 50, frames: int | None = None, surge: bool = True) -> Preset:
    """A 40 × 25 m hall watched by nine 5.5 m fisheyes; ``frames`` None runs forever; ``surge``
    False leaves out the boarding surge at the gate."""
    floor = (0.0, 0.0, 40.0, 25.0)
    xs, ys = (40.0 / 6, 20.0, 40.0 - 40.0 / 6), (4.2, 12.5, 20.8)
    cameras = [
        _fisheye(f"hall-{i + 1}", (x, y, 5.5), (1280, 1280), yaw_deg=(37.0 * i) % 360, radius=8.0)
        for i, (y, x) in enumerate((y, x) for y in ys for x in xs)
    ]
    zones = [
        Zone(id="gate", name="Gate", polygon=_rect(0.0, 0.0, 10.0, 9.0), capacity=15),
        Zone(id="corridor", name="Corridor", polygon=_rect(10.0, 9.5, 30.0, 15.5), capacity=25),
        Zone(id="shop", name="Shop", polygon=_rect(27.0, 16.0, 40.0, 25.0), capacity=20),
    ]
    pillars = tuple(Pillar(x, y, 0.4, 7.0) for x in (13.3, 26.7) for y in (8.3, 16.7))
    shelves = (
        Shelf(3.0, 6.0, 7.0, 6.8, 1.1),  # check-in counter at the gate
        Shelf(18.5, 2.5, 21.5, 4.5, 2.2),  # kiosk
        Shelf(29.5, 18.0, 35.5, 18.8, 1.8),  # shop shelves
        Shelf(29.5, 21.5, 35.5, 22.3, 1.8),
        Shelf(37.0, 17.0, 39.2, 17.6, 1.1),  # till
    )
    doors = (Door(0.0, 4.0, 3.0), Door(20.0, 0.0, 2.0), Door(40.0, 8.0, 2.0), Door(20.0, 25.0, 2.0))
    goals = (
        GoalArea(tuple(zones[0].polygon), 2.0),
        GoalArea(tuple(zones[1].polygon), 1.0),
        GoalArea(tuple(zones[2].polygon), 3.0),
        GoalArea(tuple(_rect(0.0, 0.0, 40.0, 25.0)), 0.5),
    )
    scene = SceneConfig(
        floor=floor,
        pillars=pillars,
        shelves=shelves,
        entries=doors,
        goal_areas=goals,
        identities=None,
        people=people,
        standing_fraction=0.15,
        sitting_fraction=0.1,
        group_fraction=0.3,
        fps=FPS,
        frames=frames,
        seed=seed,
        surges=(Surge(60.0, 240.0, tuple(zones[0].polygon), extra=people // 2, every_s=600.0, share=0.25),) if surge else (),
    )
    site = Site(site="demo-hall", cameras=cameras, zones=zones, floor=floor, thresholds=Thresholds(site_capacity=80, capacity_min_duration_s=5.0))
    return Preset("demo-hall", site, scene)


PRESETS: dict[str, Callable[[], Preset]] = {
    **{f"seq{n}": functools.partial(table1_sequence, n) for n in TABLE1},
    "demo-hall": demo_hall,
}


def preset(name: str) -> Preset:
    """A preset by name: ``seq1`` … ``seq7`` or ``demo-hall``."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of: {', '.join(PRESETS)}")
    return PRESETS[name]()


def _fisheye(
    camera_id: str, position: tuple[float, float, float], size: tuple[int, int], yaw_deg: float, radius: float
) -> CameraConfig:
    cam = FisheyeCamera.looking_down(position, size, FOV_DEG, yaw_deg, LENS_DISTORTION)
    # looking_down sizes the image circle for an ideal lens; with the distortion, the rim at
    # FOV/2 lands at θd(FOV/2), so scale f to put it on the edge of the shorter image side.
    half = math.radians(FOV_DEG / 2)
    K = cam.K.copy()
    K[0, 0] = K[1, 1] = K[0, 0] * half / float(cam.distort_theta(np.array(half)))
    return CameraConfig(
        id=camera_id,
        model="fisheye",
        image_size=size,
        intrinsics=Intrinsics(fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2]),
        distortion=list(LENS_DISTORTION),
        pose=Pose(position=position, yaw_deg=yaw_deg),
        monitored_radius_m=radius,
    )


def _rect(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float]]:
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]


def _disc(centre: tuple[float, float], radius: float, sides: int = 48) -> tuple[tuple[float, float], ...]:
    a = np.linspace(0.0, 2 * math.pi, sides, endpoint=False)
    return tuple((centre[0] + radius * math.cos(t), centre[1] + radius * math.sin(t)) for t in a)


def _disc_union(centres: list[tuple[float, float]], radius: float, sides: int = 96) -> list[tuple[float, float]]:
    """Outline of a union of overlapping discs, star-shaped about their mean centre (true for the
    rows of cameras used here): boundary points outside the other discs, sorted by angle."""
    c = np.asarray(centres, dtype=np.float64)
    pts = np.concatenate([np.asarray(_disc(tuple(ci), radius, sides)) for ci in c])
    outside = (np.linalg.norm(pts[:, None] - c[None], axis=-1) >= radius - 1e-9).all(1)
    pts = pts[outside]
    mid = c.mean(0)
    order = np.argsort(np.arctan2(pts[:, 1] - mid[1], pts[:, 0] - mid[0]))
    return [(float(x), float(y)) for x, y in pts[order]]
