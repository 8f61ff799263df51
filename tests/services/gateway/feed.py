"""Builders for the messages that feed a ``GatewayState`` in tests, and a controllable clock."""

from __future__ import annotations

from bevflow.schemas import DistanceIncident, DistanceViolation, Occupancy, OverCapacity, TrackState, Tracks, ZoneOccupancy

T0 = 1_700_000_000_000_000_000  # capture times start here (2023-11-14T22:13:20Z)
S = 1_000_000_000

SITE_YAML = """
site: hall
cameras:
  - id: north
    image_size: [800, 800]
    intrinsics: {fx: 250, fy: 250, cx: 400, cy: 400}
    pose: {position: [0, 0, 4]}
    monitored_radius_m: 6
  - id: south
    image_size: [800, 800]
    intrinsics: {fx: 250, fy: 250, cx: 400, cy: 400}
    pose: {position: [10, 0, 4]}
zones:
  - {id: gate, name: Gate, polygon: [[0, 0], [4, 0], [4, 4], [0, 4]], capacity: 3}
  - {id: shop, name: Shop, polygon: [[6, 0], [10, 0], [10, 4], [6, 4]], capacity: 10, crowded_level: 5}
thresholds: {site_capacity: 12}
floor: [-5, -5, 15, 5]
"""


class FakeClock:
    """Wall-clock nanoseconds that only move when a test says so."""

    def __init__(self, now: int = T0) -> None:
        self.now = now

    def __call__(self) -> int:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += int(seconds * S)


def tracks(t_ns: int, people: dict[int, tuple[float, float]], violations: list[tuple[int, int]] = (), zones=None) -> Tracks:
    """A tick with ``people`` (id -> feet xy); ``zones`` maps an id to its zone ids."""
    zones = zones or {}
    return Tracks(
        site="hall",
        time_ns=t_ns,
        tracks=[TrackState(id=i, xy=xy, zones=zones.get(i, [])) for i, xy in people.items()],
        violations=list(violations),
    )


def occupancy(t_ns: int, total: int, gate: int = 0, shop: int = 0) -> Occupancy:
    return Occupancy(
        site="hall",
        time_ns=t_ns,
        total=total,
        capacity=12,
        zones=[ZoneOccupancy(id="gate", count=gate, capacity=3), ZoneOccupancy(id="shop", count=shop, capacity=10)],
    )


def violation(event_id: str, start_ns: int, pair=(1, 2), zone: str | None = "gate", end_ns: int | None = None) -> DistanceViolation:
    return DistanceViolation(id=event_id, start_ns=start_ns, end_ns=end_ns, zone=zone, tracks=list(pair),
                             min_distance_m=1.2, limit_m=2.0)


def over_capacity(event_id: str, start_ns: int, zone: str | None = "gate", end_ns: int | None = None) -> OverCapacity:
    return OverCapacity(id=event_id, start_ns=start_ns, end_ns=end_ns, zone=zone, capacity=3, peak=5)


def incident(event_id: str, start_ns: int, people=(1, 2, 3), zone: str | None = "gate", end_ns: int | None = None) -> DistanceIncident:
    return DistanceIncident(id=event_id, start_ns=start_ns, end_ns=end_ns, zone=zone, tracks=list(people), people=len(people),
                            current=[] if end_ns else list(people), min_distance_m=0.9, limit_m=2.0, position=(1.0, 1.0),
                            last_active_ns=end_ns or start_ns, severity="medium")
