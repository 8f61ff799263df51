"""Time ``SiteAnalytics.update`` per tick for crowds of 10, 100 and 1,000 people.

People walk at random (1.2 m/s, wandering headings) in a square hall sized for ``--density``
people per square metre (0.2 is a busy concourse; at 0.5 nearly everyone is within 2 m of someone),
with four zones and a capacity, at 10 ticks per second. Prints milliseconds per tick after a
warm-up: wall-clock median and 95th percentile, and the median CPU time of the calling thread
(steadier than wall-clock on a busy machine); then open violations and events published per tick.

    python scripts/bench_analytics.py [--ticks 300] [--people 10 100 1000] [--density 0.2]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from bevflow.analytics.engine import SiteAnalytics
from bevflow.site import Site

TICK_NS = 100_000_000


def make_site(side: float, people: int) -> Site:
    h = side / 2
    square = lambda x0, y0: [(x0, y0), (x0 + h, y0), (x0 + h, y0 + h), (x0, y0 + h)]  # noqa: E731
    return Site.model_validate(
        {
            "site": "bench",
            "cameras": [
                {
                    "id": "c0",
                    "image_size": [1024, 1024],
                    "intrinsics": {"fx": 300, "fy": 300, "cx": 512, "cy": 512},
                    "pose": {"position": [h, h, 5.0]},
                }
            ],
            "zones": [
                {"id": f"z{i}", "polygon": square(x0, y0), "capacity": max(1, people // 5)}
                for i, (x0, y0) in enumerate([(0, 0), (h, 0), (0, h), (h, h)])
            ],
            "thresholds": {"site_capacity": people},
        }
    )


def bench(people: int, ticks: int, density: float, seed: int = 0) -> tuple[float, float, float, float, float]:
    side = math.sqrt(people / density)
    rng = np.random.default_rng(seed)
    analytics = SiteAnalytics(make_site(side, people))
    ids = np.arange(people)
    xy = rng.uniform(0, side, (people, 2))
    heading = rng.uniform(0, 2 * np.pi, people)
    times, cpu, pairs, events = [], [], [], []
    for k in range(ticks):
        heading += rng.normal(0, 0.3, people)
        xy = np.clip(xy + 0.12 * np.stack([np.cos(heading), np.sin(heading)], 1), 0, side)
        start, start_cpu = time.perf_counter(), time.thread_time()
        tick = analytics.update(k * TICK_NS, ids, xy)
        times.append(time.perf_counter() - start)
        cpu.append(time.thread_time() - start_cpu)
        pairs.append(len(tick.violations))
        events.append(len(tick.events))
    ms = np.asarray(times[ticks // 10 :]) * 1e3
    cpu_ms = np.asarray(cpu[ticks // 10 :]) * 1e3
    return (
        float(np.median(ms)),
        float(np.percentile(ms, 95)),
        float(np.median(cpu_ms)),
        float(np.mean(pairs)),
        float(np.mean(events)),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ticks", type=int, default=300, help="ticks per crowd size (10 per simulated second)")
    parser.add_argument("--people", type=int, nargs="+", default=[10, 100, 1000], help="crowd sizes to time")
    parser.add_argument("--density", type=float, default=0.2, help="people per square metre")
    args = parser.parse_args()
    print(f"density {args.density} people/m2, {args.ticks} ticks")
    print(f"{'people':>7} {'ms/tick p50':>12} {'p95':>8} {'cpu p50':>8} {'open violations':>16} {'events/tick':>12}")
    for n in args.people:
        p50, p95, cpu50, open_pairs, events = bench(n, args.ticks, args.density)
        print(f"{n:>7} {p50:>12.3f} {p95:>8.3f} {cpu50:>8.3f} {open_pairs:>16.1f} {events:>12.1f}")


if __name__ == "__main__":
    main()
