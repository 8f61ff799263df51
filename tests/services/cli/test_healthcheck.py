"""``bevflow healthcheck``: each kind of service found up or down, and a service's probe read
from its ``bevflow serve`` command line."""

from __future__ import annotations

import http.server
import socket
import threading

import pytest

from bevflow_services import bus
from bevflow_services.cli import main
from bevflow_services.cli.healthcheck import probe_argv
from bevflow_services.launcher import free_port


@pytest.mark.parametrize(("command", "probe"), [
    (["python", "bevflow", "serve", "router", "--listen", "tcp/0.0.0.0:7447"], ["router", "--port", "7447"]),
    (["bevflow", "serve", "router", "-l", "tls/[::]:7448"], ["router", "--port", "7448"]),
    (["bevflow", "serve", "router"], ["router", "--port", "7447"]),
    (["bevflow", "serve", "gateway", "--site", "s.yaml", "--host", "0.0.0.0", "--port", "9000"],
     ["gateway", "--url", "http://127.0.0.1:9000/api/health"]),
    (["bevflow", "serve", "gateway", "--site", "s.yaml", "--tls-cert", "c.pem", "--host", "10.0.0.2"],
     ["gateway", "--url", "https://10.0.0.2:8000/api/health"]),
    (["bevflow", "serve", "tracker", "--site", "s.yaml", "--mode", "client", "-e", "tcp/router:7447",
      "--id-file", "/data/id", "--host-name-like-flag", "x"],
     ["tracker", "--mode", "client", "--site", "s.yaml", "--connect=tcp/router:7447"]),
])
def test_probe_from_serve_command_line(command, probe) -> None:
    assert probe_argv(command) == probe


def test_probe_reads_what_the_service_took_from_its_environment(monkeypatch) -> None:
    monkeypatch.setenv("BEVFLOW_SITE", "/config/site.yaml")
    monkeypatch.setenv("BEVFLOW_CONNECT", "tcp/router:7447")
    monkeypatch.setenv("BEVFLOW_PORT", "9000")
    assert probe_argv(["bevflow", "serve", "projector", "--mode", "client"]) == \
        ["projector", "--mode", "client", "--site", "/config/site.yaml", "--connect=tcp/router:7447"]
    assert probe_argv(["bevflow", "serve", "gateway"]) == ["gateway", "--url", "http://127.0.0.1:9000/api/health"]


def test_probe_refuses_a_process_that_is_no_service() -> None:
    with pytest.raises(Exception, match="not `bevflow serve SERVICE`"):
        probe_argv(["/bin/sh", "-c", "sleep 1"])


def test_router_port(capsys) -> None:
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        port = listener.getsockname()[1]
        assert main(["healthcheck", "router", "--port", str(port)]) == 0
    assert main(["healthcheck", "router", "--port", str(port), "--timeout", "1"]) == 1
    assert "router: down" in capsys.readouterr().err


class _Health(http.server.BaseHTTPRequestHandler):
    code = 200

    def do_GET(self) -> None:
        self.send_response(self.server.code)  # type: ignore[attr-defined]
        self.end_headers()

    def log_message(self, *_args) -> None:
        pass


@pytest.mark.parametrize(("code", "rc"), [(200, 0), (503, 0), (500, 1), (404, 1)])
def test_gateway_answers(code: int, rc: int) -> None:
    server = http.server.HTTPServer(("127.0.0.1", 0), _Health)
    server.code = code  # type: ignore[attr-defined]
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        url = f"http://127.0.0.1:{server.server_port}/api/health"
        assert main(["healthcheck", "gateway", "--url", url, "--timeout", "5"]) == rc
    finally:
        server.shutdown()
        server.server_close()


def test_bus_service_by_its_liveliness_token() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    argv = ["healthcheck", "tracker", "--site", "demo-hall", "--connect", endpoint, "--timeout"]
    session = bus.open_session(bus.BusConfig(listen=(endpoint,)))
    try:
        assert main([*argv, "0.5"]) == 1
        token = bus.announce(session, bus.Keys("demo-hall"), "tracker")
        assert main([*argv, "10"]) == 0
        assert main(["healthcheck", "projector", *argv[2:], "0.5"]) == 1
        token.undeclare()
    finally:
        session.close()
