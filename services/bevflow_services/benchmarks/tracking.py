"""Time the site's central tick, fusion + tracking + analytics, as the tracker service runs it.

``SiteTracker.step`` is timed on a site of C ceiling fisheyes (5.5 m high, 8 m monitored radius)
in a square grid 10 m apart, so neighbouring circles overlap and every point of the floor is seen
by one to four cameras (two on average). P people wander over the floor at 1.0-1.6 m/s. Each
camera reports the people inside its circle as its own noisy copy (feet noise growing with the
distance from the camera, 5 % missed, a few weak fits, false positives), so the tick meets what
the projector delivers, without running the simulator or the cylinder fit: what is timed is the
tick alone. Observations are made before timing starts, and carry the covariance of each feet
position as the projector sends it (``bevflow.fusion.with_position_covariance``, computed once per
detection where the camera is); ``--covariance fusion`` leaves it out, so fusion computes it in the
tick, as it does for callers that hand ``SiteTracker`` bare cylinders (the evaluation suite).

Per tick it reports the wall-clock median and 95th percentile, the median CPU time of the
thread, and a breakdown of that CPU time into the stages of the step: fusion, tracker, analytics
and the rest (merging the cameras' inputs and building the wire messages). MOTA and IDF1 of the
reported tracks against the walkers show the tick timed is one that tracks.
"""

from __future__ import annotations

import cProfile
import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

import bevflow.live.site_tracker as site_tracker_module
from bevflow.detections import Cylinders
from bevflow.fusion import with_position_covariance
from bevflow.live.site_tracker import SiteTracker
from bevflow.metrics.tracking import score_tracking
from bevflow.site import CameraConfig, Intrinsics, Pose, Site, Thresholds, Zone

from bevflow_services.benchmarks.timing import percentile

CAMERA_SPACING_M = 10.0
CAMERA_HEIGHT_M = 5.5
MONITORED_RADIUS_M = 8.0
FPS = 10.0
STAGES = ("fusion", "tracker", "analytics")
COVARIANCE_SOURCES = ("projector", "fusion")
DEFAULT_HYPOTHESES: int = Thresholds.model_fields["track_hypotheses"].default  # what a site holds


def grid_site(cameras: int, people: int, hypotheses: int = DEFAULT_HYPOTHESES, track_views: bool = False) -> Site:
    """A site of ``cameras`` fisheyes in a near-square grid, four zones (the floor's quarters)
    and a capacity of ``people``; its tracker holds ``hypotheses`` ways of matching open and
    takes fused people (a site's default) or the cameras' views itself (``track_views``)."""
    cols = math.ceil(math.sqrt(cameras))
    rows = math.ceil(cameras / cols)
    width, depth = cols * CAMERA_SPACING_M, rows * CAMERA_SPACING_M
    configs = [
        CameraConfig(
            id=f"cam-{k + 1}",
            image_size=(1280, 1280),
            intrinsics=Intrinsics(fx=1280 / math.pi, fy=1280 / math.pi, cx=639.5, cy=639.5),
            pose=Pose(position=((k % cols + 0.5) * CAMERA_SPACING_M, (k // cols + 0.5) * CAMERA_SPACING_M, CAMERA_HEIGHT_M)),
            monitored_radius_m=MONITORED_RADIUS_M,
        )
        for k in range(cameras)
    ]
    w, d = width / 2, depth / 2
    zones = [
        Zone(id=f"zone-{i + 1}", polygon=[(x, y), (x + w, y), (x + w, y + d), (x, y + d)], capacity=max(1, people // 5))
        for i, (x, y) in enumerate([(0, 0), (w, 0), (0, d), (w, d)])
    ]
    return Site(site="bench", cameras=configs, zones=zones, floor=(0.0, 0.0, width, depth),
                thresholds=Thresholds(site_capacity=max(1, people), track_hypotheses=hypotheses, track_views=track_views))


def walk(people: int, ticks: int, floor: tuple[float, float, float, float], rng: np.random.Generator) -> np.ndarray:
    """True feet positions (ticks, people, 2) of people wandering over ``floor``; walls reflect."""
    x0, y0, x1, y1 = floor
    size = np.array([x1 - x0, y1 - y0])
    dt = 1.0 / FPS
    xy = rng.uniform(0, 1, (people, 2)) * size
    heading = rng.uniform(0, 2 * np.pi, people)
    speed = rng.uniform(1.0, 1.6, people)
    out = np.empty((ticks, people, 2))
    for k in range(ticks):
        out[k] = xy + [x0, y0]
        heading += rng.normal(0, 0.3 * math.sqrt(dt), people)
        xy = np.abs(xy + dt * speed[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=1))
        xy = np.where(xy > size, 2 * size - xy, xy)
    return out


def observe(site: Site, truth: np.ndarray, rng: np.random.Generator) -> dict[str, Cylinders]:
    """Each camera's cylinders of the people ``truth`` (P, 2) inside its monitored circle."""
    centres = np.array([c.pose.position[:2] for c in site.cameras])  # type: ignore[union-attr]
    distance = np.linalg.norm(truth[:, None, :] - centres[None], axis=2)  # (P, C)
    out = {}
    for c, config in enumerate(site.cameras):
        seen = np.flatnonzero((distance[:, c] < MONITORED_RADIUS_M) & (rng.random(len(truth)) >= 0.05))
        noise = 0.03 + 0.01 * distance[seen, c]  # a monocular fit gets worse away from the camera
        xy = truth[seen] + rng.normal(0, 1, (len(seen), 2)) * noise[:, None]
        false = rng.poisson(0.2)
        angle, radius = rng.uniform(0, 2 * np.pi, false), MONITORED_RADIUS_M * np.sqrt(rng.uniform(0, 1, false))
        xy = np.concatenate([xy, centres[c] + np.stack([radius * np.cos(angle), radius * np.sin(angle)], 1)])
        n = len(xy)
        score = np.where(rng.random(n) < 0.1, rng.uniform(0.1, 0.3, n), rng.uniform(0.5, 1.0, n))
        out[config.id] = Cylinders(xy=xy, height=rng.normal(1.7, 0.05, n), radius=rng.normal(0.3, 0.02, n),
                                   score=score, occluded=rng.random(n) < 0.05)
    return out


@dataclass
class StageClock:
    """CPU seconds of this thread spent in each stage of the ticks timed so far (CPU time, so a
    stage's share does not depend on what else the machine was doing)."""

    seconds: dict[str, list[float]]

    def wrap(self, stage: str, call: Callable) -> Callable:
        def timed(*args: object, **kwargs: object) -> object:
            start = time.thread_time()
            try:
                return call(*args, **kwargs)
            finally:
                self.seconds[stage].append(time.thread_time() - start)

        return timed


@contextmanager
def stage_clock(tracker: SiteTracker) -> Iterator[StageClock]:
    """Time the stages of ``tracker.step`` without copying it: its tracker and analytics are
    wrapped on the instance, and the fusion function where ``site_tracker`` looks it up."""
    clock = StageClock({stage: [] for stage in STAGES})
    fuse = site_tracker_module.fuse_cylinders
    site_tracker_module.fuse_cylinders = clock.wrap("fusion", fuse)  # type: ignore[assignment]
    tracker.tracker.update = clock.wrap("tracker", tracker.tracker.update)  # type: ignore[method-assign]
    tracker.analytics.update = clock.wrap("analytics", tracker.analytics.update)  # type: ignore[method-assign]
    try:
        yield clock
    finally:
        site_tracker_module.fuse_cylinders = fuse  # type: ignore[assignment]
        del tracker.tracker.update, tracker.analytics.update


def with_projector_covariance(site: Site, per_camera: dict[str, Cylinders]) -> dict[str, Cylinders]:
    """Each camera's cylinders carrying their position covariance, as the projector sends them."""
    cameras = [site.camera(c) for c in site.camera_ids]
    return {c: with_position_covariance(cyl.with_camera(site.camera_index(c)), cameras) for c, cyl in per_camera.items()}


def bench_tick(people: int, cameras: int, ticks: int = 100, warmup: int = 20, seed: int = 0,
               profiler: cProfile.Profile | None = None, covariance: str = "projector", hypotheses: int = DEFAULT_HYPOTHESES,
               track_views: bool = False) -> dict:  # fmt: skip
    """Time ``ticks`` steps after ``warmup`` untimed ones (tracks need a few hits to confirm);
    ``profiler`` (optional) is enabled around the timed steps only. ``covariance`` says where the
    position covariances come from: "projector" (with the cylinders) or "fusion" (in the tick).
    ``track_views``: the tracks take the cameras' views themselves (``--track-views``)."""
    if covariance not in COVARIANCE_SOURCES:
        raise ValueError(f"covariance must be one of {COVARIANCE_SOURCES}, got {covariance!r}")
    rng = np.random.default_rng(seed)
    site = grid_site(cameras, people, hypotheses, track_views)
    truth = walk(people, warmup + ticks, site.floor, rng)  # type: ignore[arg-type]
    observations = [observe(site, xy, rng) for xy in truth]
    if covariance == "projector":
        observations = [with_projector_covariance(site, per_camera) for per_camera in observations]
    tracker = SiteTracker(site)
    period_ns = int(1e9 / FPS)
    t0 = 1_700_000_000_000_000_000
    wall, cpu, hyp, inputs, violations, events = [], [], [], [], [], []
    with stage_clock(tracker) as clock:
        for k, per_camera in enumerate(observations):
            if k == warmup:
                for times in clock.seconds.values():
                    times.clear()
            profiling = profiler is not None and k >= warmup
            if profiling:
                profiler.enable()  # type: ignore[union-attr]
            start, start_cpu = time.perf_counter(), time.thread_time()
            step = tracker.step(t0 + k * period_ns, per_camera)
            wall.append(time.perf_counter() - start)
            cpu.append(time.thread_time() - start_cpu)
            if profiling:
                profiler.disable()  # type: ignore[union-attr]
            hyp.append((step.table.id, step.table.xy))
            inputs.append(sum(len(c) for c in per_camera.values()))
            violations.append(len(step.analytics.violations))
            events.append(len(step.events))
    ms = [s * 1e3 for s in wall[warmup:]]
    stages = {stage: float(np.median(times) * 1e3) for stage, times in clock.seconds.items()}
    cpu_ms = float(np.median(cpu[warmup:]) * 1e3)
    scores = score_tracking([(np.arange(people), xy) for xy in truth[warmup:]], hyp[warmup:], threshold_m=0.5)
    return {
        "people": people,
        "cameras": cameras,
        "covariance": covariance,
        "ticks": ticks,
        "cylinders_per_tick": float(np.mean(inputs[warmup:])),
        "ms_p50": float(np.median(ms)),
        "ms_p95": percentile(ms, 95),
        "cpu_ms_p50": cpu_ms,
        "stage_cpu_ms_p50": {**stages, "rest": cpu_ms - sum(stages.values())},
        "open_violations_per_tick": float(np.mean(violations[warmup:])),
        "events_per_tick": float(np.mean(events[warmup:])),
        "MOTA": scores.MOTA,
        "IDF1": scores.IDF1,
    }


def bench_grid(people: list[int], cameras: list[int], ticks: int, warmup: int, seed: int = 0,
               covariance: str = "projector", hypotheses: int = DEFAULT_HYPOTHESES, track_views: bool = False) -> list[dict]:
    """``bench_tick`` for every (people, cameras) pair."""
    return [bench_tick(p, c, ticks, warmup, seed, covariance=covariance, hypotheses=hypotheses, track_views=track_views)
            for c in cameras for p in people]


def format_rows(rows: list[dict]) -> list[str]:
    lines = [f"{'people':>7} {'cameras':>7} {'cyl/tick':>8} {'ms p50':>8} {'p95':>8} {'cpu p50':>8} "
             f"{'fusion':>7} {'tracker':>7} {'analyt.':>7} {'rest':>7} {'MOTA':>6} {'IDF1':>6}"]
    for r in rows:
        s = r["stage_cpu_ms_p50"]
        lines.append(
            f"{r['people']:>7} {r['cameras']:>7} {r['cylinders_per_tick']:>8.0f} {r['ms_p50']:>8.2f} {r['ms_p95']:>8.2f} "
            f"{r['cpu_ms_p50']:>8.2f} {s['fusion']:>7.2f} {s['tracker']:>7.2f} {s['analytics']:>7.2f} "
            f"{s['rest']:>7.2f} {r['MOTA']:>6.3f} {r['IDF1']:>6.3f}"
        )
    return lines


def main(argv: list[str] | None = None) -> None:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--people", type=int, nargs="+", default=[10, 100, 1000])
    parser.add_argument("--cameras", type=int, nargs="+", default=[4, 16, 64])
    parser.add_argument("--ticks", type=int, default=100, help="timed ticks per case")
    parser.add_argument("--warmup", type=int, default=20, help="untimed ticks first")
    parser.add_argument("--covariance", choices=COVARIANCE_SOURCES, default="projector",
                        help="where position covariances come from: with the cylinders, as the projector sends "
                        "them (default), or computed by fusion in the tick")
    parser.add_argument("--hypotheses", type=int, default=DEFAULT_HYPOTHESES,
                        help=f"the site's track_hypotheses: ways of matching held open (default {DEFAULT_HYPOTHESES}, "
                        "a site's)")
    parser.add_argument("--track-views", action="store_true",
                        help="the tracks take every camera's views themselves (the site's track_views true), instead of "
                        "following the fused people (a site's default)")
    parser.add_argument("--profile", action="store_true",
                        help="profile the timed steps of the first case (cProfile, thread CPU time) instead of timing")
    args = parser.parse_args(argv)
    if not 1 <= args.hypotheses <= 100:
        parser.error(f"--hypotheses must be a whole number from 1 to 100, got {args.hypotheses}")
    if args.profile:
        import pstats

        profiler = cProfile.Profile(time.thread_time)
        bench_tick(args.people[0], args.cameras[0], args.ticks, args.warmup, profiler=profiler,
                   covariance=args.covariance, hypotheses=args.hypotheses, track_views=args.track_views)
        pstats.Stats(profiler).sort_stats("tottime").print_stats(30)
        return
    rows = bench_grid(args.people, args.cameras, args.ticks, args.warmup, covariance=args.covariance,
                      hypotheses=args.hypotheses, track_views=args.track_views)
    for line in format_rows(rows):
        print(line, flush=True)


if __name__ == "__main__":
    main()
