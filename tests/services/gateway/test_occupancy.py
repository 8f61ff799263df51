"""The occupancy level of a count against the crowded level and the capacity."""

from __future__ import annotations

import pytest

from bevflow_services.gateway.occupancy import level_of


@pytest.mark.parametrize(
    ("count", "crowded", "capacity", "level"),
    [(0, None, None, "unknown"), (3, 4, 5, "normal"), (4, 4, 5, "crowded"), (5, 4, 5, "crowded"), (6, 4, 5, "over_capacity"),
     (9, None, 10, "normal"), (2, 2, None, "crowded")],
)
def test_level_of(count, crowded, capacity, level) -> None:
    assert level_of(count, crowded, capacity) == level
