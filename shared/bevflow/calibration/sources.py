"""Where a consistency check gets its people from: each source yields, frame by frame, every
camera's cylinders projected with the calibration under test (keyed by camera index).

- an annotated dataset (WILDTRACK): its annotated boxes stand in for the detector;
- a simulated crowd: the preset's cameras as they truly hang make the boxes, and the calibration
  under test places them on the floor, so a wrong calibration shows as offsets;
- messages of the running system (``CameraCylinders``, already projected by the projectors),
  grouped into ticks of capture time since cameras are not synchronised.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from bevflow.camera import Camera
from bevflow.cylinder import fit_cylinders
from bevflow.detections import Cylinders
from bevflow.schemas import CameraCylinders
from bevflow.site import Site

if TYPE_CHECKING:  # a protocol only: the evaluation modules are not loaded for a check
    from bevflow.evaluation.detection import AnnotatedDataset

Frame = dict[int, Cylinders]


@dataclass(frozen=True)
class CheckSource:
    """The cameras (as calibrated) with their ids, and the frames of cylinders to check."""

    cameras: list[Camera]
    camera_ids: list[str]
    frames: Iterable[Frame]


def dataset_source(dataset: AnnotatedDataset, site: Site | None = None, frames: int | None = None) -> CheckSource:
    """A WILDTRACK-like dataset (``camera_ids``, ``cameras``, ``frames`` with ``views``); with
    ``site``, its cameras of the same ids replace the dataset's own calibration."""
    ids = list(dataset.camera_ids)
    cameras: list[Camera] = list(dataset.cameras)
    if site is not None:
        missing = [c for c in ids if c not in site.camera_ids]
        if missing:
            raise ValueError(f"the site has no camera {', '.join(missing)} (the dataset's cameras are {', '.join(ids)})")
        cameras = [site.camera(c) for c in ids]

    def generate() -> Iterator[Frame]:
        for frame in dataset.frames[:frames]:
            yield {i: fit_cylinders(cam, view.boxes) for i, (cam, view) in enumerate(zip(cameras, frame.views, strict=True))}

    return CheckSource(cameras, ids, generate())


def simulated_source(preset_name: str, site: Site | None = None, frames: int = 100) -> CheckSource:
    """``frames`` frames of a simulation preset (``bevflow.sim.presets``); ``site`` is the
    calibration to check (default: the preset's own, which is exact)."""
    from bevflow.sim.presets import preset
    from bevflow.sim.scene import Scene

    chosen = preset(preset_name).with_scene(frames=frames)
    site = site if site is not None else chosen.site
    ids = chosen.site.camera_ids
    missing = [c for c in ids if c not in site.camera_ids]
    if missing:
        raise ValueError(f"the site has no camera {', '.join(missing)} (the simulated cameras are {', '.join(ids)})")
    cameras = [site.camera(c) for c in ids]
    rig = chosen.rig()  # the cameras as they truly hang: the preset's own

    def generate() -> Iterator[Frame]:
        for frame in Scene(chosen.scene):
            views = rig.observe(frame)
            yield {i: fit_cylinders(cam, view.boxes) for i, (cam, view) in enumerate(zip(cameras, views, strict=True))}

    return CheckSource(cameras, list(ids), generate())


def message_source(site: Site, messages: Sequence[CameraCylinders], tick_ns: int = 100_000_000, frames: int | None = None) -> CheckSource:
    """Projector messages grouped into ticks: messages whose capture times round to the same
    multiple of ``tick_ns`` form one frame."""
    unknown = sorted({m.camera for m in messages} - set(site.camera_ids))
    if unknown:
        raise ValueError(f"cylinders of camera(s) {', '.join(unknown)}, which the site does not have")
    ticks: dict[int, Frame] = {}
    for message in messages:
        index = site.camera_index(message.camera)
        tick = ticks.setdefault(round(message.capture_ns / tick_ns), {})
        tick[index] = Cylinders.merge([tick.get(index, Cylinders.empty()), message.to_cylinders(index)])
    selected = [ticks[t] for t in sorted(ticks)][:frames]
    return CheckSource([site.camera(c) for c in site.camera_ids], list(site.camera_ids), selected)
