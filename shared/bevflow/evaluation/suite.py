"""The paper's evaluation suite (its Tables 2 and 3) on the simulated Table 1 sequences.

For every preset of ``bevflow.sim.presets.table1()``, every camera set (all the cameras, and each
camera alone when there are several) and every projection method (cylinder, bbox-center,
nearest-point), the whole pipeline runs as it runs live:

1. **Simulate** the preset once: the scene's frames, and for each camera the boxes of the visible
   silhouettes (``CameraRig.observe``), which are what a perfect detector would give. Occlusion
   is the simulator's, computed from the geometry: people partly hidden by others or by pillars
   and shelves get truncated boxes, and people with less than a quarter of their camera-facing
   surface visible get none (misses). Both grow with the preset's occlusion level, which sets the
   number of occluders and how close people walk (``bevflow.sim.presets``). No extra random miss
   rate is added on top: it would count the same occlusions twice. A camera reports the people
   inside its ``reporting_radius_m`` (the monitored radius plus 0.5 m), as the live projector
   keeps them: a person walking in is tracked before they cross the circle.
2. **Detect**: the detector-noise model (``bevflow.sim.noise``) jitters, drops and adds boxes,
   with the generator ``view_rng(seed, frame, camera)`` where ``camera`` is the camera's index in
   the preset, so a camera gets the same noisy boxes alone and in a pair, and every method sees
   the same boxes. The boxes are passed as their own visible extent (``visible=``): the truncation
   is the simulator's, not the side-view rule of the noise model. With ``detector=True``
   (``bevflow evaluate --suite paper --detector``) the boxes come instead from the shipped person
   detector run on rendered frames (``bevflow.evaluation.rendered``), and the noise model is off.
3. **Project** every box to the floor with the method (``bevflow.cylinder.fit_cylinders``) and
   pass the result through the projector's wire message (``CameraCylinders``), as live.
4. **Fuse, track and analyse** with ``bevflow.live.site_tracker.SiteTracker`` over a site that
   holds only the camera set, one step per frame at the frame's capture time (10 fps).
5. **Score** (``bevflow.metrics.tracking.score_tracking``, matched within 0.5 m on the floor).

What is scored, and why:

- Ground truth: in each frame, every person whose feet lie inside the camera set's monitored area
  (the union of its cameras' monitored circles) and who is in sight of at least one camera of the
  set: some part of the body visible, unhidden by pillars, shelves and other people
  (``CameraView.in_sight_ids``). That is what annotators of the set's videos could mark, and the
  usual MOT practice (a person wholly hidden from every camera is not annotated in that frame).
  Tracks are counted as ``GroundTruthTracks`` counts them: someone who leaves the area and comes
  back is a new ground-truth track, as in the paper; someone hidden for a while inside the area
  keeps their track id, so losing them costs an identity switch or a fragmentation. A camera alone
  has its own ground truth, over its own circle. ``hidden`` reports the share of person-frames
  inside the area left out because no camera of the set could see them at all; ``unseen`` the
  share of the ground truth that no camera of the set boxed (too hidden for a box: a ceiling on
  recall).
- Hypotheses: the tracks ``SiteStep.table`` reports (confirmed tracks, matched this frame or
  coasting one frame), scored as annotated data is scored where the annotation stops at an edge
  (``scored_tracks``). Nobody outside the area is annotated, so an estimate of someone there is
  neither right nor wrong: each frame's estimates are matched one-to-one (within 0.5 m) with
  everyone the cameras see, inside the area or in the band just outside it; an estimate matched
  to someone outside is left out, one matched to someone inside is scored wherever it lies, and
  one matched to nobody is scored when it lies inside the area. So a person 0.1 m outside the
  edge placed 0.1 m inside it is no false positive, and a person 0.1 m inside placed 0.1 m
  outside is found (WILDTRACK's area keeps the second kind too; it has no positions past its edge
  to leave out the first). The tracker itself sees every detection, wherever it lands.
- MT, PT and ML are fractions of the ground-truth tracks, as in the paper's Table 2.
- ``APE`` is the tracking one: the mean distance of the matched pairs, so it can never exceed the
  0.5 m threshold. ``box_APE`` is the projection alone: the mean floor distance between each
  detected box's estimate (before fusion and tracking) and the true feet of the person it came
  from, over the camera set's boxes of people inside its area, with no threshold. Table 3 of the
  paper reports bbox-centre errors above 0.5 m, so its APE was not capped at 0.5 m either.

>>> result = run_suite("paper", frames_scale=0.01, sequences=[6], methods=["cylinder"])
>>> [(row.seq, row.cameras, row.method) for row in result.rows]
[(6, ('cam1',), 'cylinder')]
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bevflow.camera import Camera
from bevflow.cylinder import METHODS, ProjectionMethod, fit_cylinders, projection_method
from bevflow.detect.runtime import Detector
from bevflow.detections import Boxes, Cylinders
from bevflow.evaluation.rendered import RenderedDetector, attribute
from bevflow.live.site_tracker import SiteTracker
from bevflow.metrics.matching import match_positions
from bevflow.metrics.tracking import TrackingScores, score_tracking
from bevflow.schemas import CameraCylinders
from bevflow.sim.noise import DetectorNoise, apply_detector_noise, view_rng
from bevflow.sim.presets import TABLE1, Preset, table1_sequence
from bevflow.sim.scene import Scene
from bevflow.sim.views import CameraRig, CameraView, GroundTruthTracks
from bevflow.stature import with_stature

IntArray = NDArray[np.int64]
FloatArray = NDArray[np.float64]
Frame = tuple[IntArray, FloatArray]

SUITES = ("paper",)
DEFAULT_NOISE = DetectorNoise(jitter=0.03, drop=0.05, false_positives=0.02)
THRESHOLD_M = 0.5
_EPOCH_NS = 1_700_000_000 * 1_000_000_000  # a plausible capture clock; the tracker only uses differences


@dataclass(frozen=True, eq=False)
class SimulatedSequence:
    """A preset run once: the capture time of each frame (ns), everyone on the floor (visit ids
    and feet), and what every camera of the preset saw (``views[frame][camera]``). ``detected``
    (``[frame][camera]``), when present, holds the shipped detector's boxes on rendered frames,
    which then replace the noise model (``bevflow.evaluation.rendered``)."""

    preset: Preset
    time_ns: list[int]
    person_ids: list[IntArray]
    feet_xy: list[FloatArray]
    views: list[list[CameraView]]
    detected: list[list[Boxes]] | None = None

    def __len__(self) -> int:
        return len(self.time_ns)


@dataclass(frozen=True)
class SuiteRow:
    """The scores of one (sequence, camera set, method)."""

    seq: int
    cameras: tuple[str, ...]
    method: str
    scores: TrackingScores
    box_ape: float = math.nan
    unseen: float = math.nan
    hidden: float = math.nan

    def record(self) -> dict[str, Any]:
        """The JSON record: the paper's columns (MT, PT, ML as fractions of the ground-truth
        tracks), IDF1, ``box_APE``, ``unseen`` and ``hidden`` (see the module docstring), and the counts
        behind them."""
        s = self.scores
        return {
            "seq": self.seq,
            "cameras": list(self.cameras),
            "method": self.method,
            "MOTA": s.MOTA,
            "MT": s.MT_fraction,
            "PT": s.PT_fraction,
            "ML": s.ML_fraction,
            "FRAG": s.FRAG,
            "FRAG_ratio": s.FRAG_ratio,
            "P": s.precision,
            "R": s.recall,
            "F1": s.F1,
            "APE": s.APE,
            "IDF1": s.IDF1,
            "box_APE": self.box_ape,
            "unseen": self.unseen,
            "hidden": self.hidden,
            "IDSW": s.IDSW,
            "MOTP": s.MOTP,
            "gt_tracks": s.n_gt_ids,
            "frames": s.frames,
            "tp": s.tp,
            "fp": s.fp,
            "fn": s.fn,
        }


@dataclass(frozen=True)
class SuiteResult:
    """Every row of a suite run, and the settings that produced it."""

    suite: str
    rows: tuple[SuiteRow, ...]
    noise: DetectorNoise
    seed: int
    frames_scale: float
    detector: bool = False
    model: str | None = None  # with ``detector``: the ONNX file, None for the shipped one

    def as_dict(self) -> dict[str, Any]:
        return {
            "suite": self.suite,
            "frames_scale": self.frames_scale,
            "detector": self.detector,
            "model": self.model,
            "seed": self.seed,
            "noise": asdict(self.noise),
            "threshold_m": THRESHOLD_M,
            "rows": [row.record() for row in self.rows],
        }


def paper_presets(frames_scale: float = 1.0, sequences: Iterable[int] | None = None) -> list[Preset]:
    """The Table 1 presets, each shortened to ``max(1, round(frames_scale * frames))`` frames."""
    if not (math.isfinite(frames_scale) and frames_scale > 0):
        raise ValueError(f"frames_scale must be a number > 0, got {frames_scale}")
    numbers = list(TABLE1) if sequences is None else list(sequences)
    presets = [table1_sequence(n) for n in numbers]  # raises on an unknown number
    return [p.with_scene(frames=max(1, round(frames_scale * _length(p)))) for p in presets]


def _length(preset: Preset) -> int:
    if preset.scene.frames is None:
        raise ValueError(f"preset {preset.name} is endless: it has no length to scale")
    return preset.scene.frames


def camera_sets(preset: Preset) -> list[tuple[str, ...]]:
    """All the cameras of the preset, then each camera alone when there are several."""
    ids = tuple(preset.site.camera_ids)
    return [ids] + ([(c,) for c in ids] if len(ids) > 1 else [])


def simulate(preset: Preset, detector: bool = False, model: Path | None = None) -> SimulatedSequence:
    """Run the preset's scene and compute every camera's view of every frame (the slow part).
    A camera reports the people inside its ``reporting_radius_m``, as the live projector keeps
    them. ``detector``: also render every camera's frames and run the person detector on them
    (``model``, default the shipped one for each camera's height; ``bevflow.evaluation.rendered``;
    much slower)."""
    site = preset.site
    rig = CameraRig([site.camera(c.id) for c in site.cameras], [c.reporting_radius_m for c in site.cameras], preset.obstacles())
    chosen = Detector(model, threads=1) if model is not None else None  # None: by height, as live
    rendered = RenderedDetector(site, preset.scene, chosen) if detector else None
    times, ids, feet, views, detected = [], [], [], [], []
    for frame in Scene(preset.scene).run():
        times.append(_EPOCH_NS + round(frame.time_s * 1e9))
        ids.append(frame.person_ids)
        feet.append(frame.feet_xy)
        views.append(rig.observe(frame))
        if rendered is not None:
            detected.append(rendered.boxes(frame))
    return SimulatedSequence(preset, times, ids, feet, views, detected if rendered is not None else None)


@dataclass(frozen=True, eq=False)
class Detections:
    """What every camera's detector and projection gave, for one method: ``cylinders[frame][camera]``
    (camera: index in the preset), and for each camera, over all frames, the floor error of every
    box that came from a real person (``box_error``, NaN where the box could not be placed) and that
    person's true feet (``box_truth``)."""

    cylinders: list[list[Cylinders]]
    box_error: list[FloatArray]
    box_truth: list[FloatArray]


def detect(
    sequence: SimulatedSequence, noise: DetectorNoise, seed: int, methods: Sequence[ProjectionMethod]
) -> dict[str, Detections]:
    """Noisy boxes → cylinders for each method. The noise of frame k, camera c is drawn from
    ``view_rng(seed, k, c)``, once, so every method and camera set sees the same boxes. A
    sequence with ``detected`` boxes uses those instead, and ``noise`` does not apply."""
    site = sequence.preset.site
    cameras = [site.camera(c) for c in site.camera_ids]
    cylinders: dict[str, list[list[Cylinders]]] = {m: [] for m in methods}
    errors: dict[str, list[list[FloatArray]]] = {m: [[] for _ in cameras] for m in methods}
    truths: list[list[FloatArray]] = [[] for _ in cameras]
    for k, views in enumerate(sequence.views):
        for m in methods:
            cylinders[m].append([])
        for c, (camera, view) in enumerate(zip(cameras, views, strict=True)):
            if sequence.detected is not None:
                boxes = _in_reach(sequence.detected[k][c], camera, site.cameras[c].reporting_radius_m)
                source = attribute(boxes, view)
            else:
                noisy = apply_detector_noise(view.boxes, noise, view_rng(seed, k, c), camera.image_size, visible=view.boxes.xyxy)
                boxes, source = noisy.boxes, noisy.source
            real = source >= 0
            truths[c].append(view.feet_xy[source[real]])
            for m in methods:
                fit = with_stature(camera, boxes, fit_cylinders(camera, boxes, m, camera_index=c), m)
                # Through the projector's wire message, as live: unplaceable rows are dropped there.
                wire = CameraCylinders.from_cylinders(site.camera_ids[c], k, sequence.time_ns[k], fit)
                cylinders[m][k].append(wire.to_cylinders(c))
                errors[m][c].append(np.linalg.norm(fit.xy[real] - truths[c][-1], axis=1))
    truth = [np.concatenate(t).reshape(-1, 2) for t in truths]
    return {
        m: Detections(cylinders[m], [np.concatenate(e) if e else np.zeros(0) for e in errors[m]], truth) for m in methods
    }


def _in_reach(boxes: Boxes, camera: Camera, radius_m: float | None) -> Boxes:
    """The boxes the live projector keeps: a real detector sees people far past the monitored
    circle that the simulator's boxes keep to, and the projector drops those (by their cylinder)."""
    return boxes[fit_cylinders(camera, boxes).near(camera.center, radius_m)]


def ground_truth(
    sequence: SimulatedSequence, rig: CameraRig, camera_indices: Sequence[int] | None = None
) -> list[Frame]:
    """Per frame, the ground-truth (track ids, feet): the people inside ``rig``'s monitored area
    in sight of at least one of the cameras ``camera_indices`` (indices in the preset; default:
    every camera of the sequence). Track ids follow the area alone (see ``GroundTruthTracks``)."""
    tracks = GroundTruthTracks(rig)
    out = []
    for ids, feet, views in zip(sequence.person_ids, sequence.feet_xy, sequence.views, strict=True):
        gt = tracks.update(_Frame(ids, feet))
        keep = np.isin(gt.person_ids, _in_sight(views, camera_indices))
        out.append((gt.track_ids[keep], gt.feet_xy[keep]))
    return out


def hidden_share(sequence: SimulatedSequence, rig: CameraRig, camera_indices: Sequence[int]) -> float:
    """The share of person-frames inside ``rig``'s area that no camera of ``camera_indices`` can
    see at all (left out of the ground truth)."""
    total = hidden = 0
    for ids, feet, views in zip(sequence.person_ids, sequence.feet_xy, sequence.views, strict=True):
        inside = ids[rig.monitored(feet).any(axis=1)] if len(ids) else ids
        total += len(inside)
        hidden += int(np.count_nonzero(~np.isin(inside, _in_sight(views, camera_indices))))
    return hidden / total if total else math.nan


def unseen_share(sequence: SimulatedSequence, rig: CameraRig, camera_indices: Sequence[int]) -> float:
    """The share of ground-truth person-frames (inside ``rig``'s area, in sight of a camera) that
    none of the cameras boxes, before any detector noise: too hidden behind occluders or other
    people for a box. No tracker can find them, so recall cannot exceed 1 minus this."""
    total = unseen = 0
    for ids, feet, views in zip(sequence.person_ids, sequence.feet_xy, sequence.views, strict=True):
        inside = ids[rig.monitored(feet).any(axis=1)] if len(ids) else ids
        inside = inside[np.isin(inside, _in_sight(views, camera_indices))]
        seen = np.concatenate([views[c].person_ids for c in camera_indices])
        total += len(inside)
        unseen += int(np.count_nonzero(~np.isin(inside, seen)))
    return unseen / total if total else math.nan


def _in_sight(views: Sequence[CameraView], camera_indices: Sequence[int] | None) -> IntArray:
    chosen = range(len(views)) if camera_indices is None else camera_indices
    return np.concatenate([np.zeros(0, np.int64), *(views[c].in_sight_ids for c in chosen)])


def track(sequence: SimulatedSequence, camera_ids: Sequence[str], cylinders: list[list[Cylinders]]) -> list[Frame]:
    """Per frame, the (ids, feet) of the tracks the live ``SiteTracker`` reports, for a site
    holding only ``camera_ids``; ``cylinders[frame][camera]`` indexes the preset's cameras."""
    site = sequence.preset.site
    subset = site.model_copy(update={"cameras": [c for c in site.cameras if c.id in camera_ids]})
    index = {c: site.camera_index(c) for c in subset.camera_ids}
    tracker = SiteTracker(subset)
    out = []
    for time_ns, per_camera in zip(sequence.time_ns, cylinders, strict=True):
        step = tracker.step(time_ns, {c: per_camera[i] for c, i in index.items()})
        out.append((step.table.id, step.table.xy))
    return out


def evaluate_sequence(
    sequence: SimulatedSequence,
    noise: DetectorNoise = DEFAULT_NOISE,
    seed: int = 0,
    methods: Sequence[ProjectionMethod] = METHODS,
) -> list[SuiteRow]:
    """Every (camera set, method) row of one simulated preset."""
    preset = sequence.preset
    detections = detect(sequence, noise, seed, methods)
    rows = []
    for camera_ids in camera_sets(preset):
        rig = _subset_rig(preset, camera_ids)
        indices = [preset.site.camera_index(c) for c in camera_ids]
        gt = ground_truth(sequence, rig, indices)
        unseen = unseen_share(sequence, rig, indices)
        hidden = hidden_share(sequence, rig, indices)
        for method in methods:
            found = detections[method]
            tracked = track(sequence, camera_ids, found.cylinders)
            hyp = [scored_tracks(rig, *frame) for frame in zip(gt, tracked, _seen_outside(sequence, rig, indices), strict=True)]
            scores = score_tracking(gt, hyp, THRESHOLD_M)
            rows.append(SuiteRow(preset.sequence or 0, camera_ids, method, scores, _box_ape(found, rig, indices), unseen, hidden))
    return rows


def run_suite(
    name: str = "paper",
    frames_scale: float = 1.0,
    noise: DetectorNoise = DEFAULT_NOISE,
    seed: int = 0,
    methods: Sequence[str] = METHODS,
    sequences: Iterable[int] | None = None,
    processes: int = 1,
    detector: bool = False,
    model: Path | None = None,
) -> SuiteResult:
    """Run a suite (only ``"paper"`` exists): rows in the order sequence, camera set, method.
    ``processes`` > 1 runs presets in parallel (each process simulates whole presets).
    ``detector``: boxes from the shipped detector on rendered frames instead of the noise model
    (``noise`` is then unused; see ``bevflow.evaluation.rendered``); ``model``: another ONNX
    detector for that."""
    if name not in SUITES:
        raise ValueError(f"unknown suite {name!r}; choose one of: {', '.join(SUITES)}")
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise ValueError(f"methods must be among {', '.join(METHODS)}, got {list(methods)}")
    presets = paper_presets(frames_scale, sequences)
    chosen = tuple(projection_method(m) for m in methods)
    jobs = [(p, noise, seed, chosen, detector, model) for p in presets]
    if processes > 1 and len(jobs) > 1:
        # Longest presets first, so the last one to finish is short.
        order = sorted(range(len(jobs)), key=lambda k: -_cost(presets[k]))
        with ProcessPoolExecutor(max_workers=min(processes, len(jobs))) as pool:
            done = dict(zip(order, pool.map(_evaluate_preset, [jobs[k] for k in order]), strict=True))
        per_preset = [done[k] for k in range(len(jobs))]
    else:
        per_preset = [_evaluate_preset(job) for job in jobs]
    rows = tuple(row for rows in per_preset for row in rows)
    return SuiteResult(name, rows, noise, seed, frames_scale, detector, str(model) if detector and model else None)


def default_processes() -> int:
    """Worker processes worth starting here: one per core, at most one per preset."""
    return max(1, min(len(TABLE1), os.cpu_count() or 1))


def _evaluate_preset(
    job: tuple[Preset, DetectorNoise, int, tuple[ProjectionMethod, ...], bool, Path | None],
) -> list[SuiteRow]:
    preset, noise, seed, methods, detector, model = job
    return evaluate_sequence(simulate(preset, detector=detector, model=model), noise, seed, methods)


def _cost(preset: Preset) -> float:
    """Rough relative run time of a preset: rendered camera-frames, more for bigger crowds."""
    return float(preset.scene.frames or 0) * len(preset.site.cameras) * (1.0 + (preset.scene.identities or 0) / 5.0)


def _subset_rig(preset: Preset, camera_ids: Sequence[str]) -> CameraRig:
    configs = [c for c in preset.site.cameras if c.id in camera_ids]
    return CameraRig([preset.site.camera(c.id) for c in configs], [c.monitored_radius_m for c in configs])


def _box_ape(found: Detections, rig: CameraRig, camera_indices: Sequence[int]) -> float:
    """Mean floor error of the placed boxes of people inside ``rig``'s area, over the cameras."""
    error = np.concatenate([found.box_error[c] for c in camera_indices])
    truth = np.concatenate([found.box_truth[c] for c in camera_indices]).reshape(-1, 2)
    keep = np.isfinite(error) & (rig.monitored(truth).any(axis=1) if len(truth) else np.zeros(0, dtype=bool))
    return float(error[keep].mean()) if keep.any() else math.nan


def scored_tracks(rig: CameraRig, gt: Frame, hyp: Frame, outside_xy: FloatArray) -> Frame:
    """The tracks of one frame that are scored against ``gt`` (the people inside ``rig``'s
    area): matched one-to-one within ``THRESHOLD_M`` with the ground truth and ``outside_xy``
    (people in sight just outside the area, not annotated), a track is kept when it matches a
    person inside, dropped when it matches someone outside, and otherwise kept when it lies
    inside the area (see the module docstring)."""
    ids, xy = hyp
    if not len(xy):
        return ids, xy
    keep: NDArray[np.bool_] = np.any(rig.monitored(xy), axis=1)
    everyone = np.concatenate([gt[1].reshape(-1, 2), outside_xy.reshape(-1, 2)])
    if len(everyone):
        person, track, _ = match_positions(everyone, xy, THRESHOLD_M)
        keep[track] = person < len(gt[1])
    return ids[keep], xy[keep]


def _seen_outside(sequence: SimulatedSequence, rig: CameraRig, camera_indices: Sequence[int]) -> list[FloatArray]:
    """Per frame, the feet of the people outside ``rig``'s area whom a camera of
    ``camera_indices`` has in sight (the unannotated band past the monitored circles)."""
    out = []
    for ids, feet, views in zip(sequence.person_ids, sequence.feet_xy, sequence.views, strict=True):
        outside = ~rig.monitored(feet).any(axis=1) if len(feet) else np.zeros(0, dtype=bool)
        out.append(feet[outside & np.isin(ids, _in_sight(views, camera_indices))].reshape(-1, 2))
    return out


@dataclass(frozen=True)
class _Frame:
    """The two columns of a ``SceneFrame`` that ``GroundTruthTracks`` reads."""

    person_ids: IntArray
    feet_xy: FloatArray

    def __len__(self) -> int:
        return len(self.person_ids)
