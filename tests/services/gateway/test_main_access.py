"""``bevflow serve gateway`` as a process with access control on and a TLS certificate: it serves
HTTPS only, logs the one-time setup link, and that link makes the first admin (with a Secure
cookie). Skipped when openssl is not installed (it makes the test certificate)."""

from __future__ import annotations

import http.cookiejar
import json
import re
import shutil
import ssl
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from bevflow_services.launcher import free_port
from tests.services.gateway.feed import SITE_YAML

TIMEOUT_S = 30.0


def _certificate(folder: Path) -> tuple[Path, Path]:
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed, so no test certificate can be made")
    cert, key = folder / "cert.pem", folder / "key.pem"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
                    "-keyout", str(key), "-out", str(cert), "-days", "1", "-subj", "/CN=localhost",
                    "-addext", "subjectAltName=IP:127.0.0.1"], check=True, capture_output=True, timeout=60)
    return cert, key


class Client:
    """HTTPS requests trusting ``cert``, keeping cookies: (status, headers, JSON body)."""

    def __init__(self, cert: Path) -> None:
        context = ssl.create_default_context(cafile=str(cert))
        self.opener = urllib.request.build_opener(urllib.request.HTTPSHandler(context=context),
                                                  urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))

    def request(self, url: str, body: dict | None = None) -> tuple[int, dict[str, str], object]:
        data = None if body is None else json.dumps(body).encode()
        request = urllib.request.Request(url, data=data, headers={"Content-Type": "application/json"})
        try:
            with self.opener.open(request, timeout=5.0) as response:
                return response.status, dict(response.headers), json.loads(response.read() or b"null")
        except urllib.error.HTTPError as error:
            return error.code, dict(error.headers), json.loads(error.read() or b"null")


def test_the_gateway_serves_https_and_logs_a_one_time_setup_link(tmp_path: Path) -> None:
    cert, key = _certificate(tmp_path)
    site = tmp_path / "site.yaml"
    site.write_text(SITE_YAML)
    log = tmp_path / "gateway.log"
    port = free_port()
    argv = [sys.executable, "-m", "bevflow_services.gateway.main", "--site", str(site), "--port", str(port),
            "--no-view3d", "--db", str(tmp_path / "history.db"), "--tls-cert", str(cert), "--tls-key", str(key),
            "--listen", f"tcp/127.0.0.1:{free_port()}"]
    with log.open("w") as out:
        process = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT)
    try:
        base = f"https://127.0.0.1:{port}"
        client = Client(cert)
        deadline = time.monotonic() + TIMEOUT_S
        while True:
            try:
                if client.request(f"{base}/api/health")[0] in (200, 503):  # 503: it runs, with no data yet
                    break
            except (urllib.error.URLError, OSError):
                pass
            assert process.poll() is None and time.monotonic() < deadline, log.read_text()
            time.sleep(0.2)
        with pytest.raises((urllib.error.URLError, OSError)):  # plain HTTP is not served
            urllib.request.urlopen(f"http://127.0.0.1:{port}/api/health", timeout=5.0)
        assert client.request(f"{base}/api/occupancy")[0] == 401
        link = re.search(r"(https://\S+)/login\.html#setup=(\S+)", log.read_text())
        assert link is not None, log.read_text()
        assert link.group(1) == base
        status, headers, _ = client.request(f"{base}/api/auth/setup", {"token": link.group(2), "name": "chief",
                                                                       "password": "a long password"})
        assert status == 201
        assert "Secure" in headers["set-cookie"] and "HttpOnly" in headers["set-cookie"]
        assert headers["strict-transport-security"] == "max-age=31536000"
        status, _, users = client.request(f"{base}/api/users")  # the session cookie works
        assert (status, [u["name"] for u in users]) == (200, ["chief"])
    finally:
        process.terminate()
        process.wait(timeout=15)
