"""Simulated cameras that deliver pictures: a site's crowd rendered through every camera.

``RenderedCameras`` holds one ``FisheyeRenderer`` per camera of a site, each tracing that
camera's own calibrated model at the detector's input scale (``bevflow.detect.scaling``): a
frame as a real camera would deliver it, already resized the way the detector would resize it,
so the live demo pays for neither the full-resolution render nor the resize. The rendered size is
rounded to whole pixels and the model scaled by exactly that ratio, so a consumer that maps
boxes back with ``frame width / calibrated width`` lands on the calibrated pixels.

Every person keeps their clothes from frame to frame and from camera to camera
(``Appearance.for_identities``), as the same person would look the same to every camera.

>>> from bevflow.sim.presets import table1_sequence
>>> from bevflow.sim.scene import Scene
>>> p = table1_sequence(1).with_scene(frames=1)
>>> cams = RenderedCameras(p.site, p.scene)
>>> frame = next(Scene(p.scene).run())
>>> cams.render(p.site.camera_ids[0], frame).image.shape == (*cams.frame_size(p.site.camera_ids[0])[::-1], 3)
True
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from bevflow.detect.scaling import scale_factor
from bevflow.sim.bodies import BodyPrimitives
from bevflow.sim.render import FisheyeRenderer, Rendering, Room
from bevflow.sim.render_textures import Appearance, RenderStyle
from bevflow.sim.scene import SceneConfig, SceneFrame
from bevflow.site import Site


def detector_frame_size(site: Site, camera_id: str) -> tuple[int, int]:
    """(width, height) of ``camera_id``'s frame at the detector's input scale."""
    camera = site.camera(camera_id)
    factor = scale_factor(float(camera.center[2]), float(camera.K[0, 0]))
    w, h = camera.image_size
    width = max(int(round(w * factor)), 1)
    return width, max(int(round(h * width / w)), 1)  # the height Camera.scaled(width / w) gives


class RenderedCameras:
    """Renderers for ``cameras`` of ``site`` (default: all) over the static scene of ``scene``
    (floor, walls, pillars, shelves). ``style`` is the look of every camera (default: plain)."""

    def __init__(
        self,
        site: Site,
        scene: SceneConfig,
        cameras: Sequence[str] | None = None,
        style: RenderStyle | None = None,
        wall_height_m: float = 4.0,
        seed: int = 0,
    ) -> None:
        self.site = site
        self.style = style if style is not None else RenderStyle.plain()
        self.seed = seed
        room = Room.from_scene(scene, wall_height=wall_height_m)
        self.renderers: dict[str, FisheyeRenderer] = {}
        for camera_id in cameras if cameras is not None else site.camera_ids:
            camera = site.camera(camera_id)
            w, _ = camera.image_size
            size = detector_frame_size(site, camera_id)
            # Scale by the rounded ratio, not the ideal factor: the frame's width then says exactly
            # how it maps to the calibrated image.
            self.renderers[camera_id] = FisheyeRenderer(camera.scaled(size[0] / w), room)
        self._rng = np.random.default_rng(seed)

    @property
    def camera_ids(self) -> list[str]:
        return list(self.renderers)

    def frame_size(self, camera_id: str) -> tuple[int, int]:
        """(width, height) of the frames ``render`` makes for ``camera_id``."""
        return self.renderers[camera_id].camera.image_size

    def render(
        self,
        camera_id: str,
        frame: SceneFrame,
        bodies: BodyPrimitives | None = None,
        appearance: Appearance | None = None,
    ) -> Rendering:
        """``camera_id``'s view of ``frame``. Pass ``bodies`` (``frame.primitives()``) and
        ``appearance`` when rendering several cameras of one frame, to pose the crowd once."""
        bodies = bodies if bodies is not None else frame.primitives()
        appearance = appearance if appearance is not None else Appearance.for_identities(frame.identity, self.seed)
        return self.renderers[camera_id].render(bodies, frame.person_ids, appearance, self.style, self._rng)

    def render_all(self, frame: SceneFrame) -> dict[str, Rendering]:
        """Every camera's view of ``frame``, by camera id."""
        bodies = frame.primitives()
        appearance = Appearance.for_identities(frame.identity, self.seed)
        return {c: self.render(c, frame, bodies, appearance) for c in self.renderers}
