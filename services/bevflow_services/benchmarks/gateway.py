"""The gateway under load: REST latency at a fixed request rate, and websocket alert fan-out.

The gateway runs as its own process (uvicorn, the application of ``create_app``) on loopback,
fed not by the bus but by a task on its own event loop, the way the bus feed runs: 10 ticks a
second of ``people`` walking tracks with the occupancy, and distance alerts starting (and the
previous one ending) ``alert_hz`` times a second, each stamped with ``raised_ns`` just before
``GatewayState.apply``.

- REST: requests go out on a fixed schedule (``rate`` per second, cycling over the dashboard's
  routes) through at most ``connections`` keep-alive connections. A request's latency runs from
  when it was due, not from when a connection came free, so a stalled server is charged for the
  requests that waited (no coordinated omission).
- Fan-out: ``subscribers`` websocket clients of ``/ws/alerts``; every alert message raised in the
  measuring window counts once per client that receives it, its latency being arrival minus
  ``raised_ns`` (one host, one clock); messages no client received are counted as undelivered.
  All clients share one event loop here, so the spread includes this process reading 100 sockets.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import websockets

from bevflow.schemas import DistanceViolation, Occupancy, Tracks, TrackState, ZoneOccupancy

from bevflow_services.benchmarks.live import cpu_seconds, hall_site
from bevflow_services.benchmarks.timing import percentile
from bevflow_services.launcher import free_port

ROUTES = ("/api/occupancy", "/api/tracks?limit=100", "/api/alerts?limit=20", "/api/cameras", "/api/health")
ANSWERED = {"/api/health": (200, 503)}  # 503: the site is not ok, which the benchmark's made-up site may not be


# --- the server (child process) ------------------------------------------------------------------
async def synthetic_feed(state: object, people: int, alert_hz: float) -> None:
    """Feed ``state`` (a ``GatewayState``) as the bus would, until cancelled."""
    site = state.site  # type: ignore[attr-defined]
    x0, y0, x1, y1 = site.floor
    zones = [ZoneOccupancy(id=z.id, count=0, capacity=z.capacity) for z in site.zones]
    tick, alert_every = 0, max(1, round(10 / alert_hz)) if alert_hz > 0 else 0
    open_alert: DistanceViolation | None = None
    while True:
        now = time.time_ns()
        phase = tick / 50.0
        tracks = [
            TrackState(id=i + 1, xy=((x0 + x1) / 2 + 0.4 * (x1 - x0) * math.cos(phase + i), (y0 + y1) / 2 + 0.4 * (y1 - y0) * math.sin(phase + 2 * i)))
            for i in range(people)
        ]
        state.apply(Tracks(site=site.site, time_ns=now, tracks=tracks))  # type: ignore[attr-defined]
        state.apply(Occupancy(site=site.site, time_ns=now, total=people, zones=zones))  # type: ignore[attr-defined]
        if alert_every and tick % alert_every == 0:
            if open_alert is not None:
                stamp = time.time_ns()
                state.apply(open_alert.model_copy(update={"end_ns": stamp, "raised_ns": stamp}))  # type: ignore[attr-defined]
            stamp = time.time_ns()
            open_alert = DistanceViolation(id=f"bench-{tick}", start_ns=stamp, raised_ns=stamp, tracks=[1, 2],
                                           min_distance_m=1.2, limit_m=2.0)
            state.apply(open_alert)  # type: ignore[attr-defined]
        tick += 1
        await asyncio.sleep(max(0.0, 0.1 - (time.time_ns() - now) / 1e9))


def serve(port: int, people: int, alert_hz: float) -> None:
    """Run the gateway on ``port`` with the synthetic feed (what the child process does)."""
    import uvicorn

    from bevflow_services.gateway.app import create_app
    from bevflow_services.gateway.state import GatewayState

    site = hall_site(4)
    state = GatewayState(site)

    @asynccontextmanager
    async def feed() -> AsyncIterator[None]:
        task = asyncio.create_task(synthetic_feed(state, people, alert_hz))
        try:
            yield
        finally:
            task.cancel()

    uvicorn.run(create_app(site, state, feed=feed), host="127.0.0.1", port=port, log_level="warning")


def start_server(people: int, alert_hz: float, timeout_s: float = 30.0) -> tuple[subprocess.Popen[bytes], int]:
    port = free_port()
    process = subprocess.Popen([sys.executable, "-m", "bevflow_services.benchmarks.gateway", "--serve",
                                "--port", str(port), "--people", str(people), "--alert-hz", str(alert_hz)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"the gateway exited: {process.stderr.read().decode(errors='replace')[-2000:]}")  # type: ignore[union-attr]
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/health", timeout=1.0):
                return process, port
        except urllib.error.HTTPError as exc:
            if exc.code == 503:  # it answers; the site is not ok (yet)
                return process, port
            time.sleep(0.1)
        except (urllib.error.URLError, OSError):
            time.sleep(0.1)
    process.kill()
    raise RuntimeError(f"the gateway did not answer within {timeout_s:.0f} s")


# --- REST load -----------------------------------------------------------------------------------
async def _read_response(reader: asyncio.StreamReader) -> int:
    """Read one HTTP/1.1 response; returns its status."""
    head = await reader.readuntil(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    status = int(lines[0].split()[1])
    headers = {k.strip().lower(): v.strip() for k, _, v in (line.partition(":") for line in lines[1:] if line)}
    if "content-length" in headers:
        await reader.readexactly(int(headers["content-length"]))
    elif headers.get("transfer-encoding", "").lower() == "chunked":
        while True:
            size = int((await reader.readuntil(b"\r\n")).strip(), 16)
            await reader.readexactly(size + 2)
            if size == 0:
                break
    return status


async def rest_load(port: int, rate: float, duration_s: float, connections: int = 16) -> dict:
    """``rate`` GET requests a second for ``duration_s`` over at most ``connections`` connections."""
    loop = asyncio.get_running_loop()
    pool: asyncio.Queue = asyncio.Queue()
    for _ in range(connections):
        pool.put_nowait(await asyncio.open_connection("127.0.0.1", port))
    latencies: list[float] = []
    errors = 0

    async def one(k: int, due: float) -> None:
        nonlocal errors
        reader, writer = await pool.get()
        try:
            path = ROUTES[k % len(ROUTES)]
            writer.write(f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode())
            if await _read_response(reader) not in ANSWERED.get(path, (200,)):
                errors += 1
        except (OSError, asyncio.IncompleteReadError, ValueError):
            errors += 1
            writer.close()
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
        latencies.append((loop.time() - due) * 1e3)
        pool.put_nowait((reader, writer))

    start = loop.time() + 0.05
    tasks = []
    for k in range(int(rate * duration_s)):
        due = start + k / rate
        await asyncio.sleep(max(0.0, due - loop.time()))
        tasks.append(asyncio.create_task(one(k, due)))
    await asyncio.gather(*tasks)
    elapsed = loop.time() - start
    while not pool.empty():
        pool.get_nowait()[1].close()
    return {
        "requests": len(latencies), "errors": errors, "achieved_rate": len(latencies) / elapsed if elapsed > 0 else math.nan,
        "p50_ms": percentile(latencies, 50), "p99_ms": percentile(latencies, 99), "max_ms": max(latencies, default=math.nan),
    }


# --- websocket fan-out ---------------------------------------------------------------------------
async def fanout(port: int, subscribers: int, duration_s: float, grace_s: float = 2.0) -> dict:
    """``subscribers`` clients of ``/ws/alerts``: the delivery latency of every alert raised in a
    window of ``duration_s`` that opens once all of them are connected. Each client reads from the
    moment it connects (so nothing waits unread while the others connect), and reading goes on
    ``grace_s`` after the window, so a late delivery counts as late rather than as missing."""
    url = f"ws://127.0.0.1:{port}/ws/alerts?types=distance_violation"  # the pair events it raises
    received: list[tuple[int, str, int, int]] = []  # (client, alert id, raised_ns, arrival ns)

    async def listen(k: int, ws: websockets.ClientConnection) -> None:
        async for raw in ws:
            now = time.time_ns()
            event = json.loads(raw).get("event") or {}
            if event.get("raised_ns"):
                received.append((k, event["id"], event["raised_ns"], now))

    clients, tasks = [], []
    for k in range(subscribers):
        clients.append(await websockets.connect(url, open_timeout=20, max_size=None))
        tasks.append(asyncio.create_task(listen(k, clients[-1])))
    start_ns = time.time_ns()
    await asyncio.sleep(duration_s)
    end_ns = time.time_ns()
    await asyncio.sleep(grace_s)
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    for ws in clients:
        await ws.close()
    window = [r for r in received if start_ns <= r[2] < end_ns]
    latencies = [(now - raised) / 1e6 for _, _, raised, now in window]
    alerts = {(alert, raised) for _, alert, raised, _ in window}
    per_client = [0] * subscribers
    for k, *_ in window:
        per_client[k] += 1
    return {
        "subscribers": subscribers, "alert_messages": len(alerts), "deliveries": len(window),
        "undelivered": len(alerts) * subscribers - len(window),
        "deliveries_per_subscriber_min": min(per_client, default=0), "deliveries_per_subscriber_max": max(per_client, default=0),
        "p50_ms": percentile(latencies, 50), "p99_ms": percentile(latencies, 99), "max_ms": max(latencies, default=math.nan),
    }


def measure(rest_rate: float = 200.0, rest_duration_s: float = 20.0, subscribers: int = 100, fanout_duration_s: float = 20.0,
            people: int = 50, alert_hz: float = 5.0) -> dict:
    """Start the gateway, load its REST routes, then its alert websocket; stop it."""
    process, port = start_server(people, alert_hz)
    try:
        cpu0, t0 = cpu_seconds(process.pid), time.monotonic()
        rest = asyncio.run(rest_load(port, rest_rate, rest_duration_s))
        cpu1, t1 = cpu_seconds(process.pid), time.monotonic()
        ws = asyncio.run(fanout(port, subscribers, fanout_duration_s))
        cpu2, t2 = cpu_seconds(process.pid), time.monotonic()
    finally:
        process.terminate()
        try:
            process.wait(10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    rest["gateway_cpu_cores"] = round((cpu1 - cpu0) / (t1 - t0), 3)
    ws["gateway_cpu_cores"] = round((cpu2 - cpu1) / (t2 - t1), 3)
    return {"rest": {"rate": rest_rate, "duration_s": rest_duration_s, **rest},
            "websocket": {"alert_hz": alert_hz, "duration_s": fanout_duration_s, **ws}, "people": people}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--port", type=int, default=0, help=argparse.SUPPRESS)
    parser.add_argument("--people", type=int, default=50, help="tracks in every tick (default 50)")
    parser.add_argument("--alert-hz", type=float, default=5.0, help="alerts started per second (default 5)")
    parser.add_argument("--rate", type=float, default=200.0, help="REST requests per second (default 200)")
    parser.add_argument("--subscribers", type=int, default=100, help="websocket clients (default 100)")
    parser.add_argument("--duration", type=float, default=20.0, help="seconds of each phase (default 20)")
    args = parser.parse_args(argv)
    if args.serve:
        serve(args.port, args.people, args.alert_hz)
        return
    print(json.dumps(measure(args.rate, args.duration, args.subscribers, args.duration, args.people, args.alert_hz), indent=2))


if __name__ == "__main__":
    main()
