"""``bevflow serve gateway --host 0.0.0.0`` as a process: the 3D view (viser, which has no login)
listens on loopback only, whatever --host says; browsers reach it through the gateway's /view3d/."""

from __future__ import annotations

import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from bevflow_services.launcher import free_port
from tests.services.gateway.feed import SITE_YAML
from tests.services.gateway.routes.test_view3d import listening_addresses

TIMEOUT_S = 30.0


def test_a_gateway_serving_every_interface_keeps_the_3d_view_on_loopback(tmp_path: Path) -> None:
    if not Path("/proc/net/tcp").exists():
        pytest.skip("no /proc/net/tcp to read listening sockets from")
    site, log, port, view_port = tmp_path / "site.yaml", tmp_path / "gateway.log", free_port(), free_port()
    site.write_text(SITE_YAML)
    argv = [sys.executable, "-m", "bevflow_services.gateway.main", "--site", str(site), "--host", "0.0.0.0",
            "--port", str(port), "--view3d-port", str(view_port), "--db", str(tmp_path / "history.db"),
            "--listen", f"tcp/127.0.0.1:{free_port()}"]
    with log.open("w") as out:
        process = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + TIMEOUT_S
        while "Uvicorn running" not in log.read_text(errors="replace"):
            assert process.poll() is None and time.monotonic() < deadline, log.read_text()
            time.sleep(0.1)
        assert listening_addresses(port) == ["00000000"]      # the gateway: every interface, as asked
        assert listening_addresses(view_port) == ["0100007F"]  # the 3D view: 127.0.0.1 only
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/view3d/", timeout=5)
        assert refused.value.code == 401
    finally:
        process.terminate()
        process.wait(timeout=15)
