"""What the tracker service does with one assembled tick, without the bus: track the site, and
watch the cameras' calibration.

``TickHandler.handle`` takes a tick of the cameras' ``CameraCylinders`` messages and returns the
messages to publish: the tracks, the occupancy and the events (the analytics' alerts, and a
``calibration_drift`` event when a camera seems to have moved). ``main`` publishes them; tests call
``handle`` directly with ticks from a ``TickAssembler``.

Drift is judged on the per-camera cylinders *before* fusion (``DriftMonitor``): it needs each
camera's own estimate of a person that two cameras see, which fusion merges away.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from functools import cached_property

from bevflow.calibration.drift import DriftConfig, DriftMonitor
from bevflow.detections import Cylinders
from bevflow.live.assembler import Tick
from bevflow.live.site_tracker import SiteTracker
from bevflow.schemas import CalibrationDrift, CameraCylinders, Event, Occupancy, Tracks
from bevflow.site import Site

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class TickOutput:
    """The messages one tick produced, in publishing order (tracks, occupancy, then events). The
    tracks come as their wire JSON (``SiteStep.tracks_json``); ``tracks`` reads it back."""

    tracks_json: bytes
    occupancy: Occupancy
    events: list[Event] = field(default_factory=list)

    @cached_property
    def tracks(self) -> Tracks:
        return Tracks.model_validate_json(self.tracks_json)


class TickHandler:
    """Steps ``tracker`` with each tick and, unless ``drift`` is None, a ``DriftMonitor`` too.

    Args:
        site: the site; ``CameraCylinders.camera`` ids are looked up in it.
        tracker: the site's fusion, tracker and analytics.
        drift: the settings of the calibration drift watch; None turns it off.
    """

    def __init__(self, site: Site, tracker: SiteTracker, drift: DriftConfig | None = DriftConfig()) -> None:
        self.site = site
        self.tracker = tracker
        self.drift = None if drift is None else DriftMonitor(site.camera_ids, drift)
        self.drift_errors = 0

    def handle(self, tick: Tick[CameraCylinders]) -> TickOutput:
        """Track one tick. Errors of the tracker raise (the caller skips the tick); an error of the
        drift watch is logged and counted, since tracking must go on without it."""
        per_camera = {c: m.to_cylinders(self.site.camera_index(c)) for c, m in tick.items.items()}
        step = self.tracker.step(tick.time_ns, per_camera)
        events: list[Event] = list(step.events)
        events += self._drift(tick.time_ns, per_camera)
        return TickOutput(step.tracks_json, step.occupancy, events)

    def _drift(self, time_ns: int, per_camera: dict[str, Cylinders]) -> list[CalibrationDrift]:
        if self.drift is None:
            return []
        try:
            found = self.drift.update(time_ns, Cylinders.merge(list(per_camera.values())))
        except Exception:  # a bug in the watch must not stop tracking
            self.drift_errors += 1
            log.exception("calibration drift check failed at tick %d", time_ns)
            return []
        for event in found:
            if event.end_ns is None:
                log.warning("camera %s seems to have moved: its estimates shifted %.2f m against %s",
                            event.camera, event.shift_m, event.reference_camera)
            else:
                log.info("camera %s agrees with its neighbours again", event.camera)
        return [e.model_copy(update={"raised_ns": time_ns}) for e in found]
