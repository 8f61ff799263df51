"""``bevflow serve gateway --host 0.0.0.0`` as a process: the 3D view (viser, which has no login)
listens on loopback only, whatever --host says; browsers reach it through the gateway's /view3d/.
Where viser (the 'view3d' extra) is not installed, the gateway runs without the 3D view."""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from bevflow_services.gateway.main import add_arguments, view3d_port_from_args
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


@pytest.mark.parametrize(
    ("argv", "viser_installed", "port"),
    [
        ([], True, 8001),  # --port + 1
        (["--view3d-port", "9100"], True, 9100),
        (["--no-view3d"], True, None),
        ([], False, None),  # the 'view3d' extra not installed: no 3D view, and the log says why
        (["--no-view3d"], False, None),
        (["--view3d-port", "9100"], False, ModuleNotFoundError),  # asked for: `bevflow` names the extra
    ],
)
def test_the_3d_view_runs_where_viser_is_installed(monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture,
                                                     argv: list[str], viser_installed: bool, port: object) -> None:
    if not viser_installed:
        monkeypatch.setitem(sys.modules, "viser", None)  # what importing it meets where it is not installed
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--port", "8000", *argv])
    if port is ModuleNotFoundError:
        with pytest.raises(ModuleNotFoundError) as raised:
            view3d_port_from_args(args)
        assert raised.value.name == "viser"
        return
    assert view3d_port_from_args(args) == port
    warned = "no 3D view: it needs the 'view3d' extra: pip install 'bevflow[view3d]'" in caplog.text
    assert warned == (not viser_installed and not argv)
