"""Soak: run the live system for minutes and report each service's memory growth and the
messages dropped along the pipeline.

    python -m bevflow_services.benchmarks.soak --minutes 10 --cameras 16

The pipeline is ``start_pipeline``'s with simulated boxes (ingest, projector, tracker, recorder
into a temporary SQLite file, gateway) on ``hall_site(cameras)``, each camera at 10 fps. Every
``--sample-every`` seconds the resident memory (RSS, from ``/proc``) of each service is read.
Drops are counted from the outside, on the bus, where each stage's output can be matched to its
input:

- ingest: scene frames skipped at the source (gaps in the simulator's frame numbers);
- projector: camera frames whose detections never came out as cylinders;
- tracker: tracker ticks missing from the regular tick grid;
- gateway: what its own subscriptions counted as dropped or rejected (``/api/health``).

Memory growth is the least-squares slope of RSS over the run after ``--warmup`` seconds, in
MiB per minute, over the whole run and over its second half, and the difference between the last
and the first sample; the RSS at the start of each minute shows whether the growth levels off.
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import threading
import time
import urllib.error
import urllib.request
from collections import defaultdict
from pathlib import Path
from typing import Any

from bevflow.schemas import CameraCylinders, Detections2D, SimulatedTruth, Tracks
from bevflow.site import dump_site

from bevflow_services import bus
from bevflow_services.benchmarks.live import FPS, PEOPLE_PER_CAMERA, hall_site
from bevflow_services.launcher import ServiceGroup, free_port, start_pipeline

MiB = 1 << 20
TICK_NS = 100_000_000  # the tracker's default --tick-ms


def rss_bytes(pid: int) -> int | None:
    """Resident memory of a process (Linux ``/proc``); None once it is gone."""
    try:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


class StreamLog:
    """What the stages publish, reduced to what drop counts need: per camera the detection and
    cylinder sequence numbers, the simulator's frame numbers and the tracker's tick times."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.recording = False
        self.detections: dict[str, set[int]] = defaultdict(set)
        self.cylinders: dict[str, set[int]] = defaultdict(set)
        self.frames: set[int] = set()
        self.ticks: set[int] = set()

    def on_detections(self, message: Detections2D) -> None:
        with self.lock:
            if self.recording:
                self.detections[message.camera].add(message.seq)

    def on_cylinders(self, message: CameraCylinders) -> None:
        with self.lock:
            if self.recording:
                self.cylinders[message.camera].add(message.seq)

    def on_truth(self, message: SimulatedTruth) -> None:
        with self.lock:
            if self.recording:
                self.frames.add(message.frame)

    def on_tracks(self, message: Tracks) -> None:
        with self.lock:
            if self.recording:
                self.ticks.add(message.time_ns)

    def drops(self) -> dict[str, Any]:
        with self.lock:
            frames = sorted(self.frames)
            source = frames[-1] - frames[0] + 1 - len(frames) if frames else 0
            # Only frames whose detections this process saw; the last second may still be in flight.
            newest = {c: max(s) for c, s in self.detections.items() if s}
            projector = sum(len({q for q in seqs if q <= newest[c] - FPS} - self.cylinders[c])
                            for c, seqs in self.detections.items() if seqs)
            detected = sum(len(s) for s in self.detections.values())
            ticks = sorted(self.ticks)
            expected_ticks = round((ticks[-1] - ticks[0]) / TICK_NS) + 1 if ticks else 0
        return {
            "scene_frames": len(frames),
            "ingest_frames_skipped": source,
            "camera_frames_detected": detected,
            "projector_frames_dropped": projector,
            "tracker_ticks": len(ticks),
            "tracker_ticks_missing": max(0, expected_ticks - len(ticks)),
        }


def gateway_bus_counters(base: str) -> dict[str, Any]:
    try:
        with urllib.request.urlopen(f"{base}/api/health", timeout=5) as response:
            return json.loads(response.read()).get("bus") or {}
    except urllib.error.HTTPError as exc:  # 503 while the site is not ok, with the same body
        return (json.loads(exc.read()).get("bus") or {}) if exc.code == 503 else {}
    except (OSError, ValueError):
        return {}


def growth(samples: list[tuple[float, int]]) -> dict[str, Any]:
    """First, last and peak RSS (MiB), the least-squares slope in MiB per minute over the whole
    run and over its second half (near 0 there: the growth levelled off), and the RSS at the
    start of every minute (``by_minute_mib``), the time series that tells the two apart."""
    if not samples:
        return {"first_mib": math.nan, "last_mib": math.nan, "peak_mib": math.nan, "slope_mib_per_min": math.nan,
                "second_half_slope_mib_per_min": math.nan, "by_minute_mib": []}
    m = [b / MiB for _, b in samples]
    late = [s for s in samples if s[0] >= samples[-1][0] / 2]
    by_minute = [next(b for t, b in samples if t >= 60 * k) / MiB for k in range(int(samples[-1][0] // 60) + 1)]
    return {"first_mib": round(m[0], 1), "last_mib": round(m[-1], 1), "peak_mib": round(max(m), 1),
            "growth_mib": round(m[-1] - m[0], 1), "slope_mib_per_min": _slope(samples),
            "second_half_slope_mib_per_min": _slope(late), "by_minute_mib": [round(x, 1) for x in by_minute]}


def _slope(samples: list[tuple[float, int]]) -> float:
    """Least-squares slope of RSS over time, MiB per minute (NaN for fewer than two times)."""
    t = [s for s, _ in samples]
    m = [b / MiB for _, b in samples]
    mean_t, mean_m = sum(t) / len(t), sum(m) / len(m)
    spread = sum((x - mean_t) ** 2 for x in t)
    return round(sum((x - mean_t) * (y - mean_m) for x, y in zip(t, m, strict=True)) / spread * 60, 2) if spread > 0 else math.nan


def soak(minutes: float, cameras: int, people: int | None = None, sample_every_s: float = 5.0,
         warmup_s: float = 20.0) -> dict[str, Any]:
    """Run the pipeline for ``minutes`` after ``warmup_s`` and return the measurements."""
    people = people if people is not None else round(PEOPLE_PER_CAMERA * cameras)
    site = hall_site(cameras)
    keys = bus.Keys(site.site)
    with tempfile.TemporaryDirectory(prefix="bevflow-soak-") as tmp:
        site_path = Path(tmp) / f"{site.site}.yaml"
        site_path.write_text(dump_site(site))
        group = ServiceGroup(site=str(site_path), log_dir=Path(tmp) / "logs")
        with group:
            base = start_pipeline(group, free_port(), boxes="simulated", ingest_args=("--people", str(people)),
                                  gateway_args=("--no-view3d",))
            session = bus.open_session(bus.BusConfig(mode="peer", listen=("tcp/127.0.0.1:0",),
                                                     connect=(f"tcp/127.0.0.1:{group.hub_port}",)))
            log = StreamLog()
            subscriptions: list[bus.Subscription[Any]] = [
                bus.subscribe(session, keys.detections("*"), bus.JsonCodec(Detections2D), log.on_detections),
                bus.subscribe(session, keys.cylinders("*"), bus.JsonCodec(CameraCylinders), log.on_cylinders),
                bus.subscribe(session, keys.truth, bus.JsonCodec(SimulatedTruth), log.on_truth),
                bus.subscribe(session, keys.tracks, bus.JsonCodec(Tracks), log.on_tracks),
            ]
            time.sleep(warmup_s)
            gateway_before = gateway_bus_counters(base)
            with log.lock:
                log.recording = True
            rss: dict[str, list[tuple[float, int]]] = defaultdict(list)
            start = time.monotonic()
            end = start + minutes * 60
            while True:
                now = time.monotonic()
                for child in group.children:
                    value = rss_bytes(child.process.pid)
                    if value is not None:
                        rss[child.name].append((now - start, value))
                if now >= end:
                    break
                time.sleep(min(sample_every_s, max(0.0, end - now)))
            with log.lock:
                log.recording = False
            gateway_after = gateway_bus_counters(base)
            dead = [child.name for child in group.dead()]
            for subscription in subscriptions:
                subscription.close()
            session.close()
    gateway = {key: _delta(gateway_after.get(key), gateway_before.get(key))
               for key in ("received", "dropped", "rejected")}
    return {
        "minutes": minutes,
        "cameras": cameras,
        "fps": FPS,
        "people": people,
        "samples": max((len(s) for s in rss.values()), default=0),
        "memory": {name: growth(samples) for name, samples in rss.items()},
        "drops": {**log.drops(), "gateway_bus": gateway},
        "services_died": dead,
    }


def _delta(after: Any, before: Any) -> Any:
    if isinstance(after, dict):
        before = before if isinstance(before, dict) else {}
        return {k: v - before.get(k, 0) for k, v in after.items()}
    if isinstance(after, int):
        return after - (before if isinstance(before, int) else 0)
    return None


def print_summary(result: dict[str, Any]) -> None:
    print(f"soak: {result['cameras']} cameras x {result['fps']} fps, {result['people']} people, "
          f"{result['minutes']:g} min, {result['samples']} memory samples")
    print(f"{'service':12s} {'first MiB':>10s} {'last MiB':>10s} {'peak MiB':>10s} {'growth':>8s} {'MiB/min':>8s} "
          f"{'2nd half':>8s}")
    for name, m in result["memory"].items():
        print(f"{name:12s} {m['first_mib']:10.1f} {m['last_mib']:10.1f} {m['peak_mib']:10.1f} "
              f"{m.get('growth_mib', math.nan):8.1f} {m['slope_mib_per_min']:8.2f} {m['second_half_slope_mib_per_min']:8.2f}")
    print("RSS (MiB) at the start of each minute:")
    for name, m in result["memory"].items():
        print(f"{name:12s} " + " ".join(f"{x:6.0f}" for x in m["by_minute_mib"]))
    for key, value in result["drops"].items():
        print(f"{key:28s} {value}")
    print(f"{'services_died':28s} {result['services_died'] or 'none'}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="how long to measure (default 10)")
    parser.add_argument("--cameras", type=int, default=16, help="simulated cameras at 10 fps (default 16)")
    parser.add_argument("--people", type=int, default=None,
                        help=f"people walking (default {PEOPLE_PER_CAMERA:g} per camera)")
    parser.add_argument("--sample-every", type=float, default=5.0, metavar="S", help="seconds between memory samples")
    parser.add_argument("--warmup", type=float, default=20.0, metavar="S", help="seconds before measuring (default 20)")
    parser.add_argument("--json", type=Path, default=Path("soak.json"),
                        help="where to write the results (default soak.json)")
    args = parser.parse_args(argv)
    if args.minutes <= 0 or args.cameras < 1 or args.sample_every <= 0 or args.warmup < 0:
        parser.error("--minutes, --cameras and --sample-every must be positive, --warmup not negative")
    result = soak(args.minutes, args.cameras, args.people, args.sample_every, args.warmup)
    print_summary(result)
    args.json.write_text(json.dumps(result, indent=2))
    print(f"written to {args.json}")
    return 1 if result["services_died"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
