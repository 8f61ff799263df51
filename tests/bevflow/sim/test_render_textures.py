"""Looks of the renders: where a tiled floor's grout lines lie, and that shifting them is a draw of
its own, added after every other one."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from bevflow.sim.render_textures import RenderStyle


@pytest.mark.parametrize(
    ("origin", "on_grout", "inside_tile"),
    [((0.0, 0.0), (0.0, 0.3), (0.3, 0.3)),
     ((0.25, 0.1), (0.25, 0.3), (0.0, 0.3)),
     ((0.25, 0.1), (0.4, 0.1), (0.4, 0.4))],
)  # fmt: skip
def test_grout_lines_run_through_the_tile_origin(origin: tuple, on_grout: tuple, inside_tile: tuple) -> None:
    style = replace(RenderStyle.plain(), tile_origin_m=np.array(origin), noise_amount=0.0)
    grout, tile = style.floor_albedo(np.array([on_grout, inside_tile]))
    assert (grout < 0.7 * tile).all(), (grout, tile)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_shifted_grid_changes_the_origin_and_nothing_else(seed: int) -> None:
    laid = RenderStyle.sample(np.random.default_rng(seed))
    shifted = RenderStyle.sample(np.random.default_rng(seed), shifted_tiles=1.0)
    assert (laid.tile_origin_m == 0).all()
    assert ((0 < shifted.tile_origin_m) & (shifted.tile_origin_m < shifted.tile_size_m)).all()
    for name in ("floor_kind", "tile_size_m", "grout_m", "gamma", "jpeg_quality"):
        assert getattr(laid, name) == getattr(shifted, name), name
    np.testing.assert_array_equal(laid.floor_colors, shifted.floor_colors)


def test_no_shift_draws_nothing_more() -> None:
    rng_plain, rng_zero = np.random.default_rng(5), np.random.default_rng(5)
    RenderStyle.sample(rng_plain)
    RenderStyle.sample(rng_zero, shifted_tiles=0.0)
    assert rng_plain.random() == rng_zero.random()
