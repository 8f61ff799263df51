"""``bevflow serve gateway`` as a process: X-Forwarded-For is believed only from the proxies named
with ``--trusted-proxy`` (none by default), so a program on the same host cannot choose the
address that the login limits count and the audit log records."""

from __future__ import annotations

import json
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from bevflow_services.gateway.main import proxy_options
from bevflow_services.launcher import free_port
from bevflow_services.runtime import UserError
from tests.services.gateway.feed import SITE_YAML

FORGED = "203.0.113.9"
TIMEOUT_S = 30.0


def wrong_login(port: int) -> int:
    request = urllib.request.Request(f"http://127.0.0.1:{port}/api/auth/login", headers={
        "Content-Type": "application/json", "X-Forwarded-For": FORGED},
        data=json.dumps({"name": "nobody", "password": "wrong"}).encode())
    try:
        urllib.request.urlopen(request, timeout=5).close()
    except urllib.error.HTTPError as refused:
        return refused.code
    return 200


def wait_for(log: Path, text: str, process: subprocess.Popen[bytes]) -> str:
    deadline = time.monotonic() + TIMEOUT_S
    while text not in (content := log.read_text(errors="replace")):
        assert process.poll() is None and time.monotonic() < deadline, content
        time.sleep(0.1)
    return content


@pytest.mark.parametrize(("options", "logged_address"), [([], "127.0.0.1"), (["--trusted-proxy", "127.0.0.1"], FORGED)])
def test_forwarded_addresses_are_believed_only_from_trusted_proxies(tmp_path: Path, options: list[str],
                                                                    logged_address: str) -> None:
    site, log, port = tmp_path / "site.yaml", tmp_path / "gateway.log", free_port()
    site.write_text(SITE_YAML)
    argv = [sys.executable, "-m", "bevflow_services.gateway.main", "--site", str(site), "--port", str(port),
            "--no-view3d", "--db", str(tmp_path / "history.db"), "--listen", f"tcp/127.0.0.1:{free_port()}", *options]
    with log.open("w") as out:
        process = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT)
    try:
        wait_for(log, "Uvicorn running", process)
        assert wrong_login(port) == 401
        text = wait_for(log, "failed login for 'nobody'", process)
    finally:
        process.terminate()
        process.wait(timeout=15)
    assert f"failed login for 'nobody' from {logged_address}" in text


@pytest.mark.parametrize(("trusted", "expected"), [
    ([], {"proxy_headers": False, "forwarded_allow_ips": ""}),
    (["10.0.0.2", "10.1.0.0/16"], {"proxy_headers": True, "forwarded_allow_ips": "10.0.0.2,10.1.0.0/16"}),
    (["proxy.local"], UserError),
])
def test_proxy_options(trusted: list[str], expected) -> None:
    if expected is UserError:
        with pytest.raises(UserError, match="--trusted-proxy 'proxy.local'"):
            proxy_options(trusted)
    else:
        assert proxy_options(trusted) == expected
