"""No credential in any log line: an ingest whose camera URL carries a password, and a gateway
asked over HTTP and a websocket with an API token in the URL, each run as a real process."""

from __future__ import annotations

import asyncio
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
import websockets
import yaml

from bevflow_services.launcher import free_port
from bevflow_services.storage import AccessStore
from tests.services.gateway.feed import SITE_YAML

pytestmark = pytest.mark.e2e

BUILTIN_SITE = Path(__file__).resolve().parents[2] / "shared" / "bevflow" / "data" / "sites" / "demo-hall.yaml"
PASSWORD = "camera-secret-4711"
TOKEN = "bvf_" + "T0kenThatMustNotBeLogged" * 2
TIMEOUT_S = 30.0


def serve(argv: list[str], log: Path) -> subprocess.Popen[bytes]:
    with log.open("wb") as out:
        return subprocess.Popen([sys.executable, "-m", "bevflow_services.cli", "serve", *argv],
                                stdout=out, stderr=subprocess.STDOUT)


def wait_for_text(log: Path, text: str, process: subprocess.Popen[bytes]) -> str:
    deadline = time.monotonic() + TIMEOUT_S
    while text not in (content := log.read_text(errors="replace")):
        assert process.poll() is None and time.monotonic() < deadline, content
        time.sleep(0.2)
    return content


def stop(process: subprocess.Popen[bytes]) -> None:
    process.terminate()
    try:
        process.wait(10)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


def test_ingest_logs_camera_urls_without_their_password(tmp_path: Path) -> None:
    site = yaml.safe_load(BUILTIN_SITE.read_text())
    closed = free_port()  # nothing listens: the stream cannot open, and the ingest says so
    site["cameras"][0]["source"] = f"rtsp://admin:{PASSWORD}@127.0.0.1:{closed}/stream1"
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(site))
    log = tmp_path / "ingest.log"
    process = serve(["ingest", "--site", str(path), "--cameras", site["cameras"][0]["id"],
                     "--listen", f"tcp/127.0.0.1:{free_port()}"], log)
    try:
        text = wait_for_text(log, "retrying in", process)
    finally:
        stop(process)
    text = log.read_text(errors="replace")
    assert f"rtsp://admin:***@127.0.0.1:{closed}/stream1" in text
    assert PASSWORD not in text


async def _ws_with_token(port: int) -> None:
    try:
        async with websockets.connect(f"ws://127.0.0.1:{port}/ws/alerts?types=camera_down&token={TOKEN}",
                                      open_timeout=10):
            pass
    except (websockets.InvalidStatus, websockets.ConnectionClosed, OSError):
        pass  # refused or closed: what matters is what the gateway logged


def test_gateway_logs_no_token_from_urls(tmp_path: Path) -> None:
    site, db = tmp_path / "site.yaml", tmp_path / "history.db"
    site.write_text(SITE_YAML)
    with AccessStore.open(str(db)) as store:  # a real viewer token, so the websocket is accepted
        store.add_user("wall", "viewer", "not-a-real-hash", 0)  # the token alone logs in
        store.add_token(TOKEN, "wall", "tests", 0)
    port, log = free_port(), tmp_path / "gateway.log"
    process = serve(["gateway", "--site", str(site), "--port", str(port), "--no-view3d", "--db", str(db),
                     "--listen", f"tcp/127.0.0.1:{free_port()}"], log)
    try:
        wait_for_text(log, "Uvicorn running", process)
        for path in ("/api/occupancy", "/api/health"):
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}{path}?token={TOKEN}", timeout=5).close()
            except urllib.error.HTTPError:
                pass
        asyncio.run(_ws_with_token(port))
        text = wait_for_text(log, "WebSocket /ws/alerts", process)
    finally:
        stop(process)
    text = log.read_text(errors="replace")
    assert "token=***" in text
    assert TOKEN not in text and TOKEN[4:] not in text
