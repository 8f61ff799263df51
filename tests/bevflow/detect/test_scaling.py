from __future__ import annotations

import math

import pytest

from bevflow.detect.scaling import scale_factor, scaled_focal


@pytest.mark.parametrize(
    ("height", "focal", "expected"),
    [
        (3.3, 326.0, 40 * 1.9 / 326.0),
        (5.5, 400.0, 40 * 4.1 / 400.0),
        (10.0, 1000.0, 40 * 8.6 / 1000.0),
        (1.5, 100.0, 40 * 0.5 / 100.0),  # below shoulder height + 0.5 m: clamped depth
    ],
)
def test_scale_factor(height: float, focal: float, expected: float) -> None:
    assert scale_factor(height, focal) == pytest.approx(expected)


@pytest.mark.parametrize("height", [3.0, 5.5, 10.0])
def test_person_at_the_centre_becomes_20_px(height: float) -> None:
    depth = height - 1.4
    # 0.5 m shoulders at depth D span f * 0.5 / D px before scaling.
    focal = 612.0
    assert focal * 0.5 / depth * scale_factor(height, focal) == pytest.approx(20.0)


@pytest.mark.parametrize(("height", "circle"), [(3.0, 200.0), (5.5, 516.0), (10.0, 1080.0)])
def test_image_circle_is_about_126_d(height: float, circle: float) -> None:
    # A 180 degree equidistant lens: circle diameter = 2 f' (pi / 2).
    assert 2 * scaled_focal(height) * math.pi / 2 == pytest.approx(circle, rel=0.01)


@pytest.mark.parametrize("focal", [0.0, -3.0])
def test_focal_must_be_positive(focal: float) -> None:
    with pytest.raises(ValueError, match="positive"):
        scale_factor(3.3, focal)
