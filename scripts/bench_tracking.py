"""Time ``Tracker.update`` per tick for crowds of 10, 100 and 1,000 people.

People walk at 1.0-1.6 m/s with wandering headings in a square hall sized for ``--density``
people per square metre, seen at ``--fps`` ticks per second as fused cylinders with 5 cm of
position noise, 5 % of detections missed and one false positive a tick. Prints milliseconds
per update after a warm-up (wall-clock median and 95th percentile, and the median CPU time of
the calling thread, steadier on a busy machine), the number of reported tracks, and the MOTA
and IDF1 of the run (0.5 m threshold) to show the timing is of a tracker that works.

    python scripts/bench_tracking.py [--ticks 200] [--people 10 100 1000] [--density 0.1]
    python scripts/bench_tracking.py --json results.json     # also write the numbers as JSON
    python scripts/bench_tracking.py --json                  # JSON on stdout instead of the table
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

from bevflow.detections import Cylinders
from bevflow.metrics.tracking import score_tracking
from bevflow.tracking.tracker import Tracker, TrackerConfig


def walk(people: int, ticks: int, fps: float, density: float, rng: np.random.Generator) -> np.ndarray:
    """True feet positions (ticks, people, 2) of people wandering in a square hall."""
    side = math.sqrt(people / density)
    dt = 1.0 / fps
    xy = rng.uniform(0, side, (people, 2))
    heading = rng.uniform(0, 2 * np.pi, people)
    speed = rng.uniform(1.0, 1.6, people)
    out = np.empty((ticks, people, 2))
    for k in range(ticks):
        out[k] = xy
        heading += rng.normal(0, 0.3 * math.sqrt(dt), people)
        xy = xy + dt * speed[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=1)
        # Walls reflect, so the density stays what was asked for.
        xy = np.abs(xy)
        xy = np.where(xy > side, 2 * side - xy, xy)
    return out


def observe(truth: np.ndarray, side: float, rng: np.random.Generator) -> Cylinders:
    seen = truth[rng.random(len(truth)) >= 0.05]
    xy = np.concatenate([seen + rng.normal(0, 0.05, seen.shape), rng.uniform(0, side, (rng.poisson(1.0), 2))])
    return Cylinders(xy=xy, score=rng.uniform(0.5, 1.0, len(xy)))


def bench(people: int, ticks: int, fps: float, density: float, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    truth = walk(people, ticks, fps, density, rng)
    side = math.sqrt(people / density)
    observations = [observe(xy, side, rng) for xy in truth]  # made up front: not timed
    tracker = Tracker(TrackerConfig())
    wall, cpu, reported, hyp = [], [], [], []
    for k, cylinders in enumerate(observations):
        start, start_cpu = time.perf_counter(), time.thread_time()
        tracks = tracker.update(cylinders, k / fps)
        wall.append(time.perf_counter() - start)
        cpu.append(time.thread_time() - start_cpu)
        reported.append(len(tracks))
        hyp.append((tracks.id, tracks.xy))
    warm = ticks // 10
    ms = np.asarray(wall[warm:]) * 1e3
    scores = score_tracking([(np.arange(people), xy) for xy in truth], hyp, threshold_m=0.5)
    return {
        "people": people,
        "ms_p50": float(np.median(ms)),
        "ms_p95": float(np.percentile(ms, 95)),
        "cpu_ms_p50": float(np.median(np.asarray(cpu[warm:]) * 1e3)),
        "tracks_mean": float(np.mean(reported[warm:])),
        "MOTA": scores.MOTA,
        "IDF1": scores.IDF1,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ticks", type=int, default=200, help="updates per crowd size")
    parser.add_argument("--people", type=int, nargs="+", default=[10, 100, 1000], help="crowd sizes to time")
    parser.add_argument("--density", type=float, default=0.1, help="people per square metre")
    parser.add_argument("--fps", type=float, default=10.0, help="updates per simulated second")
    parser.add_argument(
        "--json", nargs="?", const="-", metavar="PATH", help="also write the results as JSON to PATH (no PATH: stdout)"
    )
    args = parser.parse_args()
    results = [bench(n, args.ticks, args.fps, args.density) for n in args.people]
    document = {"ticks": args.ticks, "fps": args.fps, "density": args.density, "results": results}
    if args.json == "-":
        json.dump(document, sys.stdout, indent=2)
        print()
        return
    print(f"density {args.density} people/m2, {args.fps:g} fps, {args.ticks} ticks")
    print(f"{'people':>7} {'ms/update p50':>14} {'p95':>8} {'cpu p50':>8} {'tracks':>8} {'MOTA':>7} {'IDF1':>7}")
    for r in results:
        print(
            f"{r['people']:>7} {r['ms_p50']:>14.3f} {r['ms_p95']:>8.3f} {r['cpu_ms_p50']:>8.3f} "
            f"{r['tracks_mean']:>8.1f} {r['MOTA']:>7.3f} {r['IDF1']:>7.3f}"
        )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(document, f, indent=2)


if __name__ == "__main__":
    main()
