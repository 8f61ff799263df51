"""``bevflow demo --detections``: a recording of boxes through every live service, as processes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from bevflow_services.launcher import free_port_pair
from tests.bevflow.evaluation.test_replay import write_recording
from tests.bevflow.evaluation.test_wildtrack_tracking import STARTS, walkers

pytestmark = pytest.mark.e2e


def tracks_now(base: str) -> list[dict]:
    try:
        with urllib.request.urlopen(f"{base}/api/tracks", timeout=2) as response:
            return json.loads(response.read())["items"]
    except (urllib.error.URLError, OSError, ValueError):
        return []


def test_the_demo_shows_a_recording_of_boxes(tmp_path: Path) -> None:
    # three people walking 0.3 m per frame past two cameras, 8 frames at 4 a second, looped
    site, detections, _ = write_recording(walkers(0.3, hidden=None, ghost=None), tmp_path)
    port = free_port_pair()  # the 3D view takes the next port
    logs = tmp_path / "logs"
    demo = subprocess.Popen(
        [sys.executable, "-m", "bevflow_services.cli", "demo", "--site", str(site), "--detections", str(detections),
         "--fps", "4", "--port", str(port), "--no-history-db", "--duration", "150", "--log-dir", str(logs)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    seen: list[dict] = []
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and demo.poll() is None:
            items = tracks_now(f"http://127.0.0.1:{port}")
            if len(items) == 3 and all(sorted(t["cameras"]) == ["CVLab1", "CVLab2"] for t in items):
                seen = items
                break
            time.sleep(0.2)
    finally:
        if demo.poll() is None:
            demo.send_signal(signal.SIGTERM)  # the demo stops its services, then itself
        output = demo.communicate(timeout=30)[0].decode(errors="replace")
    service_logs = "\n".join(f"--- {p.name}\n{p.read_text(errors='replace')[-2000:]}" for p in sorted(logs.glob("*.log")))
    assert seen, f"no three fused tracks on the dashboard's API:\n{output}\n{service_logs}"
    # each track is one of the walkers, on their line across the floor
    assert sorted(round(t["xy"][1]) for t in seen) == sorted(round(y) for _, y in STARTS.values())
    assert "the boxes recorded in" in output
