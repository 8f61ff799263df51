"""/api/health's status code follows a camera: 503 soon after its ingest stops, 200 again once
it is back (and reported up by the tracker), with /metrics saying the same; /metrics also serves
what the tracker measures about itself, sent over the bus."""

from __future__ import annotations

import os
import signal
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from bevflow.site import load_site_or_builtin

from bevflow_services.launcher import ServiceGroup, free_port
from bevflow_services.service_metrics import REPORT_EVERY_S

pytestmark = [pytest.mark.e2e, pytest.mark.slow]

SITE = "demo-hall"
STOPPED = "hall-1"
DOWN_WITHIN_S = 10.0  # the gateway's camera timeout is 4 s (CAMERA_SILENCE_S)
# The tracker reports a camera up after --camera-up-after seconds of steady reports.
UP_AFTER_S = 3.0


def status(url: str) -> int:
    try:
        with urllib.request.urlopen(url, timeout=5) as response:
            return response.status
    except urllib.error.HTTPError as exc:
        return exc.code
    except (urllib.error.URLError, OSError):
        return 0


def metric(base: str, line_start: str) -> float | None:
    with urllib.request.urlopen(f"{base}/metrics", timeout=5) as response:
        for line in response.read().decode().splitlines():
            if line.startswith(line_start + " "):
                return float(line.split()[-1])
    return None


def samples(base: str, name: str) -> list[str]:
    """The /metrics lines of series ``name``, whatever their labels."""
    with urllib.request.urlopen(f"{base}/metrics", timeout=5) as response:
        return [line for line in response.read().decode().splitlines() if line.startswith((name + " ", name + "{"))]


def wait_for_metric(base: str, line_start: str, value: float, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while (got := metric(base, line_start)) != value:
        assert time.monotonic() < deadline, f"{line_start} is {got}, not {value}, after {timeout_s:.0f} s"
        time.sleep(0.25)


def wait_for_samples(base: str, name: str, timeout_s: float) -> list[str]:
    deadline = time.monotonic() + timeout_s
    while not (found := samples(base, name)):
        assert time.monotonic() < deadline, f"no {name} on /metrics within {timeout_s:.0f} s"
        time.sleep(0.25)
    return found


def wait_for_status(url: str, code: int, timeout_s: float, group: ServiceGroup) -> float:
    """Seconds until ``url`` answers ``code``; fails naming the logs after ``timeout_s``."""
    start = time.monotonic()
    while (got := status(url)) != code:
        if time.monotonic() - start > timeout_s:
            logs = "\n".join(f"--- {c.name}\n{c.log_tail(8)}" for c in group.children)
            raise AssertionError(f"{url} answered {got}, not {code}, for {timeout_s:.0f} s\n{logs}")
        time.sleep(0.25)
    return time.monotonic() - start


def start_ingest(group: ServiceGroup, cameras: list[str], name: str):
    return group.start("ingest", "--simulate", "--cameras", ",".join(cameras), name=name)


def test_health_is_503_while_a_camera_is_stopped(tmp_path: Path) -> None:
    cameras = load_site_or_builtin(SITE).camera_ids
    group = ServiceGroup(site=SITE, log_dir=tmp_path)
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    try:
        group.start("tracker", "--camera-up-after", str(UP_AFTER_S))
        group.start("projector")
        group.start("gateway", "--port", str(port), "--auth", "off", "--no-view3d")
        group.wait_http(f"{base}/api/health")
        start_ingest(group, [c for c in cameras if c != STOPPED], "ingest-rest")
        one = start_ingest(group, [STOPPED], "ingest-one")
        wait_for_status(f"{base}/api/health", 200, 60.0, group)
        assert metric(base, "bevflow_site_ok") == 1.0
        within = 2 * REPORT_EVERY_S + 5  # the tracker reports every REPORT_EVERY_S
        [ticks] = wait_for_samples(base, "bevflow_tick_duration_seconds_count", within)
        assert float(ticks.split()[-1]) > 0
        late = samples(base, "bevflow_camera_frames_late_total")
        assert all(any(f'camera="{camera}"' in line for line in late) for camera in cameras), late

        os.killpg(one.process.pid, signal.SIGTERM)
        one.process.wait(10)
        group.children.remove(one)
        waited = wait_for_status(f"{base}/api/health", 503, DOWN_WITHIN_S, group)
        assert metric(base, "bevflow_site_ok") == 0.0
        # The site may turn degraded first (the tracker's ticks wait for the silent camera: a gap),
        # a moment before the gateway's own 4 s without the camera's messages runs out.
        wait_for_metric(base, f'bevflow_camera_state{{camera="{STOPPED}",state="down"}}', 1.0, DOWN_WITHIN_S - waited + 2)

        start_ingest(group, [STOPPED], "ingest-one-again")
        wait_for_status(f"{base}/api/health", 200, 30.0, group)
        assert metric(base, "bevflow_site_ok") == 1.0
    finally:
        group.stop()
