"""Latency of the live system, end to end: camera capture time to websocket delivery.

Starts the real services (ingest simulating N cameras at 10 fps, projector, tracker, gateway)
as separate processes, subscribes to ``/ws/tracks`` and ``/ws/alerts`` like a client would, and
measures for every message its delivery time minus the capture time it carries: ``Tracks.time_ns``
(the newest capture in the tick) and an alert's ``raised_ns`` (the capture time of the tick that
raised it). Frames dropped at the source are counted from gaps in the ground-truth frame numbers.
"""

from __future__ import annotations

import asyncio
import json
import statistics
import tempfile
import threading
import time
from pathlib import Path

import websockets

from bevflow.schemas import SimulatedTruth
from bevflow.site import dump_site, load_site_or_builtin

from bevflow_services import bus
from bevflow_services.launcher import ServiceGroup, free_port, start_pipeline

# A 2 x 2 block of the demo hall's cameras, over the floor they cover.
FOUR_CAMERAS = ("hall-1", "hall-2", "hall-4", "hall-5")


def four_camera_site(folder: Path) -> Path:
    hall = load_site_or_builtin("demo-hall")
    cams = [c for c in hall.cameras if c.id in FOUR_CAMERAS]
    site = hall.model_copy(update={"site": "bench-4", "cameras": cams, "zones": hall.zones[:2], "floor": (0.0, 0.0, 27.0, 17.0)})
    path = folder / "bench-4.yaml"
    path.write_text(dump_site(site))
    return path


def percentile(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q / 100 * (len(ordered) - 1))))]


async def _listen(url: str, latencies: list[float], stamp: str, until: float) -> None:
    async with websockets.connect(url, open_timeout=10, max_size=None) as ws:
        while time.monotonic() < until:
            try:
                raw = await asyncio.wait_for(ws.recv(), timeout=max(0.1, until - time.monotonic()))
            except TimeoutError:
                break
            now = time.time_ns()
            message = json.loads(raw)
            sent = message.get(stamp) if stamp == "time_ns" else (message.get("event") or {}).get(stamp)
            if sent:
                latencies.append((now - sent) / 1e6)


def measure(duration_s: float = 30.0, people: int = 30, warmup_s: float = 5.0) -> dict[str, float]:
    with tempfile.TemporaryDirectory(prefix="bevflow-bench-") as tmp:
        site_path = four_camera_site(Path(tmp))
        group = ServiceGroup(site=str(site_path), log_dir=Path(tmp) / "logs")
        with group:
            base = start_pipeline(group, free_port(), ingest_args=("--people", str(people)), gateway_args=("--no-view3d",))
            frames: list[int] = []
            session = bus.open_session(bus.BusConfig(mode="peer", listen=("tcp/127.0.0.1:0",),
                                                     connect=(f"tcp/127.0.0.1:{group.hub_port}",)))
            lock = threading.Lock()

            def on_truth(truth: SimulatedTruth) -> None:
                with lock:
                    frames.append(truth.frame)

            sub = bus.subscribe(session, bus.Keys("bench-4").truth, bus.JsonCodec(SimulatedTruth), on_truth)
            time.sleep(warmup_s)
            tracks_ms: list[float] = []
            alerts_ms: list[float] = []
            until = time.monotonic() + duration_s
            ws = base.replace("http://", "ws://")

            async def both() -> None:
                await asyncio.gather(_listen(f"{ws}/ws/tracks", tracks_ms, "time_ns", until),
                                     _listen(f"{ws}/ws/alerts", alerts_ms, "raised_ns", until))

            with lock:
                first = len(frames)
            asyncio.run(both())
            with lock:
                seen = frames[first:]
            sub.close()
            session.close()
    expected = (seen[-1] - seen[0] + 1) if seen else 0
    return {
        "cameras": len(FOUR_CAMERAS),
        "fps": 10,
        "people": people,
        "duration_s": duration_s,
        "tracks_messages": len(tracks_ms),
        "tracks_latency_p50_ms": percentile(tracks_ms, 50),
        "tracks_latency_p99_ms": percentile(tracks_ms, 99),
        "alerts": len(alerts_ms),
        "live_latency_p50_ms": percentile(alerts_ms, 50),
        "live_latency_p99_ms": percentile(alerts_ms, 99),
        "frames_dropped_at_source": expected - len(set(seen)),
        "frames_published": len(set(seen)),
        "alert_latency_mean_ms": statistics.fmean(alerts_ms) if alerts_ms else float("nan"),
    }


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--people", type=int, default=30)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    result = measure(args.duration, args.people)
    for key, value in result.items():
        print(f"{key:28s} {value:.1f}" if isinstance(value, float) else f"{key:28s} {value}")
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))
