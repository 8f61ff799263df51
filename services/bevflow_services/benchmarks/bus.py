"""Latency of the bus between two processes on one host: a 1280x1280 BGR frame and a small JSON
message (a ``Tracks`` of 20 people), publisher in this process, subscriber in a child process.

Latency is one way, from just before ``put`` to the subscriber holding the decoded message (a
numpy array over the pixels, or a validated pydantic model), read on the shared system clock.

    python -m bevflow_services.benchmarks.bus                      # peer to peer, shared memory on
    python -m bevflow_services.benchmarks.bus --no-shared-memory
    python -m bevflow_services.benchmarks.bus --via-router         # both processes as clients of a router
    python -m bevflow_services.benchmarks.bus --consumer async     # through AsyncSubscription to an event loop
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import subprocess
import sys
import time
from typing import Any

import numpy as np

from bevflow import schemas

from bevflow_services import bus
from bevflow_services.launcher import free_port

SIZE = 1280
KEYS = bus.Keys("bench")
ROUTER = "import sys; from bevflow_services.cli.serve import run_service; sys.exit(run_service('router', sys.argv[1:]))"


def small_message(seq: int) -> schemas.Tracks:
    people = [schemas.TrackState(id=i, xy=(i * 0.5, 3.0), velocity=(0.1, 0.0), cameras=["cam1"]) for i in range(20)]
    return schemas.Tracks(site="bench", time_ns=time.time_ns(), tracks=people, violations=[(seq % 20, (seq + 1) % 20)])


def sent_ns(message: bus.Frame | schemas.Tracks) -> int:
    return message.header.capture_ns if isinstance(message, bus.Frame) else message.time_ns


# --- the subscriber (child process) --------------------------------------------------------------
def subscriber(args: argparse.Namespace) -> None:
    cfg = bus.BusConfig(mode=args.mode, connect=(args.endpoint,), shared_memory=args.shared_memory)
    session = bus.open_session(cfg)
    codec: bus.Codec[Any] = bus.FRAMES if args.kind == "frame" else bus.JsonCodec(schemas.Tracks)  # per --kind
    key = KEYS.frame("*") if args.kind == "frame" else KEYS.tracks
    latencies: list[int] = []

    def record(message) -> None:
        latencies.append(time.time_ns() - sent_ns(message))

    if args.consumer == "async":
        async def consume() -> None:
            sub = bus.AsyncSubscription(session, key, codec, maxsize=1024)
            token = bus.announce(session, KEYS, "bench-sub", "child")
            deadline = time.monotonic() + args.timeout
            while len(latencies) < args.count and time.monotonic() < deadline:
                try:
                    record(await asyncio.wait_for(sub.get(), max(0.01, deadline - time.monotonic())))
                except TimeoutError:
                    break
            token.undeclare()

        asyncio.run(consume())
    else:
        bus.subscribe(session, key, codec, record)
        token = bus.announce(session, KEYS, "bench-sub", "child")
        deadline = time.monotonic() + args.timeout
        while len(latencies) < args.count and time.monotonic() < deadline:
            time.sleep(0.01)
        token.undeclare()
    print(json.dumps(latencies), flush=True)
    session.close()


# --- the publisher (this process) ----------------------------------------------------------------
def publish(args: argparse.Namespace, kind: str, endpoint: str, mode: str, session) -> dict[str, float]:
    child = subprocess.Popen(
        [sys.executable, "-m", "bevflow_services.benchmarks.bus", "--role", "sub", "--kind", kind, "--endpoint", endpoint, "--mode", mode,
         "--count", str(args.count + args.warmup), "--consumer", args.consumer, "--timeout", str(args.timeout),
         "--shared-memory" if args.shared_memory else "--no-shared-memory"],
        stdout=subprocess.PIPE, text=True)
    live = bus.LiveServices(session, KEYS)
    if not live.wait_until(bus.all_alive(["bench-sub"]), 20):
        child.kill()
        raise SystemExit("the subscriber process did not come up")
    codec: bus.Codec[Any] = bus.FRAMES if kind == "frame" else bus.JsonCodec(schemas.Tracks)  # per --kind
    pub = bus.Publication(session, KEYS.frame("cam1") if kind == "frame" else KEYS.tracks, codec)
    if not pub.wait_for_subscribers(10):
        raise SystemExit("the subscriber never matched")
    rate = args.frame_rate if kind == "frame" else args.json_rate
    image = np.random.default_rng(0).integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8)
    put_s = []
    for seq in range(args.count + args.warmup):
        if kind == "frame":
            header = schemas.FrameHeader(camera="cam1", seq=seq, capture_ns=time.time_ns(), width=SIZE, height=SIZE)
            message: bus.Frame | schemas.Tracks = bus.Frame(header, image)
        else:
            message = small_message(seq)
        t0 = time.perf_counter()
        pub.put(message)
        put_s.append(time.perf_counter() - t0)
        time.sleep(max(0.0, 1.0 / rate - (time.perf_counter() - t0)))
    out, _ = child.communicate(timeout=args.timeout + 20)
    latencies = np.asarray(json.loads(out.strip().splitlines()[-1]), dtype=np.float64)[args.warmup:] / 1e6
    live.close()
    pub.close()
    got = len(latencies) > 0
    return {
        "sent": args.count, "received": len(latencies),
        "p50_ms": float(np.percentile(latencies, 50)) if got else math.nan,
        "p99_ms": float(np.percentile(latencies, 99)) if got else math.nan,
        "max_ms": float(latencies.max()) if got else math.nan, "put_p50_ms": float(np.median(put_s) * 1e3),
    }


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--role", choices=("pub", "sub"), default="pub", help=argparse.SUPPRESS)
    parser.add_argument("--kind", choices=("frame", "json"), default=None, help=argparse.SUPPRESS)
    parser.add_argument("--endpoint", help=argparse.SUPPRESS)
    parser.add_argument("--mode", default="peer", help=argparse.SUPPRESS)
    parser.add_argument("--count", type=int, default=300, help="messages measured per kind (default 300)")
    parser.add_argument("--warmup", type=int, default=10, help="messages sent first and not measured")
    parser.add_argument("--frame-rate", type=float, default=30.0, help="frames per second sent (default 30)")
    parser.add_argument("--json-rate", type=float, default=200.0, help="JSON messages per second sent (default 200)")
    parser.add_argument("--consumer", choices=("callback", "async"), default="callback")
    parser.add_argument("--via-router", action="store_true", help="route through a router process")
    parser.add_argument("--shared-memory", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument("--timeout", type=float, default=60.0, help=argparse.SUPPRESS)
    return parser


def measure(argv: list[str] | None = None, echo: bool = False) -> dict[str, dict[str, float]]:
    """Both kinds of message, with the command line's options (``argv``, [] for the defaults):
    {"frame": {...}, "json": {...}}, each with sent, received, p50_ms, p99_ms, max_ms, put_p50_ms."""
    args = build_parser().parse_args(argv or [])
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = None
    if args.via_router:
        router = subprocess.Popen([sys.executable, "-c", ROUTER, "--listen", endpoint],
                                  stdout=subprocess.PIPE, text=True)
        assert router.stdout is not None  # a pipe was asked for
        router.stdout.readline()
        mode, cfg = "client", bus.BusConfig(mode="client", connect=(endpoint,), shared_memory=args.shared_memory)
    else:
        mode, cfg = "peer", bus.BusConfig(listen=(endpoint,), shared_memory=args.shared_memory)
    session = bus.open_session(cfg)
    results: dict[str, dict[str, float]] = {}
    try:
        if echo:
            print(f"bus latency, one way, {'via a router' if router else 'peer to peer'}, shared memory "
                  f"{'on' if args.shared_memory else 'off'}, consumer {args.consumer}, {args.count} messages each")
        labels = {
            "frame": f"frame {SIZE}x{SIZE}x3 ({SIZE * SIZE * 3 / 1e6:.1f} MB) at {args.frame_rate:g}/s",
            "json": f"Tracks JSON, 20 people ({len(small_message(0).model_dump_json())} B) at {args.json_rate:g}/s",
        }
        for kind, label in labels.items():
            r = results[kind] = publish(args, kind, endpoint, mode, session)
            if echo:
                print(f"  {label}: received {r['received']}/{r['sent']}, p50 {r['p50_ms']:.2f} ms, "
                      f"p99 {r['p99_ms']:.2f} ms, max {r['max_ms']:.2f} ms, put() p50 {r['put_p50_ms']:.2f} ms")
    finally:
        session.close()
        if router is not None:
            router.terminate()
            router.wait(10)
    return results


def main(argv: list[str] | None = None) -> None:
    args = build_parser().parse_args(argv)
    if args.role == "sub":
        subscriber(args)
        return
    measure(argv if argv is not None else sys.argv[1:], echo=True)


if __name__ == "__main__":
    main()
