"""The tracker alone on ideal detections: how many identities a scene costs before any detector.

``ideal_tracking`` feeds the tracker, frame by frame, every annotated person's true floor position
moved by a normal error of ``noise_m`` per axis (each point carrying that error as its
covariance), and nothing else: no misses, no false or duplicate points, no fusion. What it loses
is lost to association over time alone, so beside a replay's own figures it tells whether a
detector, fusion or the tracker holds a scene back. ``bevflow evaluate --ideal-noise`` passes the
replay's own tracker settings (the site's), and the scores are ``bevflow.evaluation.replay``'s
headline.

On CMC2 (``docs/RESULTS.md``), where the replay's tracks lie 0.13 m from the truth on average, the
tracker deciding each update at once (``--hypotheses 1``) given the truth exactly or with 0.05 /
0.10 / 0.15 m of noise scores IDF1 0.91 / 0.86 / 0.63 / 0.58 (four seeds' mean; 0.49–0.73 at
0.10 m) at MOTA 0.98 / 0.98 / 0.95 / 0.94; with 20 hypotheses, the default, 0.99 / 0.89 / 0.77
(0.10 m: six seeds, 0.62–0.89) for the first three. A quarter of
the time a person's nearest neighbour is under 0.58 m away, and a constant-velocity guess one
frame (0.25 s) ahead misses the truth by 0.11 m (median): at that noise, tracks swap in a crowd
where every person is found.
"""

from __future__ import annotations

import math

import numpy as np

from bevflow.datasets.mot import WorldTruth
from bevflow.detections import Cylinders
from bevflow.evaluation.detection import Area, scored_estimates
from bevflow.evaluation.replay import EVERYWHERE, SCORED, headline
from bevflow.evaluation.spread import Spread
from bevflow.metrics.hota import score_hota
from bevflow.metrics.tracking import score_tracking
from bevflow.tracking.hypotheses import online_tracker
from bevflow.tracking.tracker import TrackerConfig

# The least position error a point claims: no fused point claims less (fusion's floor_m, 0.1 m, over
# four views), and a tighter claim shrinks the tracker's gate below a walker's turn.
MIN_NOISE_M = 0.05


def ideal_tracking(
    truth: WorldTruth,
    fps: float,
    noise_m: float,
    tracker: TrackerConfig,
    runs: int = 1,
    area: Area = EVERYWHERE,
    threshold_m: float = 0.5,
) -> dict[str, Spread]:
    """The headline scores (``SCORED``) of ``runs`` ideal replays of ``truth`` (seeds 0 .. runs − 1),
    each position moved by ``noise_m`` (σ, metres, per axis); frame f is at f / ``fps`` seconds,
    as in a replay."""
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    if not (math.isfinite(noise_m) and noise_m >= 0):
        raise ValueError(f"noise_m must be a number of metres >= 0, got {noise_m}")
    if runs < 1:
        raise ValueError(f"runs must be >= 1, got {runs}")
    if not truth.frame_numbers:
        raise ValueError("the truth has no rows: nothing to track")
    runs_scores = [_one_run(truth, fps, noise_m, tracker, seed, area, threshold_m) for seed in range(runs)]
    return {k: Spread.of([r[k] for r in runs_scores]) for k in runs_scores[0]}


def _one_run(truth: WorldTruth, fps: float, noise_m: float, config: TrackerConfig, seed: int, area: Area,
             threshold_m: float) -> dict[str, float]:  # fmt: skip
    rng = np.random.default_rng(seed)
    # With track_views each point is a view of one camera that sees everyone: the tracks take
    # them one to one, and a point no track took is a person of its own.
    tracker = online_tracker(config, fuse=_each_view_a_person)
    variance = max(noise_m, MIN_NOISE_M) ** 2
    gt, found = [], []
    first, last = truth.frame_numbers[0], truth.frame_numbers[-1]
    for frame in range(first, last + 1):
        ids, xy = truth.at(frame)
        seen = xy + rng.normal(0.0, noise_m, xy.shape)
        covariance = np.broadcast_to(variance * np.eye(2), (len(seen), 2, 2))
        camera = np.zeros(len(seen), np.int64) if config.track_views else None
        table = tracker.update(Cylinders(xy=seen, covariance=covariance, camera=camera), frame / fps)
        keep = scored_estimates(area, xy, table.xy, threshold_m)
        gt.append((ids, xy))
        found.append((table.id[keep], table.xy[keep]))
    scores = headline(score_tracking(gt, found, threshold_m), score_hota(gt, found))
    return {k: float(scores[k]) for k in SCORED}


def _each_view_a_person(views: Cylinders) -> Cylinders:
    return Cylinders(xy=views.xy, covariance=views.covariance)
