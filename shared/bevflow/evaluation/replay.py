"""Tracking accuracy of recorded detector output, replayed through the live pipeline.

A user checks bevflow against their own detector, or a public dataset, with each camera's boxes in
files (``bevflow.datasets.mot``) and the people's floor positions. Frame by frame, each camera's
boxes (confidence at least ``min_confidence``, by default ``MIN_CONFIDENCE`` as for the command) go
through the projector's work (``bevflow.live.projection``) and then one step of the tracker
service's work (``bevflow.live.site_tracker.SiteTracker``: fusion, the one tracker, analytics), so
what is scored is what runs live. Frame f is captured at f / fps seconds, and every frame number
from the first in the files to the last annotated one is a step, boxes or not (a frame nobody
detected anything in is still time passing for the tracker); frames from the first to the last
annotated one are scored, a frame without truth rows as one with nobody in it.

Scores (matched within ``threshold_m`` on the floor):

- the online tracks, as the tracker service publishes them: CLEAR-MOT, IDF1 and detection scores
  (``bevflow.metrics.tracking``) and HOTA (``bevflow.metrics.hota``);
- ``settled``: the same tracker's output one update late (``bevflow.tracking.settled``), after
  what several hypotheses (``bevflow.tracking.hypotheses``) decided a window later where the site
  holds them;
- ``detection``: each frame's fused cylinders on their own, before tracking;
- ``cameras``: each camera's own views against the truth (``bevflow.evaluation.camera_errors``);
- ``identities``: each person's frames by the online track that followed them, where identities
  are lost (``bevflow.evaluation.identities``).

Area: the tracker sees everything, but estimates outside ``area`` that match nobody are neither
right nor wrong (``scored_estimates``, as for WILDTRACK): nobody outside it is annotated.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from bevflow.datasets.mot import MIN_CONFIDENCE, DetectionRecording, WorldTruth, check_no_long_gap
from bevflow.detections import Cylinders
from bevflow.evaluation.camera_errors import CameraError, CameraErrorSamples
from bevflow.evaluation.detection import Area, scored_estimates
from bevflow.evaluation.identities import IdentityBreakdown, identity_breakdown
from bevflow.live.projection import CameraProjection
from bevflow.live.site_tracker import SiteTracker
from bevflow.metrics.detection import DetectionScores, score_detections
from bevflow.metrics.hota import HotaScores, score_hota
from bevflow.metrics.tracking import TrackingScores, score_tracking
from bevflow.site import Site
from bevflow.tracking.hypotheses import final_updates, last_updates
from bevflow.tracking.settled import SettledTracks
from bevflow.tracking.tracker import TrackerConfig, TrackTable

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Frame = tuple[IntArray, FloatArray]

HEADLINE = ("MODA", "MOTA", "IDF1", "HOTA", "DetA", "AssA", "IDSW", "precision", "recall", "APE", "frames")
SCORED = tuple(k for k in HEADLINE if k != "frames")  # the headline's scores (frames is a count)


@dataclass(frozen=True)
class Everywhere:
    """No area limit: every estimate is scored."""

    def contains(self, xy: FloatArray) -> NDArray[np.bool_]:
        return np.ones(len(xy), dtype=bool)


EVERYWHERE = Everywhere()


def headline(s: TrackingScores, h: HotaScores) -> dict[str, float]:
    """``HEADLINE`` from one run's tracking and HOTA scores."""
    return {"MODA": s.MODA, "MOTA": s.MOTA, "IDF1": s.IDF1, "HOTA": h.HOTA, "DetA": h.DetA, "AssA": h.AssA,
            "IDSW": s.IDSW, "precision": s.precision, "recall": s.recall, "APE": s.APE, "frames": s.frames}


@dataclass(frozen=True)
class ReplayEvaluation:
    frame_numbers: tuple[int, ...]  # the scored frames
    fps: float
    min_confidence: float
    threshold_m: float
    tracker: TrackerConfig
    scores: TrackingScores  # the online tracks
    hota: HotaScores
    settled: TrackingScores
    settled_hota: HotaScores
    detection: DetectionScores  # each frame's fused cylinders, before tracking
    identities: IdentityBreakdown  # each person's frames by the online track that followed them
    cameras: tuple[CameraError, ...] = ()  # each camera's views against the truth, in site order
    tracks: tuple[tuple[int, TrackTable], ...] = field(default=(), repr=False, compare=False)
    """(frame number, online tracks) for every replayed frame, inside the area or not."""

    def headline(self) -> dict[str, float]:
        """``HEADLINE``: the online tracks' scores (MODA is theirs too)."""
        return headline(self.scores, self.hota)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: ``HEADLINE`` as top-level keys, then every score of the online tracks under
        ``tracked``, the settled ones under ``settled``, the fused detections' under ``detection``
        and where identities are lost under ``identities``."""
        out: dict[str, Any] = self.headline()
        out.update({
            "detection_MODA": self.detection.MODA,
            "tracked": {**self.scores.as_dict(), **self.hota.as_dict()},
            "settled": {**self.settled.as_dict(), **self.settled_hota.as_dict()},
            "detection": self.detection.as_dict(),
            "cameras": [c.as_dict() for c in self.cameras],
            "identities": self.identities.as_dict(),
            "fps": self.fps,
            "min_confidence": self.min_confidence,
            "threshold_m": self.threshold_m,
            "tracker": asdict(self.tracker),
            "first_frame": self.frame_numbers[0],
            "last_frame": self.frame_numbers[-1],
        })
        return out


def replay_tracking(
    site: Site,
    recording: DetectionRecording,
    truth: WorldTruth,
    fps: float,
    area: Area = EVERYWHERE,
    min_confidence: float = MIN_CONFIDENCE,
    tracker: TrackerConfig | None = None,
    threshold_m: float = 0.5,
) -> ReplayEvaluation:
    """Replay ``recording`` through the live pipeline of ``site`` and score it against ``truth``
    (module docstring). ``tracker`` default: the site's settings, as the tracker service runs
    them; the frame rate reaches them through the time between updates (the tracker's gates
    follow the filter's uncertainty, which grows with it). ``RecordingError`` where the frames
    leave an hour without a row (``bevflow.datasets.mot.check_no_long_gap``)."""
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    if not truth.frame_numbers:
        raise ValueError("the truth has no rows: nothing to score")
    site_cameras = [site.camera(c) for c in site.camera_ids]
    config = tracker or TrackerConfig.from_thresholds(site.thresholds, site_cameras)
    first_scored, last = truth.frame_numbers[0], truth.frame_numbers[-1]
    check_no_long_gap({**recording.frames_by_file(last), "the truth": truth.by_frame.keys()}, fps)
    first = min([first_scored, *recording.frame_numbers[:1]])
    run = _Run(site, config, area, threshold_m)
    projection = CameraProjection(site)
    cameras = CameraErrorSamples(site.camera_ids, site_cameras, truth, fps, threshold_m)
    for frame in range(first, last + 1):
        per_camera = {c.camera_id: projection.project(c.camera_id, boxes) for c in recording.cameras
                      if len(boxes := c.boxes(frame, min_confidence))}
        run.step(frame, frame / fps, per_camera, truth.at(frame) if frame >= first_scored else None)
        if frame >= first_scored:
            cameras.add(frame, per_camera)
    return replace(run.finish(tuple(range(first_scored, last + 1)), fps, min_confidence), cameras=cameras.errors())


class _Run:
    """The site tracker and what is kept of each step for scoring."""

    def __init__(self, site: Site, config: TrackerConfig, area: Area, threshold_m: float) -> None:
        self.site_tracker = SiteTracker(site, tracker_config=config, keep_final=True)
        self.config, self.area, self.threshold_m = config, area, threshold_m
        self.late = SettledTracks()
        self.tracks: list[tuple[int, TrackTable]] = []
        self.settled: list[TrackTable] = []
        self.gt: list[Frame] = []
        self.fused: list[FloatArray] = []
        self.scored_from: int | None = None  # index in ``tracks`` of the first scored frame

    def step(self, frame: int, time_s: float, per_camera: dict[str, Cylinders], gt: Frame | None) -> None:
        result = self.site_tracker.step(round(time_s * 1e9), per_camera)
        self.tracks.append((frame, result.table))
        self.settled += self.late.push_each(final_updates(self.site_tracker.tracker, time_s))
        if gt is None:
            return
        if self.scored_from is None:
            self.scored_from = len(self.tracks) - 1
        self.gt.append(gt)
        fused = result.fusion.fused.xy
        self.fused.append(fused[scored_estimates(self.area, gt[1], fused, self.threshold_m)])

    def finish(self, frame_numbers: tuple[int, ...], fps: float, min_confidence: float) -> ReplayEvaluation:
        self.settled += self.late.push_each(last_updates(self.site_tracker.tracker))
        if (settled := self.late.flush()) is not None:
            self.settled.append(settled.tracks)
        start = self.scored_from or 0
        online = self._scored([t for _, t in self.tracks[start:]])
        late = self._scored(self.settled[start:])
        return ReplayEvaluation(
            frame_numbers=frame_numbers, fps=fps, min_confidence=min_confidence, threshold_m=self.threshold_m,
            tracker=self.config,
            scores=score_tracking(self.gt, online, self.threshold_m), hota=score_hota(self.gt, online),
            settled=score_tracking(self.gt, late, self.threshold_m), settled_hota=score_hota(self.gt, late),
            detection=score_detections([g[1] for g in self.gt], self.fused, self.threshold_m),
            identities=identity_breakdown(self.gt, online, self.threshold_m),
            tracks=tuple(self.tracks),
        )

    def _scored(self, tables: list[TrackTable]) -> list[Frame]:
        """Each frame's tracks inside the area, or outside it and matching a person."""
        out = []
        for (_, gt_xy), table in zip(self.gt, tables, strict=True):
            keep = scored_estimates(self.area, gt_xy, table.xy, self.threshold_m)
            out.append((table.id[keep], table.xy[keep]))
        return out
