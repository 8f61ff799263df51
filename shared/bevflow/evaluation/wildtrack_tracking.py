"""Tracking accuracy on an annotated multi-camera dataset (WILDTRACK), end to end.

``evaluate_detection`` makes every frame's fused cylinders (noise -> projection -> fusion); here
they go, in capture-time order, through the one world tracker (``bevflow.tracking.tracker``, as
the live tracker service runs it after fusion) and the tracks it reports are scored against the
annotated identities (``bevflow.metrics.tracking``: MOTA, IDF1, IDSW, MT / PT / ML, FRAG, matched
within ``threshold_m`` on the floor).

Two sets of detection scores come out, and they are not the same thing:

- the **per-frame** scores (``detection``): the fused cylinders of each frame on their own;
- the **tracked** scores (``scores.MODA``, ``precision``, ...): the tracker's output, which is
  missing the first ``activate_hits − 1`` frames of every new track, bridges a missed frame of a
  confirmed track (``report_max_misses``) at its predicted position, and does not report a false
  positive seen in one frame only (it never gets the hits to be confirmed).

Time. The tracker predicts with real time steps: frame f is captured at
``f × dataset.seconds_per_frame_number`` (WILDTRACK: 0.5 s between annotated frames, so a walker
moves about 0.7 m between two of them).

Tracker settings (``WILDTRACK_TRACKER``); everything else is the tracker's default.

- ``activate_hits=2``. The paper's 3 hits to confirm a track take 1 s at 2 frames per second:
  every person appearing would be missing for 2 frames (about 400 misses over the 200 frames).
  Two hits (0.5 s) still reject a false positive seen in one frame only, which is what the rule
  is for (170 of the 216 false positives of the fused detections are such).
- ``process_noise=0.1`` (m²/s³, default 0.3). Over 0.5 s steps the default lets a track's
  velocity follow the noise of the fused feet (0.1–0.4 m along a side camera's line of sight),
  and tracks swap more (seed 0: 126 identity switches against 93). 0.1 scored a higher IDF1 and
  MOTA on each half of the frames with each of two noise seeds (``docs/RESULTS.md`` lists all
  of them, and the defaults' numbers).

- ``coast_needs_sighting=True``. A confirmed track missed in a frame is reported there only when
  a camera still sees part of someone near its predicted feet (a cut box that placed nobody,
  ``Fusion.sightings``). A person hidden behind another on these side views nearly always
  leaves such a box; a track coasting on where nobody is seen is mostly a person who has left,
  or a ghost (seed 0: tracked false positives 316 → 174, misses 274 → 353).

- ``gate_chi2=None``: gated by distance alone and costed by distance. The Mahalanobis gate (the
  default elsewhere) with its likelihood costs gains IDF1 here but loses MOTA (seed 0: IDF1 0.863
  → 0.869, MOTA 0.869 → 0.865, tracked MODA 0.896 → 0.891), so it is not used.

Settled. The same tracker's output one update late (``bevflow.tracking.settled``: a new track's
first detection and a missed update bridged by the next one are reported) is scored as well, as
``settled``: what history and offline analysis can have, where live alerts cannot wait.

Area. The tracker sees every fused cylinder, inside the annotated area or not (a person walking in
from outside arrives with their track); the tracks are scored like detections
(``scored_estimates``): those inside the area, and those outside it that match a person inside.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any, Protocol, Unpack

import numpy as np
from numpy.typing import NDArray

from bevflow.detections import Cylinders
from bevflow.evaluation.detection import (
    AnnotatedDataset,
    Area,
    DetectionEvaluation,
    DetectionOptions,
    evaluate_detection,
    scored_estimates,
)
from bevflow.metrics.tracking import TrackingScores, score_tracking
from bevflow.tracking.settled import SettledTracks
from bevflow.tracking.hypotheses import final_updates, last_updates, online_tracker
from bevflow.tracking.tracker import TrackerConfig, TrackTable

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Frame = tuple[IntArray, FloatArray]

WILDTRACK_TRACKER = TrackerConfig(
    activate_hits=2, process_noise=0.1, confirm_multi_view=True, coast_needs_sighting=True, gate_chi2=None
)
"""The tracker settings for 2 annotated frames per second (see the module docstring)."""

TRACKING_KEYS = ("MOTA", "MOTP", "IDF1", "IDP", "IDR", "IDSW", "MT", "PT", "ML", "FRAG", "FRAG_ratio")
TRACKED_DETECTION_KEYS = ("MODA", "MODP", "precision", "recall", "F1", "APE", "tp", "fp", "fn")


@dataclass(frozen=True)
class TrackingEvaluation:
    """Per-frame detection scores and the tracked output's scores of one run."""

    detection: DetectionEvaluation
    tracker: TrackerConfig
    seconds_per_frame_number: float
    scores: TrackingScores
    tracks: int  # distinct track ids reported in the scored frames
    settled: TrackingScores  # the same tracks one update late (module docstring, "Settled")

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: the detection dictionary as it is (its ``MODA``, ``precision``, ... are the
        per-frame fused detections), plus the tracking scores as top-level keys (``MOTA``,
        ``IDF1``, ``IDSW``, ``MT``, ``ML``, ``FRAG``, ...), ``tracked_MODA`` and the tracked
        output's detection scores under ``tracked``, and the settled output's tracking and
        detection scores under ``settled``."""
        s = self.scores
        out = self.detection.as_dict()
        out.update({k: getattr(s, k) for k in TRACKING_KEYS})
        out["tracked_MODA"] = s.MODA
        out["tracked"] = {k: getattr(s, k) for k in TRACKED_DETECTION_KEYS}
        out["settled"] = {k: getattr(self.settled, k) for k in (*TRACKING_KEYS, *TRACKED_DETECTION_KEYS)}
        out["gt_tracks"] = s.n_gt_ids
        out["tracks"] = self.tracks
        out["tracker"] = asdict(self.tracker)
        out["seconds_per_frame_number"] = self.seconds_per_frame_number
        return out


class TimedDataset(AnnotatedDataset, Protocol):
    """An annotated dataset whose frame numbers map to capture times."""

    @property
    def seconds_per_frame_number(self) -> float: ...


def evaluate_tracking(
    dataset: TimedDataset,
    tracker: TrackerConfig = WILDTRACK_TRACKER,
    detection: DetectionEvaluation | None = None,
    **detection_options: Unpack[DetectionOptions],
) -> TrackingEvaluation:
    """Track the fused cylinders of ``evaluate_detection(dataset, **detection_options)`` (or of
    ``detection``, a run already made on ``dataset``) and score the tracks.

    ``dataset`` must have ``seconds_per_frame_number`` (the capture time of a frame number)."""
    if detection is None:
        detection = evaluate_detection(dataset, **detection_options)
    elif detection_options:
        raise TypeError("pass either a finished detection run or options for a new one, not both")
    seconds = float(dataset.seconds_per_frame_number)
    by_number = {int(f.frame): f for f in dataset.frames}
    frames = [by_number[n] for n in detection.frame_numbers]
    if len(detection.fused) != len(frames):
        raise ValueError("the detection run kept no fused cylinders per frame; run evaluate_detection again")
    gt, hyp, settled_hyp = track_and_match_both(
        [(f.person_ids, f.feet_xy) for f in frames],
        detection.fused,
        [n * seconds for n in detection.frame_numbers],
        dataset.area,
        tracker,
        detection.threshold_m,
        detection.sightings or None,
    )
    scores = score_tracking(gt, hyp, detection.threshold_m)
    ids = np.unique(np.concatenate([h[0] for h in hyp])) if hyp else np.zeros(0)
    return TrackingEvaluation(detection, tracker, seconds, scores, len(ids), score_tracking(gt, settled_hyp, detection.threshold_m))


def track_and_match(
    gt: Sequence[Frame],
    fused: Sequence[Cylinders],
    times_s: Sequence[float],
    area: Area,
    config: TrackerConfig,
    threshold_m: float = 0.5,
    sightings: Sequence[Cylinders] | None = None,
    settled: bool = False,
) -> tuple[list[Frame], list[Frame]]:
    """Run one tracker over ``fused`` (one set of cylinders per frame, at ``times_s``, increasing;
    ``sightings``, when given, one ``Fusion.sightings`` per frame) and return, per frame, the
    ground truth and the scored tracks ``(ids, feet)``: those inside ``area`` or matching a person
    (``scored_estimates``). ``settled``: the tracks one update late (``SettledTracks``) instead of
    the online ones."""
    gt_out, online, late = track_and_match_both(gt, fused, times_s, area, config, threshold_m, sightings)
    return gt_out, late if settled else online


def track_and_match_both(
    gt: Sequence[Frame],
    fused: Sequence[Cylinders],
    times_s: Sequence[float],
    area: Area,
    config: TrackerConfig,
    threshold_m: float = 0.5,
    sightings: Sequence[Cylinders] | None = None,
) -> tuple[list[Frame], list[Frame], list[Frame]]:
    """``track_and_match``'s ground truth, online tracks and settled tracks, from one pass of
    the tracker."""
    if sightings is None:
        sightings = [Cylinders.empty()] * len(fused)
    if not (len(gt) == len(fused) == len(times_s) == len(sightings)):
        raise ValueError(
            f"gt, fused, times_s and sightings differ in length: {len(gt)}, {len(fused)}, {len(times_s)}, {len(sightings)}"
        )
    tracker = online_tracker(config, keep_final=True)
    online: list[TrackTable] = []
    settled: list[TrackTable] = []
    late = SettledTracks()
    for cylinders, seen, time_s in zip(fused, sightings, times_s, strict=True):
        online.append(tracker.update(cylinders, time_s, seen))
        settled += late.push_each(final_updates(tracker, time_s))
    settled += late.push_each(last_updates(tracker))
    if (frame := late.flush()) is not None:
        settled.append(frame.tracks)
    gt_out = [(np.asarray(ids, dtype=np.int64), np.asarray(feet, dtype=np.float64)) for ids, feet in gt]

    def scored(tables: list[TrackTable]) -> list[Frame]:
        keep = [scored_estimates(area, feet, t.xy, threshold_m) for (_, feet), t in zip(gt_out, tables, strict=True)]
        return [(t.id[k], t.xy[k]) for t, k in zip(tables, keep, strict=True)]

    return gt_out, scored(online), scored(settled)
