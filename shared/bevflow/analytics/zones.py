"""Which zone each person stands in: point-in-polygon for N points against Z zones at once.

The test is the crossing number (even-odd rule), vectorised over the (point, edge) pairs that can
cross, so it handles concave polygons and costs a few passes of numpy arithmetic per tick.

Edge rule (half-open, as in W. R. Franklin's PNPOLY): a point exactly on an edge or vertex is
inside for the edges that bound the polygon from the left or from below, and outside for those
that bound it from the right or from above; the unit square holds [0, 1) x [0, 1). The rule is
what makes zones that tile the floor (sharing edges exactly) count a person on the common
border in exactly one of them, never in both or neither.

>>> points_in_polygons([[0.5, 0.5], [1.0, 0.5]], [[(0, 0), (1, 0), (1, 1), (0, 1)]]).tolist()
[[True], [False]]
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bevflow.analytics.positions import IntArray
from bevflow.site import Zone

BoolArray = NDArray[np.bool_]


class PolygonSet:
    """Z polygons flattened into one edge list, ready for ``contains``.

    Each edge is stored pointing upwards (lower end first), so the crossing test gives the same
    answer whichever way round the polygon is drawn and wherever the polygon starts."""

    def __init__(self, polygons: Sequence[ArrayLike]) -> None:
        lower, upper, owner = [], [], []
        for z, polygon in enumerate(polygons):
            p = np.asarray(polygon, dtype=np.float64).reshape(-1, 2)
            if len(p) < 3:
                raise ValueError(f"polygon {z} has {len(p)} points; a zone needs at least 3")
            q = np.roll(p, -1, axis=0)
            up = p[:, 1] <= q[:, 1]
            lower.append(np.where(up[:, None], p, q))
            upper.append(np.where(up[:, None], q, p))
            owner.append(np.full(len(p), z))
        self.count = len(polygons)
        self._lower = np.concatenate(lower) if lower else np.zeros((0, 2))
        self._upper = np.concatenate(upper) if upper else np.zeros((0, 2))
        self._owner: IntArray = np.concatenate(owner) if owner else np.zeros(0, dtype=np.int64)

    def contains(self, xy: ArrayLike) -> BoolArray:
        """(N, Z) bool: point n lies inside polygon z (edge rule in the module docstring)."""
        pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        n, z = len(pts), self.count
        if z == 0 or n == 0:
            return np.zeros((n, z), dtype=bool)
        # The horizontal ray from a point to +x crosses an edge when the point's y lies in the
        # edge's half-open span [ay, by) and the edge passes to the right of the point. Sorting
        # the points by y turns each edge's span into one run of points, so only the (point,
        # edge) pairs that can cross are ever formed, however many zones the site has.
        order = np.argsort(pts[:, 1], kind="stable")
        ys = pts[order, 1]
        ax, ay = self._lower[:, 0], self._lower[:, 1]
        bx, by = self._upper[:, 0], self._upper[:, 1]
        first = np.searchsorted(ys, ay, side="left")
        length = np.searchsorted(ys, by, side="left") - first  # 0 for horizontal edges
        edge = np.repeat(np.arange(len(ax)), length)
        run_offset = np.repeat(np.cumsum(length) - length - first, length)
        point = order[np.arange(len(edge)) - run_offset]
        px, py = pts[point, 0], pts[point, 1]
        # Right of the point, for an upward edge, is a positive cross product (point strictly left).
        right = (bx - ax)[edge] * (py - ay[edge]) - (by - ay)[edge] * (px - ax[edge]) > 0
        cell = point[right] * z + self._owner[edge[right]]
        crossings = np.bincount(cell, minlength=n * z).reshape(n, z)
        return (crossings & 1).astype(bool)


def points_in_polygons(xy: ArrayLike, polygons: Sequence[ArrayLike]) -> BoolArray:
    """(N, Z) bool matrix of which polygon holds which point; see ``PolygonSet``."""
    return PolygonSet(polygons).contains(xy)


class ZoneIndex:
    """The site's zones, for membership queries by position."""

    def __init__(self, zones: Sequence[Zone]) -> None:
        self.zones = tuple(zones)
        self.ids = tuple(z.id for z in self.zones)
        self._polygons = PolygonSet([z.polygon for z in self.zones])

    def __len__(self) -> int:
        return len(self.zones)

    def contains(self, xy: ArrayLike) -> BoolArray:
        """(N, Z) bool: person n stands in zone z (columns ordered like ``ids``)."""
        return self._polygons.contains(xy)

    def first_zone(self, xy: ArrayLike) -> list[str | None]:
        """For each point, the first zone (in site order) that holds it, or None."""
        inside = self.contains(xy)
        first = inside.argmax(axis=1)
        return [self.ids[z] if inside[n, z] else None for n, z in enumerate(first)]


def zone_lists(inside: BoolArray, zone_ids: Sequence[str]) -> list[list[str]]:
    """For each row of an (N, Z) membership matrix, the ids of its zones (in ``zone_ids`` order),
    each a list of its own.

    >>> zone_lists(np.array([[True, False], [True, True], [True, False]]), ["hall", "bar"])
    [['hall'], ['hall', 'bar'], ['hall']]
    """
    inside = np.asarray(inside, dtype=bool)
    if inside.ndim != 2 or inside.shape[1] != len(zone_ids):
        raise ValueError(f"membership matrix has shape {inside.shape}, expected (N, {len(zone_ids)})")
    n, z = inside.shape
    if n == 0 or z == 0:
        return [[] for _ in range(n)]
    if z > 64:
        names = np.asarray(zone_ids, dtype=object)
        return [names[row].tolist() for row in inside]
    # People stand in few combinations of zones: name each combination once (found by packing a
    # row's bits into one uint64) rather than every person's row.
    packed = np.zeros((n, 8), np.uint8)
    packed[:, : (z + 7) // 8] = np.packbits(inside, axis=1)
    _, first, which = np.unique(packed.view(np.uint64).ravel(), return_index=True, return_inverse=True)
    combinations = [[zone_ids[k] for k in np.flatnonzero(inside[row]).tolist()] for row in first.tolist()]
    return [list(combinations[k]) for k in which.reshape(-1).tolist()]


def zones_by_track(ids: IntArray, inside: BoolArray, zone_ids: Sequence[str]) -> dict[int, list[str]]:
    """Track id -> ids of the zones it stands in, from an (N, Z) membership matrix."""
    ids = np.asarray(ids).reshape(-1)
    if len(ids) != len(inside):
        raise ValueError(f"{len(ids)} track ids but {len(inside)} membership rows")
    return dict(zip(ids.tolist(), zone_lists(inside, zone_ids), strict=True))
