from __future__ import annotations

import itertools

import numpy as np
import pytest

from bevflow.camera import FisheyeCamera
from bevflow.sim.presets import OCCLUSION_LEVELS, PRESETS, demo_hall, preset, table1, table1_sequence
from bevflow.sim.scene import Scene
from bevflow.site import dump_site, parse_site

# The paper's Table 1: cameras, heights, radius per camera, frames, identities, occlusion.
TABLE1 = [
    (1, 1, 2, (3.3, 3.3), 3.5, 1610, 3, 1),
    (2, 1, 2, (3.3, 3.3), 3.5, 654, 5, 2),
    (3, 1, 2, (3.3, 3.3), 3.5, 750, 5, 3),
    (4, 1, 2, (3.3, 3.3), 3.5, 1083, 4, 4),
    (5, 1, 2, (3.3, 3.3), 3.5, 837, 5, 5),
    (6, 2, 1, (5.5,), 8.0, 334, 6, 2),
    (7, 3, 1, (8.1,), 10.0, 578, 13, 4),
]


@pytest.mark.parametrize(
    ("seq", "scenario", "n_cams", "heights", "radius", "frames", "identities", "occlusion"), TABLE1
)
def test_sequences_match_table_1(seq, scenario, n_cams, heights, radius, frames, identities, occlusion) -> None:
    p = table1_sequence(seq)
    assert (p.sequence, p.scenario, p.occlusion_level) == (seq, scenario, occlusion)
    assert len(p.site.cameras) == n_cams
    assert [c.height_m for c in p.site.cameras] == pytest.approx(heights)
    assert [c.monitored_radius_m for c in p.site.cameras] == [radius] * n_cams
    assert (p.scene.frames, p.scene.fps, p.scene.identities) == (frames, 10.0, identities)
    assert p.scene.seed == seq and table1_sequence(seq, seed=99).scene.seed == 99


@pytest.mark.parametrize("seq", [1, 2, 3, 4, 5])
def test_camera_pairs_overlap_a_little(seq: int) -> None:
    a, b = table1_sequence(seq).site.built_cameras.values()
    gap = np.linalg.norm(a.center[:2] - b.center[:2])
    assert 2 * 3.5 - 1.0 < gap < 2 * 3.5  # circles of 3.5 m overlapping by less than a metre


@pytest.mark.parametrize("p", [*table1(), demo_hall()], ids=lambda p: p.name)
def test_cameras_are_downward_fisheyes_with_real_sensors(p) -> None:
    for config, cam in zip(p.site.cameras, p.site.built_cameras.values(), strict=True):
        assert isinstance(cam, FisheyeCamera)
        assert config.image_size in [(1280, 1280), (2048, 2048)]
        assert np.abs(cam.dist).max() < 0.05  # small departure from equidistant
        np.testing.assert_allclose(cam.nadir_pixel(), (np.array(config.image_size) - 1) / 2, atol=1e-6)
        # The lens sees 185° and its image circle fills the sensor: 92.5° off the axis is the rim.
        rim = np.radians(92.5)
        side = np.array([[np.sin(rim), 0.0, np.cos(rim)]])
        radius = np.linalg.norm(cam.project_directions(side)[0] - cam.nadir_pixel())
        assert radius == pytest.approx(min(config.image_size) / 2, abs=0.5)


def test_occlusion_levels_add_occluders_and_crowding() -> None:
    counts = []
    for seq in (1, 2, 3, 4, 5):  # one scenario, levels 1 to 5
        scene = table1_sequence(seq).scene
        counts.append((len(scene.pillars) + len(scene.shelves), scene.group_fraction))
        level = OCCLUSION_LEVELS[seq]
        assert (len(scene.pillars), len(scene.shelves)) == level[:2]
    assert counts[0] == (0, 0.0)
    assert all(a <= b for a, b in itertools.pairwise(counts))
    assert counts[-1][0] >= 3


@pytest.mark.parametrize("p", [*table1(), demo_hall()], ids=lambda p: p.name)
def test_obstacles_stand_on_the_floor_and_sites_round_trip(p) -> None:
    x0, y0, x1, y1 = p.scene.floor
    assert p.site.floor == p.scene.floor
    for pillar in p.scene.pillars:
        assert x0 < pillar.x < x1 and y0 < pillar.y < y1
    for shelf in p.scene.shelves:
        assert x0 <= shelf.x0 < shelf.x1 <= x1 and y0 <= shelf.y0 < shelf.y1 <= y1
    again = parse_site(dump_site(p.site))
    assert again == p.site


@pytest.mark.parametrize("seq", range(1, 8))
def test_every_sequence_runs_and_its_cameras_see_people(seq: int) -> None:
    p = table1_sequence(seq).with_scene(frames=15)
    rig = p.rig()
    seen = 0
    for frame in Scene(p.scene).run():
        assert len(frame) == p.scene.identities  # everyone is inside at the start
        seen += sum(len(v) for v in rig.observe(frame))
    assert seen >= 15  # at least one person a frame on average


def test_demo_hall_is_a_large_hall_with_zones_pillars_and_a_crowd() -> None:
    p = demo_hall(frames=20)
    x0, y0, x1, y1 = p.site.floor
    assert (x1 - x0, y1 - y0) == (40.0, 25.0)
    assert 6 <= len(p.site.cameras) <= 9
    assert all(c.height_m == pytest.approx(5.5) for c in p.site.cameras)
    assert {z.id for z in p.site.zones} == {"gate", "shop", "corridor"}
    assert all(z.capacity for z in p.site.zones)
    assert len(p.scene.pillars) >= 4
    frames = list(Scene(p.scene).run())
    assert all(40 <= len(f) <= 60 for f in frames)
    assert (frames[-1].group >= 0).sum() >= 4  # some walk in groups


def test_every_zone_point_of_the_demo_hall_is_seen_by_a_camera() -> None:
    p = demo_hall()
    cams = list(p.site.built_cameras.values())
    radius = np.array([c.monitored_radius_m for c in p.site.cameras])
    centres = np.array([c.center[:2] for c in cams])
    for zone in p.site.zones:
        poly = np.asarray(zone.polygon)  # rectangles: a grid over the bounds, edges included
        lo, hi = poly.min(0), poly.max(0)
        gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 41), np.linspace(lo[1], hi[1], 41))
        pts = np.stack([gx.ravel(), gy.ravel()], 1)
        within = np.linalg.norm(pts[:, None] - centres[None], axis=-1) <= radius[None]
        assert within.any(1).all(), f"zone {zone.id} has unseen floor"
        for k, cam in enumerate(cams):  # a point in a camera's circle is inside its image
            floor = np.c_[pts[within[:, k]], np.zeros(within[:, k].sum())]
            assert cam.in_image(cam.project(floor)).all()


def test_demo_hall_cameras_overlap_their_neighbours() -> None:
    p = demo_hall()
    centres = np.array([c.center[:2] for c in p.site.built_cameras.values()])
    gaps = np.linalg.norm(centres[:, None] - centres[None], axis=-1) + np.eye(len(centres)) * 1e3
    assert np.all(gaps.min(1) < 2 * 8.0 - 1.0)


def test_presets_by_name() -> None:
    assert set(PRESETS) == {f"seq{n}" for n in range(1, 8)} | {"demo-hall"}
    assert preset("seq3").sequence == 3 and preset("demo-hall").name == "demo-hall"


@pytest.mark.parametrize(
    ("build", "message"),
    [(lambda: preset("seq9"), "unknown preset 'seq9'"), (lambda: table1_sequence(0), "1 to 7")],
)
def test_unknown_presets_are_refused(build, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        build()
