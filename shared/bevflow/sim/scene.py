"""People walking through an indoor site: who is where, frame by frame.

A ``SceneConfig`` describes the floor, its static obstacles (pillars, shelves and counters), the
doors people enter and leave by, and the crowd (how many identities, how many present at once,
groups, people who stop to stand or sit, walking speeds). ``Scene(config).run()`` yields one
``SceneFrame`` per time step. Runs are deterministic: the same config and seed give the same frames.

How people move:

- Each visit is a plan: walk to a few goals (sampled in the goal areas), sometimes stop at them,
  maybe stand or sit for a long while, then walk to an exit and leave. Routes come from a
  visibility graph around the obstacles (people walk straight lines that cut corners, as they do),
  and a light social-force model keeps them apart and off the obstacles while they follow it.
- Groups of 2–4 enter together; the others keep a slot beside or behind the leader.
- Someone who leaves comes back after an absence with a NEW person id (the paper counts a return
  as a new track); ``identity`` stays the same, and so does the body.

>>> cfg = SceneConfig(floor=(0.0, 0.0, 8.0, 6.0), identities=3, frames=20, seed=1)
>>> frames = list(Scene(cfg).run())
>>> len(frames), frames[-1].time_s, len(frames[0].person_ids)
(20, 1.9, 3)
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.sparse.csgraph import dijkstra

from bevflow.sim.bodies import BodyPrimitives, BodyShape, Posture, pose_bodies
from bevflow.sim.surge import Surge, extra_people, surge_area

FloatArray = NDArray[np.float64]
# One step of a visit: walk to a place (a goal, a door to leave by, the door reached) or stand still.
_PlaceStep = tuple[Literal["goal", "exit", "exit_now"], FloatArray]
_DwellStep = tuple[Literal["dwell"], tuple[float, Posture]]
_PlanStep = _PlaceStep | _DwellStep
IntArray = NDArray[np.int64]

BODY_RADIUS = 0.25  # m: how close a person's feet centre may come to an obstacle or wall
_ROUTE_CLEARANCE = 0.45  # m: routes keep this far from obstacles, so corners are not scraped


# --- configuration --------------------------------------------------------------------------------
@dataclass(frozen=True)
class Pillar:
    """A round column standing on the floor."""

    x: float
    y: float
    radius: float
    height: float


@dataclass(frozen=True)
class Shelf:
    """An axis-aligned box standing on the floor: a shelf, counter, desk or kiosk."""

    x0: float
    y0: float
    x1: float
    y1: float
    height: float


@dataclass(frozen=True)
class Door:
    """A gap in the floor border centred at (x, y), ``width`` metres wide."""

    x: float
    y: float
    width: float = 1.5


@dataclass(frozen=True)
class GoalArea:
    """A polygon where people choose goals; areas are picked in proportion to weight × area."""

    polygon: tuple[tuple[float, float], ...]
    weight: float = 1.0


@dataclass(frozen=True)
class SceneConfig:
    """Everything a scene needs. ``identities`` is the number of distinct people (None: a
    never-ending stream of new ones); ``people`` how many are inside at once (default: all
    identities). ``standing_fraction`` / ``sitting_fraction`` are the shares of visits spent
    mostly standing or sitting still; ``group_fraction`` the share of visits made in groups.
    ``frames`` None runs forever (a live demo)."""

    floor: tuple[float, float, float, float]
    pillars: tuple[Pillar, ...] = ()
    shelves: tuple[Shelf, ...] = ()
    entries: tuple[Door, ...] = ()
    exits: tuple[Door, ...] = ()  # empty: people leave by the entries
    goal_areas: tuple[GoalArea, ...] = ()  # empty: the whole floor
    identities: int | None = 10
    people: int | None = None
    standing_fraction: float = 0.1
    sitting_fraction: float = 0.0
    group_fraction: float = 0.2
    dwell_probability: float = 0.3
    goals_per_visit: tuple[int, int] = (2, 5)
    absence_s: tuple[float, float] = (5.0, 30.0)
    speed_mean_mps: float = 1.25
    speed_std_mps: float = 0.2
    fps: float = 10.0
    frames: int | None = 600
    seed: int = 0
    surges: tuple[Surge, ...] = ()  # times when more people come in, all for one area (``bevflow.sim.surge``)

    def __post_init__(self) -> None:
        x0, y0, x1, y1 = self.floor
        if not (x1 - x0 > 2 * BODY_RADIUS + 0.5 and y1 - y0 > 2 * BODY_RADIUS + 0.5):
            raise ValueError(f"floor {self.floor} must be (xmin, ymin, xmax, ymax) with room to walk")
        for name in ("standing_fraction", "sitting_fraction", "group_fraction", "dwell_probability"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1], got {getattr(self, name)}")
        if self.standing_fraction + self.sitting_fraction > 1.0:
            raise ValueError("standing_fraction + sitting_fraction must not exceed 1")
        if self.identities is None and self.people is None:
            raise ValueError("an endless stream of identities needs 'people' (how many are inside at once)")
        if self.fps <= 0 or (self.frames is not None and self.frames < 0):
            raise ValueError("fps must be positive and frames non-negative")
        if (self.identities is not None and self.identities < 0) or (self.people is not None and self.people < 0):
            raise ValueError("identities and people must not be negative")
        if not 1 <= self.goals_per_visit[0] <= self.goals_per_visit[1]:
            raise ValueError(f"goals_per_visit must be (least, most) with 1 <= least <= most, not {self.goals_per_visit}")
        if not 0.0 <= self.absence_s[0] <= self.absence_s[1]:
            raise ValueError(f"absence_s must be (shortest, longest) seconds, got {self.absence_s}")
        for kind, doors in (("entries", self.entries), ("exits", self.exits)):
            for i, d in enumerate(doors):
                if _border_normal(self.floor, d.x, d.y) is None:
                    raise ValueError(f"{kind}[{i}] at ({d.x}, {d.y}) is not on the floor border {self.floor}")

    @property
    def present_target(self) -> int:
        if self.people is not None:
            return self.people if self.identities is None else min(self.people, self.identities)
        assert self.identities is not None
        return self.identities

    @property
    def exit_doors(self) -> tuple[Door, ...]:
        return self.exits or self.entries


def _border_normal(floor: tuple[float, float, float, float], x: float, y: float) -> tuple[float, float] | None:
    """The inward normal of the floor edge a door sits on, or None if it is on none."""
    x0, y0, x1, y1 = floor
    for nx, ny, dist in ((1.0, 0.0, x - x0), (-1.0, 0.0, x1 - x), (0.0, 1.0, y - y0), (0.0, -1.0, y1 - y)):
        if abs(dist) < 0.05 and x0 - 0.05 <= x <= x1 + 0.05 and y0 - 0.05 <= y <= y1 + 0.05:
            return nx, ny
    return None


# --- obstacle geometry ------------------------------------------------------------------------------
class Obstacles:
    """The pillars and shelves of a scene as arrays, with the distance and segment tests that the
    crowd model and the camera views need."""

    def __init__(self, pillars: tuple[Pillar, ...] = (), shelves: tuple[Shelf, ...] = ()) -> None:
        self.pillar_xy = np.array([[p.x, p.y] for p in pillars], dtype=np.float64).reshape(-1, 2)
        self.pillar_radius = np.array([p.radius for p in pillars], dtype=np.float64)
        self.pillar_height = np.array([p.height for p in pillars], dtype=np.float64)
        self.shelf_lo = np.array([[min(s.x0, s.x1), min(s.y0, s.y1)] for s in shelves], dtype=np.float64).reshape(-1, 2)
        self.shelf_hi = np.array([[max(s.x0, s.x1), max(s.y0, s.y1)] for s in shelves], dtype=np.float64).reshape(-1, 2)
        self.shelf_height = np.array([s.height for s in shelves], dtype=np.float64)

    def __len__(self) -> int:
        return len(self.pillar_xy) + len(self.shelf_lo)

    def signed_distance(self, xy: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Floor points (N, 2) → signed distance (N, O) to each footprint (negative inside) and the
        unit direction (N, O, 2) pointing away from it. Pillars come first, then shelves."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        rel = xy[:, None, :] - self.pillar_xy[None]
        norm = np.linalg.norm(rel, axis=-1)
        p_dist = norm - self.pillar_radius[None]
        p_dir = np.where(norm[..., None] > 1e-9, rel / np.maximum(norm, 1e-9)[..., None], [1.0, 0.0])
        centre = (self.shelf_lo + self.shelf_hi) / 2
        half = (self.shelf_hi - self.shelf_lo) / 2
        rel = xy[:, None, :] - centre[None]
        q = np.abs(rel) - half[None]
        outside = np.maximum(q, 0.0)
        out_norm = np.linalg.norm(outside, axis=-1)
        s_dist = out_norm + np.minimum(q.max(-1), 0.0)
        sign = np.where(rel >= 0, 1.0, -1.0)
        inside_dir = np.where((q[..., 0] >= q[..., 1])[..., None], [1.0, 0.0], [0.0, 1.0]) * sign
        out_dir = outside * sign / np.maximum(out_norm, 1e-9)[..., None]
        s_dir = np.where((out_norm > 1e-9)[..., None], out_dir, inside_dir)
        return np.concatenate([p_dist, s_dist], 1), np.concatenate([p_dir, s_dir], 1)

    def near_segments(self, a: FloatArray, b: FloatArray, inflate: float) -> NDArray[np.bool_]:
        """(N, O): whether each floor segment a→b (N, 2) passes within ``inflate`` of each
        footprint (shelves grow with square corners, a slightly conservative shape)."""
        a, b = np.asarray(a, dtype=np.float64).reshape(-1, 2), np.asarray(b, dtype=np.float64).reshape(-1, 2)
        d = b - a
        rel = self.pillar_xy[None] - a[:, None]
        t = np.clip((rel * d[:, None]).sum(-1) / np.maximum((d * d).sum(-1), 1e-12)[:, None], 0.0, 1.0)
        gap = np.linalg.norm(a[:, None] + t[..., None] * d[:, None] - self.pillar_xy[None], axis=-1)
        t0, t1 = _slab_interval(a, d, self.shelf_lo - inflate, self.shelf_hi + inflate)
        return np.concatenate([gap < (self.pillar_radius + inflate)[None], (t0 < t1) & (t1 > 0.0) & (t0 < 1.0)], 1)

    def blocks_segments(self, a: FloatArray, b: FloatArray, inflate: float) -> NDArray[np.bool_]:
        """(N,): whether each floor segment a→b passes within ``inflate`` of any footprint."""
        blocked: NDArray[np.bool_] = np.any(self.near_segments(a, b, inflate), axis=1)
        return blocked

    def blocks_rays(
        self, origin: FloatArray, points: FloatArray, only: NDArray[np.bool_] | None = None
    ) -> NDArray[np.bool_]:
        """(N,): whether the 3D segments origin→points (N, 3) pass through a pillar or shelf, what a
        camera at ``origin`` cannot see. ``only`` (N, O) limits which obstacles each ray is tested
        against (all by default)."""
        o = np.asarray(origin, dtype=np.float64)
        d = np.asarray(points, dtype=np.float64).reshape(-1, 3) - o
        hit = np.zeros(len(d), dtype=bool)
        n_pillars = len(self.pillar_xy)
        for k in range(len(self)):
            rows: slice | NDArray[np.intp] = slice(None)
            if only is not None:
                rows = np.flatnonzero(only[:, k])
                if not len(rows):
                    continue
            if k < n_pillars:
                t0, t1 = _cylinder_interval(o, d[rows], self.pillar_xy[k], self.pillar_radius[k], self.pillar_height[k])
            else:
                j = k - n_pillars
                lo = np.append(self.shelf_lo[j], 0.0)[None]
                hi = np.append(self.shelf_hi[j], self.shelf_height[j])[None]
                t0, t1 = (x[:, 0] for x in _slab_interval(np.broadcast_to(o, d[rows].shape), d[rows], lo, hi))
            hit[rows] |= np.maximum(t0, 0.0) < np.minimum(t1, 1.0 - 1e-6)
        return hit


def _cylinder_interval(
    o: FloatArray, d: FloatArray, xy: FloatArray, r: float, h: float
) -> tuple[FloatArray, FloatArray]:
    """Parameter interval of o + t·d (d: (N, 3)) inside the vertical cylinder of radius r and
    height h standing at xy (empty when t0 ≥ t1)."""
    rel = o[:2] - xy
    a = (d[:, :2] ** 2).sum(-1)
    b = 2 * d[:, :2] @ rel
    c = rel @ rel - r * r
    disc = b * b - 4 * a * c
    root = np.sqrt(np.maximum(disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        t0 = np.where(disc > 0, (-b - root) / (2 * a), np.inf)
        t1 = np.where(disc > 0, (-b + root) / (2 * a), -np.inf)
        z0, z1 = -o[2] / d[:, 2], (h - o[2]) / d[:, 2]
    flat = np.abs(d[:, 2]) < 1e-12
    in_z = 0.0 <= o[2] <= h
    zlo = np.where(flat, -np.inf if in_z else np.inf, np.minimum(z0, z1))
    zhi = np.where(flat, np.inf if in_z else -np.inf, np.maximum(z0, z1))
    return np.maximum(t0, zlo), np.minimum(t1, zhi)


def _slab_interval(a: FloatArray, d: FloatArray, lo: FloatArray, hi: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Parameter interval of a + t·d (N, D) inside each box [lo, hi] (B, D); (N, B) each."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d[:, None, :]
        ta = (lo[None] - a[:, None, :]) * inv
        tb = (hi[None] - a[:, None, :]) * inv
    flat = np.abs(d[:, None, :]) < 1e-12
    inside = (a[:, None, :] >= lo[None]) & (a[:, None, :] <= hi[None])
    tmin = np.where(flat, np.where(inside, -np.inf, np.inf), np.minimum(ta, tb))
    tmax = np.where(flat, np.where(inside, np.inf, -np.inf), np.maximum(ta, tb))
    return tmin.max(-1), tmax.min(-1)


# --- routes -------------------------------------------------------------------------------------------
class Navigator:
    """Shortest walking routes on a visibility graph whose nodes ring each obstacle."""

    def __init__(self, floor: tuple[float, float, float, float], obstacles: Obstacles) -> None:
        self.floor = floor
        self.obstacles = obstacles
        margin = _ROUTE_CLEARANCE + 0.05
        ring = 8
        ang = (np.arange(ring) + 0.5) * 2 * math.pi / ring
        circle = np.stack([np.cos(ang), np.sin(ang)], 1) / math.cos(math.pi / ring)
        nodes = [obstacles.pillar_xy[i] + (r + margin) * circle for i, r in enumerate(obstacles.pillar_radius)]
        corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])
        for lo, hi in zip(obstacles.shelf_lo - margin, obstacles.shelf_hi + margin, strict=True):
            nodes.append(np.where(corners == 0, lo, hi))
        pts = np.concatenate(nodes) if nodes else np.zeros((0, 2))
        self.nodes = pts[self.is_free(pts, clearance=_ROUTE_CLEARANCE)]
        n = len(self.nodes)
        ii, jj = np.triu_indices(n, 1)
        ok = ~obstacles.blocks_segments(self.nodes[ii], self.nodes[jj], _ROUTE_CLEARANCE)
        self._graph = np.zeros((n + 2, n + 2))
        length = np.linalg.norm(self.nodes[ii] - self.nodes[jj], axis=1)
        self._graph[ii[ok], jj[ok]] = self._graph[jj[ok], ii[ok]] = length[ok]

    def is_free(self, xy: FloatArray, clearance: float = _ROUTE_CLEARANCE) -> NDArray[np.bool_]:
        """Inside the walls (by the body radius) and at least ``clearance`` from every obstacle."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        x0, y0, x1, y1 = self.floor
        inside = (xy[:, 0] >= x0 + BODY_RADIUS) & (xy[:, 0] <= x1 - BODY_RADIUS)
        inside &= (xy[:, 1] >= y0 + BODY_RADIUS) & (xy[:, 1] <= y1 - BODY_RADIUS)
        if len(self.obstacles):
            inside &= (self.obstacles.signed_distance(xy)[0] >= clearance).all(1)
        return inside

    def route(self, start: FloatArray, goal: FloatArray) -> list[FloatArray]:
        """Waypoints from ``start`` to ``goal`` (goal last; start excluded). A straight line when
        nothing is in the way; the goal alone when no route exists (the crowd model copes)."""
        start, goal = np.asarray(start, dtype=np.float64), np.asarray(goal, dtype=np.float64)
        # Start and goal may lie a little inside the route clearance (people are pushed about).
        clearance = _ROUTE_CLEARANCE - 0.1
        if not len(self.nodes) or not self.obstacles.blocks_segments(start[None], goal[None], clearance)[0]:
            return [goal]
        n = len(self.nodes)
        graph = self._graph.copy()
        for k, p in ((n, start), (n + 1, goal)):
            ends = np.broadcast_to(p, self.nodes.shape)
            ok = ~self.obstacles.blocks_segments(ends, self.nodes, clearance)
            graph[k, :n] = graph[:n, k] = np.where(ok, np.linalg.norm(self.nodes - p, axis=1), 0.0)
        # One source, asked for as a list of one: the rows are the distances and predecessors from it.
        distances, predecessors = dijkstra(graph, directed=False, indices=[n], return_predecessors=True)
        dist, prev = distances[0], predecessors[0]
        if not np.isfinite(dist[n + 1]):
            return [goal]
        path, k = [], int(prev[n + 1])
        while k != n and k >= 0:
            path.append(self.nodes[k])
            k = int(prev[k])
        return path[::-1] + [goal]


def _sample_in_polygon(rng: np.random.Generator, polygon: FloatArray, n: int) -> FloatArray:
    lo, hi = polygon.min(0), polygon.max(0)
    pts = rng.uniform(lo, hi, size=(n, 2))
    return pts[_in_polygon(pts, polygon)]


def _in_polygon(pts: FloatArray, polygon: FloatArray) -> NDArray[np.bool_]:
    """Even-odd rule, vectorised over points."""
    x, y = pts[:, 0:1], pts[:, 1:2]
    ax, ay = polygon[:, 0], polygon[:, 1]
    bx, by = np.roll(ax, -1), np.roll(ay, -1)
    crosses = (ay > y) != (by > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xs = ax + (y - ay) * (bx - ax) / (by - ay)
    inside: NDArray[np.bool_] = (crosses & (x < xs)).sum(1) % 2 == 1
    return inside


def polygon_area(polygon: FloatArray) -> float:
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1))))


# --- the crowd ------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class SceneFrame:
    """Everyone inside at one time step, as columns of length N. ``person_ids`` are visit ids (a
    return gets a new one), ``identity`` the person behind it, ``group`` a group id or −1.
    ``feet_xy`` is the floor point below the pelvis, the ground truth the paper annotates."""

    index: int
    time_s: float
    person_ids: IntArray
    identity: IntArray
    group: IntArray
    feet_xy: FloatArray
    heading: FloatArray
    gait_phase: FloatArray
    speed: FloatArray
    posture: IntArray
    body: BodyShape

    def __len__(self) -> int:
        return len(self.person_ids)

    def primitives(self) -> BodyPrimitives:
        return pose_bodies(self.body, self.feet_xy, self.heading, self.gait_phase, self.speed, self.posture)


def _leader(follower: _Walker) -> _Walker:
    assert follower.leader is not None, "only a group's followers keep a slot"
    return follower.leader


def _door_taken(walker: _Walker) -> FloatArray:
    """The door someone who has gone out left by: their plan still starts with reaching it."""
    step = walker.plan[0]
    assert step[0] != "dwell", "nobody leaves while standing still"
    return step[1]


@dataclass(eq=False)
class _Walker:
    pid: int
    identity: int
    pos: FloatArray
    speed: float  # preferred walking speed
    plan: list[_PlanStep]
    group: int = -1
    leader: _Walker | None = None
    slot: FloatArray = field(default_factory=lambda: np.zeros(2))  # (forward, left) from the leader
    vel: FloatArray = field(default_factory=lambda: np.zeros(2))
    heading: float = 0.0
    phase: float = 0.0
    posture: Posture = Posture.WALKING
    route: list[FloatArray] = field(default_factory=list)
    dwell_left: float = 0.0
    spot: FloatArray = field(default_factory=lambda: np.zeros(2))  # where a dwell started
    stuck_s: float = 0.0
    gone: bool = False

    @property
    def dwelling(self) -> bool:
        return self.dwell_left > 0.0


class Scene:
    """Runs a ``SceneConfig``. ``run()`` (or iterating) starts afresh each time, so two runs of
    the same config give identical frames."""

    def __init__(self, config: SceneConfig) -> None:
        self.config = config
        self.obstacles = Obstacles(config.pillars, config.shelves)
        self.navigator = Navigator(config.floor, self.obstacles)
        areas = config.goal_areas or (GoalArea(_rect(config.floor)),)
        self._areas = [np.asarray(a.polygon, dtype=np.float64) for a in areas]
        weights = np.array([a.weight * polygon_area(p) for a, p in zip(areas, self._areas, strict=True)])
        self._area_p = weights / weights.sum()
        self._doors_in = [_door_inner(config.floor, d) for d in config.entries]
        self._doors_out = [_door_inner(config.floor, d) for d in config.exit_doors]

    def __iter__(self) -> Iterator[SceneFrame]:
        return self.run()

    def run(self) -> Iterator[SceneFrame]:
        cfg = self.config
        self._rng = np.random.default_rng(cfg.seed)
        self._shapes: list[BodyShape] = []
        self._speeds: list[float] = []
        self._next_pid, self._next_group = 1, 0
        self._away: list[tuple[float, int]] = []  # (back at time, identity)
        self._walkers: list[_Walker] = []
        self._t = 0.0
        self._place_initial_crowd()
        dt = 1.0 / cfg.fps
        index = 0
        while cfg.frames is None or index < cfg.frames:
            t = index * dt
            self._t = t
            if index:
                self._step(t, dt)
            yield self._frame(index, t)
            index += 1

    # --- population -------------------------------------------------------------------------------------
    def _new_identity(self) -> int:
        shape = BodyShape.sample(self._rng, 1)
        self._shapes.append(shape)
        c = self.config
        self._speeds.append(float(np.clip(self._rng.normal(c.speed_mean_mps, c.speed_std_mps), 0.5, 2.0)))
        return len(self._shapes) - 1

    def _take_identities(self, t: float, n: int) -> list[int]:
        """Up to n identities ready to (re-)enter: returning ones first, then never-seen ones."""
        ready = sorted((back, i) for back, i in self._away if back <= t)[:n]
        for item in ready:
            self._away.remove(item)
        ids = [i for _, i in ready]
        limit = self.config.identities
        while len(ids) < n and (limit is None or len(self._shapes) < limit):
            ids.append(self._new_identity())
        return ids

    def _group_size(self, available: int) -> int:
        if available >= 2 and self._rng.random() < self.config.group_fraction:
            return min(available, int(self._rng.integers(2, 5)))
        return 1

    def _place_initial_crowd(self) -> None:
        target = self.config.present_target
        while len(self._walkers) < target:
            size = self._group_size(target - len(self._walkers))
            ids = self._take_identities(0.0, size)
            if not ids:
                break
            self._start_visit(ids, self._sample_goal())
        if self._walkers:  # group slots may overlap an obstacle or someone: settle before frame 0
            settled = self._resolve(np.array([w.pos for w in self._walkers]), np.zeros(len(self._walkers), bool))
            for w, p in zip(self._walkers, settled, strict=True):
                w.pos = p

    def _spawn(self, t: float) -> None:
        present = len(self._walkers)
        target = self.config.present_target + extra_people(self.config.surges, t)
        if present >= target or not self._doors_in:
            return
        door = self._doors_in[int(self._rng.integers(len(self._doors_in)))]
        if any(math.hypot(*(w.pos - door[0])) < 1.0 for w in self._walkers):
            return  # the doorway is busy: try again next frame
        ids = self._take_identities(t, self._group_size(target - present))
        if ids:
            self._start_visit(ids, door[0].copy(), inward=door[1])

    def _start_visit(self, ids: list[int], at: FloatArray, inward: FloatArray | None = None) -> None:
        """One person, or a group led by the first, starting at ``at`` (inside, or in a doorway
        facing ``inward``)."""
        rng = self._rng
        group = -1
        if len(ids) > 1:
            group, self._next_group = self._next_group, self._next_group + 1
        leader = None
        for k, identity in enumerate(ids):
            slot = _group_slot(k, len(ids))
            pos = at.copy()
            if k and inward is not None:  # side by side in the doorway, a little staggered
                side = np.array([-inward[1], inward[0]]) * 0.55 * ((k + 1) // 2) * (1 if k % 2 else -1)
                pos = at + side + inward * 0.15 * k
            elif k:
                pos = at + slot + rng.normal(0, 0.05, 2)
            speed = self._speeds[identity] if leader is None else max(self._speeds[identity], leader.speed)
            plan = self._plan() if leader is None else []
            w = _Walker(self._next_pid, identity, pos, speed, plan, group, leader, slot)
            w.heading = float(rng.uniform(-math.pi, math.pi)) if inward is None else math.atan2(inward[1], inward[0])
            w.phase = float(rng.uniform(0, 2 * math.pi))
            self._next_pid += 1
            self._walkers.append(w)
            leader = leader or w

    def _plan(self) -> list[_PlanStep]:
        rng, cfg = self._rng, self.config
        surge = surge_area(cfg.surges, self._t)
        if surge is not None and rng.random() < surge.share:
            return self._surge_plan(surge)
        u = rng.random()
        long_stop = Posture.STANDING if u < cfg.standing_fraction else None
        if long_stop is None and u < cfg.standing_fraction + cfg.sitting_fraction:
            long_stop = Posture.SITTING
        n_goals = int(rng.integers(cfg.goals_per_visit[0], cfg.goals_per_visit[1] + 1))
        stop_at = int(rng.integers(n_goals)) if long_stop is not None else -1
        plan: list[_PlanStep] = []
        for k in range(n_goals):
            plan.append(("goal", self._sample_goal()))
            if k == stop_at and long_stop is not None:
                plan.append(("dwell", (float(rng.uniform(20.0, 90.0)), long_stop)))
            elif rng.random() < cfg.dwell_probability:
                plan.append(("dwell", (float(rng.uniform(1.5, 6.0)), Posture.STANDING)))
        if self._doors_out:
            plan.append(("exit", self._doors_out[int(rng.integers(len(self._doors_out)))][0]))
        return plan

    def _surge_plan(self, surge: Surge) -> list[_PlanStep]:
        """A visit during a surge: straight to its area, a long stand there, then out."""
        rng = self._rng
        for _ in range(200):
            pts = _sample_in_polygon(rng, np.asarray(surge.area, dtype=np.float64), 8)
            pts = pts[self.navigator.is_free(pts, clearance=_ROUTE_CLEARANCE)]
            if len(pts):
                break
        else:
            raise ValueError("no free floor in the surge area")
        plan: list[_PlanStep] = [("goal", pts[0]), ("dwell", (float(rng.uniform(*surge.stay_s)), Posture.STANDING))]
        if self._doors_out:
            plan.append(("exit", self._doors_out[int(rng.integers(len(self._doors_out)))][0]))
        return plan

    def _sample_goal(self) -> FloatArray:
        for _ in range(200):
            area = self._areas[int(self._rng.choice(len(self._areas), p=self._area_p))]
            pts = _sample_in_polygon(self._rng, area, 8)
            pts = pts[self.navigator.is_free(pts, clearance=_ROUTE_CLEARANCE)]
            if len(pts):
                goal: FloatArray = pts[0]
                return goal
        raise ValueError("no free floor to walk to: the goal areas are covered by obstacles")

    # --- one time step ------------------------------------------------------------------------------
    def _step(self, t: float, dt: float) -> None:
        walkers = self._walkers
        desired = np.zeros((len(walkers), 2))
        followers = []
        for k, w in enumerate(walkers):  # leaders come before their followers
            if w.leader is not None and w.leader.gone:  # the leader went out: follow them through the door
                w.plan, w.leader, w.route = [("exit", _door_taken(w.leader))], None, []
            if w.leader is None:
                desired[k] = self._pursue(w, dt)
            else:
                followers.append(k)
        if followers:
            desired[followers] = self._follow([walkers[k] for k in followers], dt)
        self._move(desired, dt)
        for w in [w for w in walkers if w.gone]:
            walkers.remove(w)
            lo, hi = self.config.absence_s
            self._away.append((t + float(self._rng.uniform(lo, hi)), w.identity))
        self._spawn(t)

    def _pursue(self, w: _Walker, dt: float) -> FloatArray:
        """Desired velocity of someone following their own plan; advances the plan."""
        if w.dwelling:
            w.dwell_left -= dt
            if w.dwell_left > 0:  # hold the spot: someone who stops is not pushed around by passers-by
                return _toward(w.pos, w.spot, min(0.6, 1.5 * math.hypot(*(w.spot - w.pos))), slow_down=False)
            w.posture = Posture.WALKING
        while w.route and math.hypot(*(w.route[0] - w.pos)) < (0.35 if len(w.route) == 1 else 0.6):
            w.route.pop(0)
            if not w.route and w.plan and w.plan[0][0] == "exit_now":
                w.gone = True
                return np.zeros(2)
        if not w.route:
            if not w.plan:
                if self._doors_out:
                    return np.zeros(2)
                w.plan = self._plan()
            step = w.plan.pop(0)
            if step[0] == "dwell":
                seconds, posture = step[1]
                w.dwell_left, w.posture, w.spot = seconds, posture, w.pos.copy()
                return np.zeros(2)
            kind, where = step
            if kind == "exit":
                w.plan.insert(0, ("exit_now", where))
            w.route = self.navigator.route(w.pos, np.asarray(where))
            w.stuck_s = 0.0
        self._watch_progress(w, dt)
        return _toward(w.pos, w.route[0], w.speed, slow_down=len(w.route) == 1)

    def _watch_progress(self, w: _Walker, dt: float) -> None:
        """Someone pinned against others or an obstacle first looks for a new route, then gives up
        the goal (never the exit)."""
        moving = math.hypot(*w.vel) > 0.2 * w.speed
        w.stuck_s = max(0.0, w.stuck_s - dt) if moving else w.stuck_s + dt
        if w.stuck_s > 2.0 and int(w.stuck_s / dt) % 20 == 0:
            w.route = self.navigator.route(w.pos, w.route[-1])
        if w.stuck_s > 6.0 and not (w.plan and w.plan[0][0] == "exit_now"):
            w.route = [w.pos.copy()]
            w.stuck_s = 0.0

    def _follow(self, ws: list[_Walker], dt: float) -> FloatArray:
        """Desired velocities of group members: each keeps a slot beside or behind the leader,
        or the leader's own spot when the slot is inside an obstacle; around obstacles by route."""
        leaders = [_leader(w) for w in ws]
        heading = np.array([leader.heading for leader in leaders])
        slot = np.array([w.slot for w in ws])
        lead = np.array([leader.pos for leader in leaders])
        c, s = np.cos(heading), np.sin(heading)
        target = lead + np.stack([c * slot[:, 0] - s * slot[:, 1], s * slot[:, 0] + c * slot[:, 1]], 1)
        target = np.where(self.navigator.is_free(target, clearance=BODY_RADIUS)[:, None], target, lead)
        pos = np.array([w.pos for w in ws])
        blocked = self.obstacles.blocks_segments(pos, target, BODY_RADIUS)
        out = np.zeros((len(ws), 2))
        for i, w in enumerate(ws):
            leader = w.leader
            assert leader is not None
            gap = math.hypot(*(target[i] - w.pos))
            w.posture = Posture.STANDING if leader.dwelling and gap < 0.4 else Posture.WALKING
            if blocked[i]:
                if not w.route or int(w.stuck_s / dt) % 10 == 0:
                    w.route = self.navigator.route(w.pos, target[i])
                w.stuck_s += dt
                while len(w.route) > 1 and math.hypot(*(w.route[0] - w.pos)) < 0.6:
                    w.route.pop(0)
                out[i] = _toward(w.pos, w.route[0], 1.2 * w.speed, slow_down=False)
                continue
            w.route, w.stuck_s = [], 0.0
            if w.posture == Posture.WALKING:
                v = leader.vel + 1.5 * (target[i] - w.pos)
                norm = math.hypot(*v)
                out[i] = v * min(1.0, 1.4 * w.speed / norm) if norm > 1e-9 else v
        return out

    def _move(self, desired: FloatArray, dt: float) -> None:
        walkers = self._walkers
        if not walkers:
            return
        pos = np.array([w.pos for w in walkers])
        vel = np.array([w.vel for w in walkers])
        speed = np.array([w.speed for w in walkers])
        group = np.array([w.group for w in walkers])
        anchored = np.array([w.posture == Posture.SITTING for w in walkers])
        still = np.array([w.dwelling or w.posture == Posture.STANDING for w in walkers])
        heading = np.array([w.heading for w in walkers])
        force = _social_force(pos, heading, group) * np.where(still, 0.3, 1.0)[:, None] + self._obstacle_force(pos)
        vel = vel + dt * ((desired - vel) / 0.5 + force)
        norm = np.linalg.norm(vel, axis=1, keepdims=True)
        vel *= np.minimum(1.0, 1.3 * speed[:, None] / np.maximum(norm, 1e-9))
        vel[anchored] = 0.0
        new = self._resolve(pos + vel * dt, anchored)
        vel = (new - pos) / dt
        for k, w in enumerate(walkers):
            w.vel, w.pos = vel[k], new[k]
            v = math.hypot(*w.vel)
            if v > 0.25:
                turn = (math.atan2(w.vel[1], w.vel[0]) - w.heading + math.pi) % (2 * math.pi) - math.pi
                w.heading = (w.heading + max(-6.0 * dt, min(6.0 * dt, turn)) + math.pi) % (2 * math.pi) - math.pi
            height = float(self._shapes[w.identity].height[0])
            w.phase = (w.phase + 2 * math.pi * v * dt / (height * (0.45 + 0.25 * v))) % (2 * math.pi)

    def _obstacle_force(self, pos: FloatArray) -> FloatArray:
        x0, y0, x1, y1 = self.config.floor
        walls = np.stack([pos[:, 0] - x0, x1 - pos[:, 0], pos[:, 1] - y0, y1 - pos[:, 1]], 1)
        push = 3.0 * np.exp((BODY_RADIUS - walls) / 0.1)
        force = np.stack([push[:, 0] - push[:, 1], push[:, 2] - push[:, 3]], 1)
        if len(self.obstacles):
            dist, away = self.obstacles.signed_distance(pos)
            mag = np.where(dist < 1.0, 4.0 * np.exp((BODY_RADIUS - dist) / 0.12), 0.0)
            force += (mag[..., None] * away).sum(1)
        return force

    def _resolve(self, pos: FloatArray, anchored: NDArray[np.bool_]) -> FloatArray:
        """Hard constraints after the soft forces: people do not overlap, and never stand inside
        an obstacle or a wall (obstacles have the last word)."""
        free = (~anchored).astype(np.float64)
        share = free[:, None] / np.maximum(free[:, None] + free[None], 1.0)
        for _ in range(2):
            diff = pos[:, None] - pos[None]
            dist = np.linalg.norm(diff, axis=-1) + np.eye(len(pos)) * 1e3
            overlap = np.maximum(0.5 - dist, 0.0)
            if not overlap.any():
                break
            pos = pos + ((overlap * share)[..., None] * diff / dist[..., None]).sum(1)
        return self._push_out(pos)

    def _push_out(self, pos: FloatArray) -> FloatArray:
        x0, y0, x1, y1 = self.config.floor
        lo, hi = [x0 + BODY_RADIUS, y0 + BODY_RADIUS], [x1 - BODY_RADIUS, y1 - BODY_RADIUS]
        pos = np.clip(pos, lo, hi)
        for _ in range(4):  # more than once only where two obstacles nearly touch
            if not len(self.obstacles):
                break
            dist, away = self.obstacles.signed_distance(pos)
            depth = np.maximum(BODY_RADIUS - dist, 0.0)
            if not depth.any():
                break
            pos = np.clip(pos + (depth[..., None] * away).sum(1), lo, hi)
        return pos

    def _frame(self, index: int, t: float) -> SceneFrame:
        ws = self._walkers
        return SceneFrame(
            index=index,
            time_s=round(t, 9),
            person_ids=np.array([w.pid for w in ws], dtype=np.int64),
            identity=np.array([w.identity for w in ws], dtype=np.int64),
            group=np.array([w.group for w in ws], dtype=np.int64),
            feet_xy=np.array([w.pos for w in ws], dtype=np.float64).reshape(-1, 2),
            heading=np.array([w.heading for w in ws], dtype=np.float64),
            gait_phase=np.array([w.phase for w in ws], dtype=np.float64),
            speed=np.array([math.hypot(*w.vel) for w in ws], dtype=np.float64),
            posture=np.array([int(w.posture) for w in ws], dtype=np.int64),
            body=BodyShape.concatenate([self._shapes[w.identity] for w in ws]),
        )


def _toward(pos: FloatArray, target: FloatArray, speed: float, slow_down: bool) -> FloatArray:
    d = target - pos
    dist = math.hypot(*d)
    if dist < 1e-6:
        return np.zeros(2)
    return d / dist * speed * (min(1.0, dist / 0.8) if slow_down else 1.0)


def _social_force(pos: FloatArray, heading: FloatArray, group: IntArray) -> FloatArray:
    """Exponential repulsion between people, stronger from those ahead (Helbing's social force,
    with its anisotropy); members of one group tolerate each other closer."""
    diff = pos[:, None] - pos[None]
    dist = np.linalg.norm(diff, axis=-1) + np.eye(len(pos)) * 1e3
    away = diff / dist[..., None]
    facing = np.stack([np.cos(heading), np.sin(heading)], 1)
    ahead = -(away * facing[:, None]).sum(-1)
    weight = 0.35 + 0.65 * (1 + ahead) / 2
    same = (group[:, None] == group[None]) & (group[:, None] >= 0)
    mag = np.where(dist < 2.5, 2.0 * np.exp((0.5 - dist) / 0.3), 0.0) * weight * np.where(same, 0.3, 1.0)
    push: FloatArray = (mag[..., None] * away).sum(1)
    return push


def _group_slot(k: int, size: int) -> FloatArray:
    """(forward, left) offset of member k from the leader: side by side for pairs and triples,
    two by two for four."""
    if k == 0:
        return np.zeros(2)
    if size <= 3:
        return np.array([0.0, 0.7 * ((k + 1) // 2) * (1 if k % 2 else -1)])
    return np.array([[0.0, 0.7], [-0.8, 0.0], [-0.8, 0.7]][k - 1])


def _door_inner(floor: tuple[float, float, float, float], door: Door) -> tuple[FloatArray, FloatArray]:
    """Where people appear and disappear at a door (a little inside the wall) and the inward normal."""
    normal = np.asarray(_border_normal(floor, door.x, door.y), dtype=np.float64)
    x0, y0, x1, y1 = floor
    at = np.array([min(max(door.x, x0), x1), min(max(door.y, y0), y1)]) + normal * (BODY_RADIUS + 0.15)
    return at, normal


def _rect(floor: tuple[float, float, float, float]) -> tuple[tuple[float, float], ...]:
    x0, y0, x1, y1 = floor
    return ((x0, y0), (x1, y0), (x1, y1), (x0, y1))
