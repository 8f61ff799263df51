"""The paper suite with the shipped detector instead of the noise model (``--detector``).

Each camera's view of every frame is rendered (``bevflow.sim.render``: the calibrated fisheye,
the room's walls, pillars and shelves, textured people) straight at the detector's input scale
(``bevflow.detect.scaling``), as a live camera's frame would reach the detector after its resize.
The shipped model (``bevflow.detect.runtime.Detector``) finds the people, and its boxes are
mapped back to the calibrated image's pixels; from there on the suite runs as with simulated
boxes (projection, fusion, tracking, scoring), against the same ground truth.

Each box is attributed to the person whose simulated box (``CameraView.boxes``, the visible
silhouette) it overlaps most, with IoU at least ``MATCH_IOU``, one box per person; that only
feeds the per-box error (``box_APE``): a box attributed to nobody is a false positive there,
and the tracking scores never use the attribution.

Rendering and detection cost 0.04–0.2 s per camera-frame (a 235 px frame at 3.3 m to a 507 px
one at 5.5 m, measured on a loaded 2-core machine), so use a small ``--frames-scale``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from bevflow.detect.runtime import RENDER_TRAINED_RANGES, Detector, DetectorBank
from bevflow.detect.window import Window, detection_window, scaled_window
from bevflow.detections import Boxes
from bevflow.evaluation.detector import iou_matrix
from bevflow.sim.render import FisheyeRenderer, Room
from bevflow.sim.render_textures import Appearance, RenderStyle
from bevflow.sim.scene import SceneConfig, SceneFrame
from bevflow.sim.views import CameraView
from bevflow.site import Site

IntArray = NDArray[np.int64]
MATCH_IOU = 0.3


class RenderedDetector:
    """Renders each camera of ``site`` over the static scene of ``scene`` and runs ``detector``
    on the frames (default: the render-trained model for the camera's height, ``RENDER_TRAINED_RANGES``, one
    thread), within each camera's detection window
    as the detector service does (``whole_frame``: on all of it). ``boxes(frame)`` gives one
    ``Boxes`` per camera, in site order, in the calibrated cameras' pixels."""

    def __init__(
        self, site: Site, scene: SceneConfig, detector: Detector | None = None, seed: int = 0, whole_frame: bool = False
    ) -> None:
        bank = DetectorBank(RENDER_TRAINED_RANGES, threads=1)
        self.detectors = [detector if detector is not None else _scaled_model(bank, site.camera(c.id).center[2])
                          for c in site.cameras]
        self.seed = seed
        self.style = RenderStyle.plain()
        room = Room.from_scene(scene)
        self.renderers: list[FisheyeRenderer] = []
        self.factors: list[float] = []
        self.windows: list[Window] = []
        for config, camera_detector in zip(site.cameras, self.detectors, strict=True):
            camera = site.camera(config.id)
            w, _ = camera.image_size
            ideal = camera_detector.scale_for(float(camera.center[2]), float(camera.K[0, 0]))
            # Scale by the rounded width's ratio, so boxes map back exactly (as a resized frame would).
            factor = max(int(round(w * ideal)), 1) / w
            scaled = camera.scaled(factor)
            self.renderers.append(FisheyeRenderer(scaled, room))
            self.factors.append(factor)
            # The detector service searches only this window of each frame.
            window = None if whole_frame else detection_window(camera, config.reporting_radius_m)
            self.windows.append(scaled_window(window, factor, *scaled.image_size))
        self._rng = np.random.default_rng(seed)

    def boxes(self, frame: SceneFrame) -> list[Boxes]:
        """Every camera's detections in ``frame`` (one ``Boxes`` per camera, site order)."""
        bodies = frame.primitives()
        appearance = Appearance.for_identities(frame.identity, self.seed)
        out = []
        for renderer, detector, factor, (x0, y0, x1, y1) in zip(
            self.renderers, self.detectors, self.factors, self.windows, strict=True
        ):
            image = renderer.render(bodies, frame.person_ids, appearance, self.style, self._rng).image
            found = detector.detect_scaled(image[y0:y1, x0:x1], 1.0)
            # Window pixels → detector-scale pixels → calibrated pixels (pixel-centre coordinates).
            xyxy = found.xyxy + [x0, y0, x0, y0]
            out.append(Boxes(xyxy=(xyxy + 0.5) / factor - 0.5, confidence=found.confidence))
        return out


def attribute(boxes: Boxes, view: CameraView) -> IntArray:
    """Per detected box, the row of ``view`` (the person) it shows, or -1: a one-to-one match on
    IoU with the simulated silhouette boxes, pairs below ``MATCH_IOU`` left unmatched."""
    source = np.full(len(boxes), -1, dtype=np.int64)
    if not len(boxes) or not len(view):
        return source
    iou = iou_matrix(boxes.xyxy, view.boxes.xyxy)
    rows, cols = linear_sum_assignment(-iou)
    good = iou[rows, cols] >= MATCH_IOU
    source[rows[good]] = cols[good]
    return source


def _scaled_model(bank: DetectorBank, height_m: float) -> Detector:
    """The model for a camera this high; frames are rendered straight at its input scale, which
    only a single-input model has (the rim tiles need the camera's own frame)."""
    model = bank.for_height(height_m)
    if not isinstance(model, Detector):
        raise TypeError(f"a camera {height_m:g} m high would get {type(model).__name__}, which cannot take a frame rendered at its scale")
    return model
