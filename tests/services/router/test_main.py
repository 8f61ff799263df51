"""The router as a real process: client-mode sessions meet through it; it stops on signals."""

from __future__ import annotations

import queue
import signal
import socket
import subprocess
import sys
import threading

import pytest

from bevflow import schemas
from bevflow_services import bus
from bevflow_services.cli.serve import run_service
from bevflow_services.launcher import free_port
from bevflow_services.runtime import UserError

TIMEOUT = 10.0


def serve_router_command(*args: str) -> list[str]:
    return [sys.executable, "-m", "bevflow_services.cli", "serve", "router", *args]


class Router:
    """A router subprocess whose output lines can be awaited."""

    def __init__(self, *args: str) -> None:
        self.process = subprocess.Popen(serve_router_command(*args), stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT, text=True)
        self.lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.process.stdout:
            self.lines.put(line.rstrip("\n"))

    def next_line(self) -> str:
        return self.lines.get(timeout=TIMEOUT)

    def output(self) -> str:
        """Everything it printed so far (waiting a little for a crashing process to finish)."""
        try:
            self.process.wait(1.0)
        except subprocess.TimeoutExpired:
            pass
        lines = []
        while not self.lines.empty():
            lines.append(self.lines.get())
        return "\n".join(lines)

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait(TIMEOUT)


@pytest.fixture
def router_endpoint():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = Router("--listen", endpoint, "--site-id", "routed")
    try:
        line = router.next_line()
        assert line.startswith("bevflow router ") and line.endswith(f"listening on {endpoint}"), (
            line + "\n" + router.output())
        yield endpoint, router
    finally:
        router.stop()


def test_clients_meet_through_the_router(router_endpoint):
    endpoint, _ = router_endpoint
    keys = bus.Keys("routed")
    client = bus.BusConfig(mode="client", connect=(endpoint,))
    with bus.open_session(client) as publisher_side, bus.open_session(client) as subscriber_side:
        received: queue.Queue = queue.Queue()
        codec = bus.JsonCodec(schemas.Occupancy)
        bus.subscribe(subscriber_side, keys.occupancy, codec, received.put)
        pub = bus.Publication(publisher_side, keys.occupancy, codec)
        assert pub.wait_for_subscribers(TIMEOUT)
        message = schemas.Occupancy(site="routed", time_ns=5, total=7)
        pub.put(message)
        assert received.get(timeout=TIMEOUT) == message
        # The router announced itself in the site it was given.
        live = bus.LiveServices(subscriber_side, keys)
        assert live.wait_until(lambda s: {x.service for x in s} == {"router"}, TIMEOUT)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_router_stops_cleanly_on_signals(router_endpoint, sig):
    _, router = router_endpoint
    router.process.send_signal(sig)
    assert router.process.wait(TIMEOUT) == 0
    assert router.next_line() == "bevflow router stopped"


def test_router_cannot_take_a_port_in_use():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(UserError, match=f"cannot join the bus .*127.0.0.1:{port}.*in use"):
            run_service("router", ["--listen", f"tcp/127.0.0.1:{port}"])


def test_router_has_no_mode_flag():
    with pytest.raises(SystemExit):
        run_service("router", ["--mode", "peer"])
