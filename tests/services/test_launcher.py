"""Which services ``start_pipeline`` starts, in which order and with which flags (no processes),
that a group stops its children when it is sent SIGTERM (real processes), and which ports it
takes for free."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from bevflow_services import launcher
from bevflow_services.launcher import start_pipeline


class FakeGroup:
    def __init__(self, log_dir: Path) -> None:
        self.log_dir = log_dir
        self.started: list[tuple[str, tuple[str, ...]]] = []
        self.waited: list[str] = []

    def start(self, service: str, *extra: str, name: str | None = None) -> None:
        self.started.append((service, extra))

    def wait_http(self, url: str, timeout_s: float = 30.0) -> None:
        self.waited.append(url)


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        ({}, [("tracker", ("--id-file", "{log}/tracker-next-id", "--max-wait-ms", "1000")), ("projector", ()), ("recorder", ("--db", "{log}/history.db")),
              ("gateway", ("--port", "8123", "--db", "{log}/history.db", "--auth", "off")), ("detector", ()), ("ingest", ("--simulate", "--render"))]),
        ({"boxes": "simulated", "history_db": None},
         [("tracker", ("--id-file", "{log}/tracker-next-id")), ("projector", ()), ("gateway", ("--port", "8123", "--auth", "off")),
          ("ingest", ("--simulate",))]),
        ({"history_db": "/data/h.db", "detector_args": ("--threads", "1"), "ingest_args": ("--people", "5"),
          "gateway_args": ("--no-view3d", "--auth", "on"), "tracker_args": ("--tick-ms", "200")},
         [("tracker", ("--id-file", "{log}/tracker-next-id", "--tick-ms", "200")), ("projector", ()), ("recorder", ("--db", "/data/h.db")),
          ("gateway", ("--port", "8123", "--db", "/data/h.db", "--no-view3d", "--auth", "on")), ("detector", ("--threads", "1")),
          ("ingest", ("--simulate", "--render", "--people", "5"))]),
    ],
)
def test_the_pipeline_starts_what_was_asked_for(tmp_path: Path, options: dict, expected: list) -> None:
    group = FakeGroup(tmp_path)
    base = start_pipeline(group, 8123, **options)  # type: ignore[arg-type]
    assert base == "http://127.0.0.1:8123"
    assert group.waited == ["http://127.0.0.1:8123/api/health"]
    fill = [(s, tuple(a.replace("{log}", str(tmp_path)) for a in args)) for s, args in expected]
    assert group.started == fill
    # The ingest comes last, once everything that consumes its frames is up.
    assert group.started[-1][0] == "ingest"


def test_an_unknown_box_source_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="boxes must be one of rendered, simulated"):
        start_pipeline(FakeGroup(tmp_path), 8000, boxes="real")



GROUP_UNDER_SIGTERM = """
import subprocess, sys, time
from pathlib import Path
from bevflow_services.launcher import Child, ServiceGroup
log_dir = Path(sys.argv[1])
with ServiceGroup(site="unused", log_dir=log_dir) as group:
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"], start_new_session=True)
    group.children.append(Child("sleeper", child, log_dir / "sleeper.log"))
    print(child.pid, flush=True)
    time.sleep(120)
"""


def test_a_sigterm_stops_the_group_and_its_children(tmp_path: Path) -> None:
    parent = subprocess.Popen([sys.executable, "-c", GROUP_UNDER_SIGTERM, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        child_pid = int(parent.stdout.readline())  # type: ignore[union-attr]
        parent.send_signal(signal.SIGTERM)
        assert parent.wait(timeout=30) == 128 + signal.SIGTERM
    finally:
        parent.kill()
    with pytest.raises(ProcessLookupError):  # stopped and reaped, not left running in its own session
        os.kill(child_pid, 0)


@pytest.mark.parametrize(("held_by", "free"), [(None, True), ("listener", False), ("bound socket", False)])
def test_a_port_is_free_unless_a_listener_or_a_socket_holds_it(held_by: str | None, free: bool) -> None:
    port = launcher.free_port()
    with socket.socket() as holder:
        if held_by is not None:
            holder.bind(("127.0.0.1", port))
            if held_by == "listener":
                holder.listen()
        assert launcher.port_free(port) is free


def test_a_port_pair_is_two_free_ports_neither_handed_out_again() -> None:
    port = launcher.free_port_pair()
    assert launcher.port_free(port) and launcher.port_free(port + 1)
    assert all(launcher.free_port() not in (port, port + 1) for _ in range(200))
