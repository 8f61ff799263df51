"""A busy hall for the dashboard tests: a site, an hour of history, live ticks, alerts.

``Scene`` fills a ``GatewayState`` the way the bus would: half an hour of occupancy with a crowded
stretch, a minute of track history, a few alerts, live services and cameras; then ``Feeder`` keeps
ticking in a thread (people milling in the zones and walking across the hall, the entrance
over capacity, two pairs too close) so the map has trails and the websockets have something to send.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import numpy as np

from bevflow.analytics.zones import points_in_polygons
from bevflow.schemas import (
    CameraHealthEvent,
    DistanceIncident,
    FrameHeader,
    Occupancy,
    OverCapacity,
    TrackState,
    Tracks,
    ZoneOccupancy,
)
from bevflow.site import Site, parse_site

from bevflow_services.gateway import GatewayState

S = 1_000_000_000

SITE_YAML = """
site: hall
floor: [0, 0, 30, 20]
cameras:
  - {id: hall-sw, image_size: [1024, 1024], intrinsics: {fx: 317, fy: 317, cx: 512, cy: 512},
     pose: {position: [7.5, 5, 5.5]}, monitored_radius_m: 9.5}
  - {id: hall-se, image_size: [1024, 1024], intrinsics: {fx: 317, fy: 317, cx: 512, cy: 512},
     pose: {position: [22.5, 5, 5.5]}, monitored_radius_m: 9.5}
  - {id: hall-nw, image_size: [1024, 1024], intrinsics: {fx: 317, fy: 317, cx: 512, cy: 512},
     pose: {position: [7.5, 15, 5.5]}, monitored_radius_m: 9.5}
  - {id: hall-ne, image_size: [1024, 1024], intrinsics: {fx: 317, fy: 317, cx: 512, cy: 512},
     pose: {position: [22.5, 15, 5.5]}, monitored_radius_m: 9.5}
zones:
  - {id: entrance, name: Main entrance, polygon: [[1, 6], [7, 6], [7, 9], [1, 9]], capacity: 8}
  - {id: food-court, name: Food court, polygon: [[20, 10.5], [28, 10.5], [28, 14.5], [20, 14.5]],
     capacity: 20, crowded_level: 15}
  - {id: gate-a, name: Gate A, polygon: [[12, 15], [18, 15], [18, 19], [12, 19]], capacity: 15}
thresholds: {site_capacity: 60}
"""

UP_CAMERAS = ("hall-sw", "hall-se", "hall-nw")  # hall-ne is reported down
VIOLATIONS = [(1, 2), (3, 4)]
CIRCLE_RADIUS_M = 0.5
CIRCLE_PERIOD_S = 20.0
WALK_SPEED_M_S = 1.1


def hall() -> Site:
    return parse_site(SITE_YAML)


def _inside(
    rng: np.random.Generator, box: tuple[float, float, float, float], n: int, clear_of: np.ndarray | None = None
) -> np.ndarray:
    """n circle centres in box; with clear_of, none whose circle can pass within a click's reach of those points."""
    x0, y0, x1, y1 = box
    margin = 0.7
    keep: list[np.ndarray] = []
    while len(keep) < n:
        point = rng.uniform([x0 + margin, y0 + margin], [x1 - margin, y1 - margin])
        if clear_of is None or np.linalg.norm(clear_of - point, axis=1).min() > 2 * CIRCLE_RADIUS_M + 0.6:
            keep.append(point)
    return np.array(keep)


@dataclass(frozen=True)
class Crowd:
    """Who walks where (row i is track id i + 1). People in zones mill about on small circles;
    people in the open hall walk back and forth along a straight stretch at walking speed."""

    bases: np.ndarray  # (N, 2) metres
    circles: np.ndarray  # (N,) radius of the circle walked, 0 for straight walkers
    strides: np.ndarray  # (N, 2) half the straight stretch, 0 for circlers
    phases: np.ndarray  # (N,) in [0, 1)

    def positions(self, t_s: float) -> np.ndarray:
        angle = 2 * math.pi * (t_s / CIRCLE_PERIOD_S + self.phases)
        around = self.circles[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])
        length = np.maximum(np.linalg.norm(self.strides, axis=1), 1e-9)
        u = t_s * WALK_SPEED_M_S / (4 * length) + self.phases
        triangle = 2 * np.abs(2 * (u % 1.0) - 1) - 1  # -1 .. 1 and back, at constant speed
        return self.bases + around + self.strides * triangle[:, None]


def _clear_stretch(rng: np.random.Generator, zones: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """A straight stretch in the open hall that keeps 0.8 m from every zone and 1 m from the walls."""
    while True:
        centre = rng.uniform([4.0, 3.0], [26.0, 17.0])
        angle = rng.uniform(0, math.pi)
        stride = rng.uniform(1.5, 3.0) * np.array([math.cos(angle), math.sin(angle)])
        along = centre + np.linspace(-1, 1, 9)[:, None] * stride
        margin = along[:, None, :] + 0.8 * np.array([(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)])
        inside_floor = ((along > 1) & (along < [29, 19])).all()
        if inside_floor and not points_in_polygons(margin.reshape(-1, 2), zones).any():
            return centre, stride


def crowd(site: Site) -> Crowd:
    """44 people: 10 in the entrance (capacity 8), 16 in the food court (crowded at 15), 3 at
    gate A, 15 walking in the open hall; ids 1-2 walk side by side, 3-4 keep close in the entrance."""
    rng = np.random.default_rng(7)
    zones = [np.asarray(z.polygon) for z in site.zones]
    close_pair = np.array([[2.2, 7.2], [3.3, 7.6]])  # ids 3-4, which the person-panel test clicks on
    milling = np.vstack([
        close_pair,
        _inside(rng, (1, 6, 7, 9), 8, clear_of=close_pair),
        _inside(rng, (20, 10.5, 28, 14.5), 16),
        _inside(rng, (12, 15, 18, 19), 3),
    ])
    walks = [(np.array([11.0, 3.0]), np.array([3.0, 0.0])), (np.array([12.2, 3.0]), np.array([3.0, 0.0]))]  # ids 1-2
    walks += [_clear_stretch(rng, zones) for _ in range(13)]
    n_walk = len(walks)
    bases = np.vstack([[w[0] for w in walks[:2]], milling, [w[0] for w in walks[2:]]])
    strides = np.vstack([[w[1] for w in walks[:2]], np.zeros_like(milling), [w[1] for w in walks[2:]]])
    circles = np.r_[np.zeros(2), np.full(len(milling), CIRCLE_RADIUS_M), np.zeros(n_walk - 2)]
    phases = rng.uniform(0, 1, len(bases))
    for a, b in VIOLATIONS:  # pairs move in step, so they stay close
        phases[b - 1] = phases[a - 1]
    return Crowd(bases, circles, strides, phases)


@dataclass
class Scene:
    """The hall, its crowd, and the state they feed."""

    site: Site
    state: GatewayState
    crowd: Crowd

    @classmethod
    def build(cls, now_ns: int | None = None) -> Scene:
        site = hall()
        now_ns = time.time_ns() if now_ns is None else now_ns
        scene = cls(site, GatewayState(site), crowd(site))
        scene.fill_history(now_ns)
        return scene

    @property
    def ids(self) -> list[int]:
        return list(range(1, len(self.crowd.bases) + 1))

    def tracks(self, t_ns: int) -> Tracks:
        xy = self.crowd.positions(t_ns / S)
        velocity = (self.crowd.positions(t_ns / S + 0.05) - self.crowd.positions(t_ns / S - 0.05)) / 0.1
        inside = points_in_polygons(xy, [np.asarray(z.polygon) for z in self.site.zones])
        zone_ids = [z.id for z in self.site.zones]
        up = [c for c in self.site.cameras if c.id in UP_CAMERAS]
        centres = np.array([c.pose.position[:2] for c in up])
        seen = np.linalg.norm(xy[:, None, :] - centres[None], axis=2) < 9.5
        people = [
            TrackState(
                id=i + 1,
                xy=(float(xy[i, 0]), float(xy[i, 1])),
                velocity=(float(velocity[i, 0]), float(velocity[i, 1])),
                zones=[zone_ids[z] for z in np.flatnonzero(inside[i])],
                cameras=[up[c].id for c in np.flatnonzero(seen[i])],
            )
            for i in range(len(xy))
        ]
        return Tracks(site="hall", time_ns=t_ns, tracks=people, violations=VIOLATIONS)

    def occupancy(self, t_ns: int, total: int, counts: dict[str, int]) -> Occupancy:
        zones = [ZoneOccupancy(id=z.id, name=z.name, count=counts.get(z.id, 0), capacity=z.capacity) for z in self.site.zones]
        return Occupancy(site="hall", time_ns=t_ns, total=total, capacity=60, zones=zones)

    def live_occupancy(self, tracks: Tracks) -> Occupancy:
        counts: dict[str, int] = {}
        for person in tracks.tracks:
            for zone in person.zones:
                counts[zone] = counts.get(zone, 0) + 1
        return self.occupancy(tracks.time_ns, len(tracks.tracks), counts)

    def fill_history(self, now_ns: int) -> None:
        """Half an hour of occupancy (a crowded stretch 20 minutes ago, the entrance filling up in
        the last ten), a minute of tracks, alerts, services and camera frames."""
        for s in range(-1800, 0):
            t = now_ns + s * S
            bump = 14 * math.exp(-(((s + 1150) / 160) ** 2))
            entrance = int(round(3 + 7 / (1 + math.exp(-(s + 300) / 60))))
            counts = {"entrance": entrance, "food-court": 16 if s > -1200 else 11, "gate-a": 3}
            self.state.apply(self.occupancy(t, int(round(40 + bump + 2 * math.sin(s / 90))), counts))
        for s in np.arange(-60.0, 0.0, 0.5):
            self.state.apply(self.tracks(now_ns + int(s * S)))
        for name, instance in [("ingest", c) for c in UP_CAMERAS] + [("detector", "d1"), ("projector", "p1"), ("tracker", "t1")]:
            self.state.service_up(name, instance)
        self.state.apply(incident("inc-earlier", now_ns - 720 * S, [7, 9], end_ns=now_ns - 680 * S))
        self.state.apply(CameraHealthEvent(id="down-hall-ne", type="camera_down", camera="hall-ne",
                                           start_ns=now_ns - 130 * S, reason="stream closed by the camera"))
        self.state.apply(OverCapacity(id="oc-entrance", start_ns=now_ns - 180 * S, zone="entrance", capacity=8, peak=10))
        self.state.apply(incident("inc-1-2", now_ns - 20 * S, [1, 2]))
        self.frames(now_ns, seq=0)

    def frames(self, t_ns: int, seq: int) -> None:
        for camera in UP_CAMERAS:
            self.state.apply(FrameHeader(camera=camera, seq=seq, capture_ns=t_ns, width=1024, height=1024))


def incident(event_id: str, start_ns: int, people: list[int], end_ns: int | None = None, zone: str | None = None,
             position: tuple[float, float] = (11.6, 3.0)) -> DistanceIncident:
    """A distance incident of ``people`` (ongoing unless ``end_ns``), as the tracker publishes it."""
    return DistanceIncident(id=event_id, start_ns=start_ns, end_ns=end_ns, zone=zone, tracks=people, people=len(people),
                            current=[] if end_ns else people, min_distance_m=1.2, limit_m=2.0, position=position,
                            last_active_ns=end_ns or start_ns, severity="low" if len(people) < 3 else "medium")


class Feeder:
    """Ticks a scene into its state every ``period_s`` from a thread, until stopped."""

    def __init__(self, scene: Scene, period_s: float = 0.2) -> None:
        self.scene = scene
        self.period_s = period_s
        self.stop_event = threading.Event()
        self.thread = threading.Thread(target=self.run, name="dashboard-feeder", daemon=True)

    def run(self) -> None:
        seq = 1
        while not self.stop_event.wait(self.period_s):
            now = time.time_ns()
            tracks = self.scene.tracks(now)
            self.scene.state.apply(tracks)
            self.scene.state.apply(self.scene.live_occupancy(tracks))
            self.scene.frames(now, seq)
            seq += 1

    def __enter__(self) -> Feeder:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop_event.set()
        self.thread.join(timeout=5)
