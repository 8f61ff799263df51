from __future__ import annotations

import numpy as np
import pytest

from bevflow.sim.bodies import BodyShape, pose_bodies
from bevflow.sim.render_rays import ray_box, ray_ellipsoids, ray_pillar, trace_bodies
from bevflow.sim.scene import Pillar, Shelf

ORIGIN = np.array([0.0, 0.0, 5.0])
DOWN = np.array([[0.0, 0.0, -1.0]])


@pytest.mark.parametrize(
    ("center", "radii", "expected"),
    [
        ((0.0, 0.0, 1.0), (0.5, 0.5, 0.5), 3.5),  # a ball below: its top
        ((0.0, 0.0, 1.0), (0.3, 0.3, 1.0), 3.0),  # a standing ellipsoid: its top
        ((2.0, 0.0, 1.0), (0.5, 0.5, 0.5), np.inf),  # beside the ray
        ((0.0, 0.0, 6.0), (0.5, 0.5, 0.5), np.inf),  # behind the camera
    ],
)
def test_a_ray_meets_an_ellipsoid_at_its_surface(center: tuple, radii: tuple, expected: float) -> None:
    t = ray_ellipsoids(ORIGIN, DOWN, np.array([center]), np.eye(3)[None], np.array([radii]))
    assert t[0, 0] == pytest.approx(expected)


@pytest.mark.parametrize(
    ("direction", "expected_t", "expected_normal"),
    [
        ((0.0, 0.0, -1.0), 2.0, (0.0, 0.0, 1.0)),  # straight down onto the top
        ((1.0, 0.0, 0.0), 0.6, (-1.0, 0.0, 0.0)),  # sideways into the side
    ],
)
def test_pillar_and_box_hits(direction: tuple, expected_t: float, expected_normal: tuple) -> None:
    d = np.array([direction])
    o = np.array([0.0, 0.0, 5.0]) if direction[2] < 0 else np.array([-1.0, 0.0, 1.0])
    pillar = Pillar(0.0, 0.0, 0.4, 3.0)
    t, normal = ray_pillar(o, d, pillar)
    assert t[0] == pytest.approx(expected_t) and normal[0] == pytest.approx(expected_normal)
    box = Shelf(-0.4, -0.4, 0.4, 0.4, 3.0)
    t, normal, top = ray_box(o, d, box)
    assert t[0] == pytest.approx(expected_t) and normal[0] == pytest.approx(expected_normal)
    assert bool(top[0]) == (direction[2] < 0)


def test_all_bodies_at_once_agree_with_one_body_at_a_time() -> None:
    rng = np.random.default_rng(3)
    n = 5
    bodies = pose_bodies(BodyShape.sample(rng, n), rng.uniform(-2, 2, (n, 2)), rng.uniform(0, 6, n), rng.uniform(0, 6, n),
                         np.full(n, 1.2), np.zeros(n, int))  # fmt: skip
    # 300 rays per body, aimed near it, grouped by body as the renderer sends them.
    who = np.repeat(np.arange(n), 300)
    target = bodies.centers[who, 2] + rng.normal(0, 0.12, (len(who), 3))
    d = target - ORIGIN
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    products = np.stack([d[:, 0] ** 2, d[:, 1] ** 2, d[:, 2] ** 2, d[:, 0] * d[:, 1], d[:, 0] * d[:, 2], d[:, 1] * d[:, 2]], 1)
    t, part = trace_bodies(ORIGIN, d.astype(np.float32), products.astype(np.float32), bodies, who)
    for b in range(n):
        rows = who == b
        ref = ray_ellipsoids(ORIGIN, d[rows], bodies.centers[b], bodies.axes[b], bodies.radii[b])
        hit = np.isfinite(ref.min(1))
        assert hit.sum() > 30
        # float32 may flip a grazing ray; everything else agrees to a millimetre.
        agree = np.isfinite(t[rows]) == hit
        assert agree.mean() > 0.98
        both = hit & np.isfinite(t[rows])
        np.testing.assert_allclose(t[rows][both], ref.min(1)[both], atol=1e-3)
        assert (part[rows][both] == ref.argmin(1)[both]).mean() > 0.98
