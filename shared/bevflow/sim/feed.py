"""Simulated cameras reporting detections, frame by frame: what the live demo and the live
benchmarks feed the pipeline until real frames and the detector take over.

One ``SimulatedFeed`` runs the crowd of a site (``scene_for_site``), looks at it through every
camera (``CameraRig``) and passes each camera's exact boxes through the detector-noise model.
Ground truth comes with every frame: the people on the monitored floor, with track ids counted
the way the paper counts them.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from bevflow.detections import Boxes
from bevflow.sim.noise import DetectorNoise, apply_detector_noise, view_rng
from bevflow.sim.presets import PRESETS, Preset, SceneChanges
from bevflow.sim.scene import Door, Scene, SceneConfig, SceneFrame
from bevflow.sim.views import GroundTruth, GroundTruthTracks
from bevflow.site import Site

LIVE_NOISE = DetectorNoise(jitter=0.02, drop=0.05, false_positives=0.02)


@dataclass(frozen=True, eq=False)
class SimulatedFrame:
    index: int
    time_s: float
    truth: GroundTruth
    detections: list[Boxes]  # one per camera of the site, in the site's camera order


def scene_for_site(site: Site, people: int | None = None, seed: int = 0) -> Preset:
    """An endless crowd for ``site``: the built-in preset's crowd when the site is one of them
    (``demo-hall``), otherwise people walking between doors in the middle of each wall of the
    floor (the site's ``floor``, or the box around the cameras' monitored circles)."""
    if site.site in PRESETS:
        preset = PRESETS[site.site]()
        changes: SceneChanges = {"frames": None, "seed": seed}
        if people is not None:
            changes["people"], changes["identities"] = people, None
        return Preset(site.site, site, preset.with_scene(**changes).scene)
    x0, y0, x1, y1 = site.floor or _coverage_box(site)
    doors = (Door(x0, (y0 + y1) / 2), Door(x1, (y0 + y1) / 2), Door((x0 + x1) / 2, y0), Door((x0 + x1) / 2, y1))
    crowd = people if people is not None else max(4, int((x1 - x0) * (y1 - y0) / 30.0))
    scene = SceneConfig(floor=(x0, y0, x1, y1), entries=doors, identities=None, people=crowd, frames=None, seed=seed)
    return Preset(site.site, site, scene)


def _coverage_box(site: Site) -> tuple[float, float, float, float]:
    boxes = []
    for config in site.cameras:
        centre = site.camera(config.id).center
        radius = config.monitored_radius_m or max(2.0, 1.5 * centre[2])
        boxes.append((centre[0] - radius, centre[1] - radius, centre[0] + radius, centre[1] + radius))
    b = np.array(boxes)
    return float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 2].max()), float(b[:, 3].max())


class SimulatedFeed:
    """Iterate to get ``SimulatedFrame``s at the scene's frame rate (``preset.scene.fps``)."""

    def __init__(self, preset: Preset, noise: DetectorNoise = LIVE_NOISE, seed: int = 0) -> None:
        self.preset = preset
        self.noise = noise
        self.seed = seed
        self.rig = preset.rig()
        self.image_sizes = [preset.site.camera(c).image_size for c in preset.site.camera_ids]

    @property
    def fps(self) -> float:
        return self.preset.scene.fps

    def __iter__(self) -> Iterator[SimulatedFrame]:
        for frame, truth in self.scene_frames():
            yield self.observe(frame, truth)

    def scene_frames(self) -> Iterator[tuple[SceneFrame, GroundTruth]]:
        """The crowd alone, frame by frame, with its ground truth: cheap. A live feed that falls
        behind skips ``observe`` (the expensive part) for the frames it drops."""
        truth = GroundTruthTracks(self.rig)
        for frame in Scene(self.preset.scene).run():
            yield frame, truth.update(frame)

    def observe(self, frame: SceneFrame, truth: GroundTruth) -> SimulatedFrame:
        """What every camera reports of ``frame``, through the detector-noise model."""
        detections = [Boxes.empty() for _ in self.image_sizes]
        for view in self.rig.observe(frame):
            c = view.camera_index
            rng = view_rng(self.seed, frame.index, c)
            noisy = apply_detector_noise(view.boxes, self.noise, rng, self.image_sizes[c], visible=view.boxes.xyxy)
            detections[c] = noisy.boxes
        return SimulatedFrame(frame.index, frame.time_s, truth, detections)
