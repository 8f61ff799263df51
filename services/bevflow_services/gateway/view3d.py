"""The live 3D view: a viser server showing the floor, the cameras, the zones and the people.

Drawn for a security operator glancing at a wall screen: a dark floor with a faint metre grid,
zones as translucent areas with their names, coloured by occupancy as on the 2D map, cameras as yellow frustums with their ids,
people as cyan cylinders with their track ids above their heads. Everyone in a distance violation
turns red and stands on a red disc half the distance limit wide, and a red line, a few pixels
thick at any zoom, joins each pair in violation.

People are one batched mesh of unit cylinders, scaled per person to their fitted radius and
height (one message for the whole crowd instead of one per person). A background thread
refreshes the scene from ``GatewayState`` a few times a second, inside ``server.atomic()`` so a
browser never shows half an update.
"""

from __future__ import annotations

import logging
import math
import threading

import numpy as np
import viser
import viser.transforms as vtf

from bevflow.schemas import Tracks
from bevflow.site import Site

from bevflow_services.gateway.occupancy import level_of
from bevflow_services.gateway.state import GatewayState

log = logging.getLogger(__name__)

FLOOR_COLOR = (30, 35, 44)
GRID_CELL_COLOR = (52, 60, 72)
GRID_SECTION_COLOR = (84, 95, 112)
PERSON_COLOR = (40, 190, 255)
VIOLATION_COLOR = (255, 40, 40)
CAMERA_COLOR = (255, 210, 40)
COVERAGE_COLOR = (110, 100, 60)
# Zone fills by occupancy level, meaning what they mean on the 2D map (not which zone it is).
LEVEL_COLORS = {"unknown": (150, 160, 175), "normal": (60, 200, 110), "crowded": (255, 170, 30),
                "over_capacity": (255, 80, 70)}
ZONE_OPACITY = 0.22
LABEL_LIFT_M = 0.25
VIOLATION_LINE_Z_M = 1.0  # waist height: between the bodies, below the id labels
VIOLATION_LINE_PX = 7.0  # screen pixels: as visible across the hall as next to the camera
FRUSTUM_SCALE_M = 0.6
INITIAL_FOV_DEG = 45.0
DISC_OPACITY = 0.55
LEGEND = """**People**: cyan cylinders with their track id; **red** with a red disc while closer than the
distance limit to someone (a red line joins the pair). **Zones**: green normal, amber crowded, red over
capacity, as on the 2D map.
**Cameras**: yellow frustums; the thin circles are the areas they monitor."""


def unit_cylinder(segments: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a cylinder of radius 1 from z=0 to z=1, capped at both ends."""
    a = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.stack([np.cos(a), np.sin(a)], axis=1)
    bottom = np.column_stack([ring, np.zeros(segments)])
    top = np.column_stack([ring, np.ones(segments)])
    vertices = np.vstack([bottom, top, [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]])
    i = np.arange(segments)
    j = (i + 1) % segments
    b0, t0 = 2 * segments, 2 * segments + 1
    side = np.concatenate([np.stack([i, j, j + segments], 1), np.stack([i, j + segments, i + segments], 1)])
    caps = np.concatenate([np.stack([np.full(segments, b0), j, i], 1), np.stack([np.full(segments, t0), i + segments, j + segments], 1)])
    return vertices.astype(np.float32), np.concatenate([side, caps]).astype(np.uint32)


def triangulate(polygon: np.ndarray) -> np.ndarray:
    """(M, 3) vertex indices of triangles covering a simple polygon (convex or not), by ear
    clipping, each wound counter-clockwise seen from above. Zones are a few vertices, so the
    O(V³) worst case does not matter."""
    points = np.asarray(polygon, dtype=np.float64)
    if len(points) < 3:
        return np.zeros((0, 3), dtype=np.uint32)
    x, y = points[:, 0], points[:, 1]
    area2 = float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    left = list(range(len(points))) if area2 >= 0 else list(range(len(points)))[::-1]
    triangles = []
    while len(left) > 3:
        for k in range(len(left)):
            a, b, c = left[k - 1], left[k], left[(k + 1) % len(left)]
            if _cross(points[a], points[b], points[c]) <= 1e-12:
                continue  # a reflex or flat corner is no ear
            others = [p for p in left if p not in (a, b, c)]
            if not any(_inside_triangle(points[p], points[a], points[b], points[c]) for p in others):
                triangles.append((a, b, c))
                left.pop(k)
                break
        else:  # a self-intersecting outline has no ear left: fan the rest rather than loop forever
            triangles += [(left[0], left[k], left[k + 1]) for k in range(1, len(left) - 1)]
            left = []
    if len(left) == 3:
        triangles.append((left[0], left[1], left[2]))
    return np.array(triangles, dtype=np.uint32).reshape(-1, 3)


def _cross(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def _inside_triangle(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> bool:
    return _cross(a, b, p) >= 0 and _cross(b, c, p) >= 0 and _cross(c, a, p) >= 0


def floor_extent(site: Site) -> tuple[float, float, float, float]:
    """(xmin, ymin, xmax, ymax): the site's floor, or the cameras' coverage with a margin."""
    if site.floor is not None:
        return site.floor
    centers = np.array([site.camera(c.id).center[:2] for c in site.cameras])
    reach = max((c.monitored_radius_m or 5.0) for c in site.cameras)
    lo, hi = centers.min(axis=0) - reach, centers.max(axis=0) + reach
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def vertical_fov(site: Site, camera_id: str) -> float:
    """The angle between the rays of the top and bottom image centre pixels, capped for display."""
    camera = site.camera(camera_id)
    w, h = camera.image_size
    rays = camera.rays(np.array([[w / 2, 0.0], [w / 2, float(h)]]))
    cos = float(np.clip(np.dot(rays[0], rays[1]), -1.0, 1.0))
    fov = math.acos(cos) if np.isfinite(cos) else math.radians(120)
    return min(fov, math.radians(150))


def polyline_segments(points: np.ndarray, z: float, closed: bool = True) -> np.ndarray:
    """(N, 2, 3) segments joining consecutive floor points at height ``z``."""
    xyz = np.column_stack([points, np.full(len(points), z)])
    ends = np.roll(xyz, -1, axis=0) if closed else xyz[1:]
    starts = xyz if closed else xyz[:-1]
    return np.stack([starts, ends], axis=1)


def on_floor(segments: np.ndarray, floor: tuple[float, float, float, float]) -> np.ndarray:
    """The (N, 2, 3) segments whose two ends lie on the floor rectangle (edges included)."""
    x0, y0, x1, y1 = floor
    xy = segments[..., :2]
    inside = ((xy[..., 0] >= x0) & (xy[..., 0] <= x1) & (xy[..., 1] >= y0) & (xy[..., 1] <= y1)).all(axis=1)
    return segments[inside]


def person_colors(tracks: Tracks) -> np.ndarray:
    """(N, 3) uint8 colours of ``tracks.tracks``: red for those in a violation, cyan otherwise."""
    violating = {i for pair in tracks.violations for i in pair}
    rows = [VIOLATION_COLOR if t.id in violating else PERSON_COLOR for t in tracks.tracks]
    return np.array(rows, dtype=np.uint8).reshape(-1, 3)


class View3D:
    """A viser server showing one site, refreshed from ``state`` at ``rate_hz``.

    ``start()`` opens the server (viser moves to the next free port if ``port`` is taken;
    ``port`` then reports the real one) and the refresh thread; ``stop()`` ends both.
    """

    def __init__(self, state: GatewayState, host: str = "127.0.0.1", port: int = 8081, rate_hz: float = 5.0) -> None:
        self.state = state
        self.site = state.site
        self.host = host
        self.requested_port = port
        self.period_s = 1.0 / rate_hz
        self.server: viser.ViserServer | None = None
        self._stop = threading.Event()
        self._refreshing = threading.Lock()
        self._thread: threading.Thread | None = None
        self._shown_time_ns: int | None = None
        self._people: viser.BatchedMeshHandle | None = None
        self._labels: dict[int, viser.LabelHandle] = {}
        self._lines: viser.LineSegmentsHandle | None = None
        self._discs: viser.BatchedMeshHandle | None = None
        self._mesh = unit_cylinder()
        self._zones: dict[str, tuple[viser.MeshHandle, viser.LineSegmentsHandle, str]] = {}  # handles, level shown

    @property
    def port(self) -> int | None:
        return None if self.server is None else self.server.get_port()

    def start(self) -> None:
        self.server = viser.ViserServer(host=self.host, port=self.requested_port, verbose=False)
        # A small panel that folds away, the legend folded in it: the scene is what the operator looks at.
        self.server.gui.configure_theme(dark_mode=True, show_share_button=False, brand_color=PERSON_COLOR,
                                        control_width="small", show_logo=False)
        self.server.gui.main_panel.minimize()
        self.server.scene.set_up_direction("+z")
        with self.server.gui.add_folder("Legend", expand_by_default=False):
            self.server.gui.add_markdown(LEGEND)
        self._draw_site()
        self._thread = threading.Thread(target=self._run, name="view3d", daemon=True)
        self._thread.start()
        log.info("3D view on http://%s:%d/", self.host, self.port)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self.server is not None:
            self.server.stop()
        self.server = None

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            try:
                self.refresh()
            except Exception:  # a bad frame must not end the view; the next tick tries again
                log.exception("3D view refresh failed")

    # --- static scene --------------------------------------------------------------------------
    def _draw_site(self) -> None:
        assert self.server is not None
        x0, y0, x1, y1 = floor_extent(self.site)
        # Start looking at the whole floor from above its south edge, not at the origin up close.
        cx, cy, span = (x0 + x1) / 2, (y0 + y1) / 2, max(x1 - x0, y1 - y0)
        # A narrower lens than viser's 75 degrees, from farther away: people stay upright on screen
        # instead of leaning outwards towards the edges.
        self.server.initial_camera.fov = math.radians(INITIAL_FOV_DEG)
        self.server.initial_camera.look_at = (cx, cy, 0.0)
        self.server.initial_camera.position = (cx, cy - 0.6 * span, 0.9 * span)
        # An opaque dark plane under a faint 1 m / 5 m grid: bright people and zones stand out on it.
        self.server.scene.add_grid(
            "/floor", width=x1 - x0, height=y1 - y0, plane="xy", position=(cx, cy, 0.0),
            cell_size=1.0, cell_color=GRID_CELL_COLOR, section_size=5.0, section_color=GRID_SECTION_COLOR,
            plane_color=FLOOR_COLOR, plane_opacity=1.0, shadow_opacity=0.35, fade_distance=10.0 * span,
        )
        self._draw_zones()
        self._draw_cameras()

    def _draw_zones(self) -> None:
        assert self.server is not None
        scene = self.server.scene
        for k, zone in enumerate(self.site.zones):
            color = LEVEL_COLORS["unknown"]
            polygon = np.asarray(zone.polygon, dtype=np.float64)
            # Stacked a millimetre apart so overlapping zones do not flicker against each other.
            z = 0.01 + 0.001 * k
            vertices = np.column_stack([polygon, np.full(len(polygon), z)]).astype(np.float32)
            area = scene.add_mesh_simple(f"/zones/{zone.id}/area", vertices, triangulate(polygon), color=color,
                                         opacity=ZONE_OPACITY, side="double", cast_shadow=False, receive_shadow=False)
            outline = scene.add_line_segments(f"/zones/{zone.id}/outline", polyline_segments(polygon, z + 0.005),
                                              colors=color, thickness=0.08)
            self._zones[zone.id] = (area, outline, "unknown")
            cx, cy = polygon.mean(axis=0)
            scene.add_label(f"/zones/{zone.id}/label", zone.name or zone.id, position=(float(cx), float(cy), 0.05),
                            font_screen_scale=1.4, anchor="center-center")

    def _draw_cameras(self) -> None:
        assert self.server is not None
        scene = self.server.scene
        floor = floor_extent(self.site)
        for config in self.site.cameras:
            camera = self.site.camera(config.id)
            w, h = camera.image_size
            scene.add_camera_frustum(f"/cameras/{config.id}", fov=vertical_fov(self.site, config.id), aspect=w / h,
                                     scale=FRUSTUM_SCALE_M, thickness=0.05, color=CAMERA_COLOR,
                                     wxyz=vtf.SO3.from_matrix(camera.R.T).wxyz, position=camera.center,
                                     cast_shadow=False)
            scene.add_label(f"/cameras/{config.id}/label", config.id, position=(0.0, 0.0, 0.0), anchor="bottom-center")
            if config.monitored_radius_m:
                a = np.linspace(0, 2 * np.pi, 96, endpoint=False)
                circle = camera.center[:2] + config.monitored_radius_m * np.column_stack([np.cos(a), np.sin(a)])
                arcs = on_floor(polyline_segments(circle, 0.005), floor)
                if len(arcs):
                    scene.add_line_segments(f"/coverage/{config.id}", arcs, colors=COVERAGE_COLOR, thickness=0.04)

    # --- people --------------------------------------------------------------------------------
    def refresh(self) -> None:
        """Show the latest tracks if they changed since the last refresh."""
        with self._refreshing:  # the refresh thread and a caller must not interleave
            tracks = self.state.tracks
            if self.server is None or tracks is None or tracks.time_ns == self._shown_time_ns:
                return
            with self.server.atomic():
                self._show_people(tracks)
                self._show_violations(tracks)
                self._show_zone_levels()
            self._shown_time_ns = tracks.time_ns

    def _show_zone_levels(self) -> None:
        """Recolour the zones whose occupancy level changed."""
        occupancy = self.state.occupancy
        counts = {z.id: z.count for z in occupancy.zones} if occupancy is not None else {}
        for zone in self.site.zones:
            area, outline, shown = self._zones[zone.id]
            level = level_of(counts.get(zone.id, 0), zone.effective_crowded_level, zone.capacity)
            if level != shown:
                color = LEVEL_COLORS[level]
                area.color = color
                outline.colors = np.tile(np.array(color, dtype=np.uint8), (len(outline.points), 2, 1))
                self._zones[zone.id] = (area, outline, level)

    def _show_people(self, tracks: Tracks) -> None:
        people = tracks.tracks
        positions = np.array([[t.xy[0], t.xy[1], 0.0] for t in people], dtype=np.float32).reshape(-1, 3)
        scales = np.array([[t.radius, t.radius, t.height] for t in people], dtype=np.float32).reshape(-1, 3)
        self._people = self._batched(self._people, "/people", positions, scales, person_colors(tracks))
        self._show_labels(tracks)

    def _batched(
        self, handle: viser.BatchedMeshHandle | None, name: str, positions: np.ndarray, scales: np.ndarray,
        colors: np.ndarray, opacity: float | None = None,
    ) -> viser.BatchedMeshHandle | None:
        """Cylinders at ``positions``: ``handle`` updated in place, or replaced when the count
        changed (so every per-instance array matches), or removed when there are none."""
        assert self.server is not None
        if len(positions) == 0:
            if handle is not None:
                handle.remove()
            return None
        if handle is not None and len(handle.batched_positions) == len(positions):
            handle.batched_positions = positions
            handle.batched_scales = scales
            handle.batched_colors = colors
            return handle
        wxyzs = np.tile(np.array([1.0, 0.0, 0.0, 0.0], dtype=np.float32), (len(positions), 1))
        return self.server.scene.add_batched_meshes_simple(
            name, *self._mesh, batched_wxyzs=wxyzs, batched_positions=positions, batched_scales=scales,
            batched_colors=colors, lod="off", opacity=opacity, cast_shadow=opacity is None,
            receive_shadow=opacity is None,
        )

    def _show_labels(self, tracks: Tracks) -> None:
        assert self.server is not None
        seen = set()
        for t in tracks.tracks:
            seen.add(t.id)
            position = (t.xy[0], t.xy[1], t.height + LABEL_LIFT_M)
            label = self._labels.get(t.id)
            if label is None:
                self._labels[t.id] = self.server.scene.add_label(f"/labels/{t.id}", str(t.id), position=position,
                                                                  anchor="bottom-center", font_screen_scale=1.2)
            else:
                label.position = position
        for gone in set(self._labels) - seen:
            self._labels.pop(gone).remove()

    def _show_violations(self, tracks: Tracks) -> None:
        """A red disc on the floor, half the distance limit wide, under everyone in a violation
        (the discs of a pair overlap), and a red line above the heads of each pair."""
        assert self.server is not None
        where = {t.id: (t.xy[0], t.xy[1]) for t in tracks.tracks}
        pairs = np.array([(where[a], where[b]) for a, b in tracks.violations if a in where and b in where])
        pairs = pairs.reshape(-1, 2, 2)
        if self._lines is not None:
            self._lines.remove()
            self._lines = None
        if len(pairs):
            lines = np.concatenate([pairs, np.full((len(pairs), 2, 1), VIOLATION_LINE_Z_M)], axis=2)
            self._lines = self.server.scene.add_line_segments("/violations/lines", lines.astype(np.float32),
                                                              colors=VIOLATION_COLOR, thickness=VIOLATION_LINE_PX,
                                                              thickness_units="screen")
        feet = np.unique(pairs.reshape(-1, 2), axis=0)
        radius = self.site.thresholds.social_distance_m / 2.0
        positions = np.column_stack([feet, np.full(len(feet), 0.02)]).astype(np.float32)
        scales = np.tile(np.array([radius, radius, 0.01], dtype=np.float32), (len(feet), 1))
        colors = np.tile(np.array(VIOLATION_COLOR, dtype=np.uint8), (len(feet), 1))
        self._discs = self._batched(self._discs, "/violations/discs", positions, scales, colors, DISC_OPACITY)

    # --- for tests and status pages ------------------------------------------------------------
    @property
    def shown_people(self) -> int:
        return 0 if self._people is None else len(self._people.batched_positions)

    @property
    def shown_labels(self) -> list[int]:
        return sorted(self._labels)

    @property
    def shown_violation_lines(self) -> int:
        return 0 if self._lines is None else len(self._lines.points)

    @property
    def shown_violation_discs(self) -> int:
        return 0 if self._discs is None else len(self._discs.batched_positions)
