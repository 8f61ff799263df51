"""The live 3D view: a viser server showing the floor, the cameras, the zones and the people.

People are one batched mesh of unit cylinders, scaled per person to their fitted radius and
height (one message for the whole crowd instead of one per person); each has an id label; pairs
closer than the social-distance limit get a red line between them. A background thread refreshes
the scene from ``GatewayState`` a few times a second, inside ``server.atomic()`` so a browser
never shows half an update.
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

from bevflow_services.gateway.state import GatewayState

log = logging.getLogger(__name__)

PERSON_COLOR = (60, 140, 230)
VIOLATION_COLOR = (230, 40, 40)
ZONE_COLOR = (40, 170, 90)
LABEL_LIFT_M = 0.25


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
        self._mesh = unit_cylinder()

    @property
    def port(self) -> int | None:
        return None if self.server is None else self.server.get_port()

    def start(self) -> None:
        self.server = viser.ViserServer(host=self.host, port=self.requested_port, verbose=False)
        self.server.scene.set_up_direction("+z")
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
        scene = self.server.scene
        x0, y0, x1, y1 = floor_extent(self.site)
        # Start looking at the whole floor from above its south edge, not at the origin up close.
        cx, cy, span = (x0 + x1) / 2, (y0 + y1) / 2, max(x1 - x0, y1 - y0)
        self.server.initial_camera.look_at = (cx, cy, 0.0)
        self.server.initial_camera.position = (cx, cy - 0.8 * span, 0.7 * span)
        scene.add_grid("/floor", width=x1 - x0, height=y1 - y0, plane="xy", position=((x0 + x1) / 2, (y0 + y1) / 2, 0.0),
                       cell_size=1.0, section_size=5.0)
        for config in self.site.cameras:
            camera = self.site.camera(config.id)
            w, h = camera.image_size
            scene.add_camera_frustum(f"/cameras/{config.id}", fov=vertical_fov(self.site, config.id), aspect=w / h,
                                     scale=0.4, color=(30, 30, 30), wxyz=vtf.SO3.from_matrix(camera.R.T).wxyz,
                                     position=camera.center)
            scene.add_label(f"/cameras/{config.id}/label", config.id, position=(0.0, 0.0, 0.0))
            if config.monitored_radius_m:
                a = np.linspace(0, 2 * np.pi, 64, endpoint=False)
                circle = camera.center[:2] + config.monitored_radius_m * np.column_stack([np.cos(a), np.sin(a)])
                scene.add_line_segments(f"/coverage/{config.id}", polyline_segments(circle, 0.005), colors=(150, 150, 150),
                                        thickness=0.02)
        for zone in self.site.zones:
            polygon = np.asarray(zone.polygon, dtype=np.float64)
            scene.add_line_segments(f"/zones/{zone.id}", polyline_segments(polygon, 0.01), colors=ZONE_COLOR, thickness=0.05)
            cx, cy = polygon.mean(axis=0)
            scene.add_label(f"/zones/{zone.id}/label", zone.name or zone.id, position=(float(cx), float(cy), 0.05))

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
            self._shown_time_ns = tracks.time_ns

    def _show_people(self, tracks: Tracks) -> None:
        assert self.server is not None
        people = tracks.tracks
        if not people:
            if self._people is not None:
                self._people.remove()
                self._people = None
        else:
            positions = np.array([[t.xy[0], t.xy[1], 0.0] for t in people], dtype=np.float32)
            scales = np.array([[t.radius, t.radius, t.height] for t in people], dtype=np.float32)
            violating = {i for pair in tracks.violations for i in pair}
            colors = np.array([VIOLATION_COLOR if t.id in violating else PERSON_COLOR for t in people], dtype=np.uint8)
            if self._people is not None and len(self._people.batched_positions) == len(people):
                self._people.batched_positions = positions
                self._people.batched_scales = scales
                self._people.batched_colors = colors
            else:
                # The instance count changed: replace the node (same name) so every array matches.
                wxyzs = np.tile(np.array([1.0, 0.0, 0.0, 0.0], dtype=np.float32), (len(people), 1))
                self._people = self.server.scene.add_batched_meshes_simple(
                    "/people", *self._mesh, batched_wxyzs=wxyzs, batched_positions=positions,
                    batched_scales=scales, batched_colors=colors, lod="off",
                )
        self._show_labels(tracks)

    def _show_labels(self, tracks: Tracks) -> None:
        assert self.server is not None
        seen = set()
        for t in tracks.tracks:
            seen.add(t.id)
            position = (t.xy[0], t.xy[1], t.height + LABEL_LIFT_M)
            label = self._labels.get(t.id)
            if label is None:
                self._labels[t.id] = self.server.scene.add_label(f"/labels/{t.id}", str(t.id), position=position,
                                                                  anchor="bottom-center")
            else:
                label.position = position
        for gone in set(self._labels) - seen:
            self._labels.pop(gone).remove()

    def _show_violations(self, tracks: Tracks) -> None:
        assert self.server is not None
        where = {t.id: (t.xy[0], t.xy[1], 1.0) for t in tracks.tracks}
        pairs = [(where[a], where[b]) for a, b in tracks.violations if a in where and b in where]
        if self._lines is not None:
            self._lines.remove()
            self._lines = None
        if pairs:
            self._lines = self.server.scene.add_line_segments("/violations", np.array(pairs, dtype=np.float32),
                                                              colors=VIOLATION_COLOR, thickness=0.05)

    # --- for tests and status pages ------------------------------------------------------------
    @property
    def shown_people(self) -> int:
        return 0 if self._people is None else len(self._people.batched_positions)

    @property
    def shown_labels(self) -> list[int]:
        return sorted(self._labels)
