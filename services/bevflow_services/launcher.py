"""Start bevflow's services as child processes on one machine, watch them, and stop them.

Used by ``bevflow demo``, the end-to-end tests and the live benchmarks, so all three run the
same topology: every service its own process, in Zenoh peer mode on loopback, meeting through
the first one started (the hub), which listens on a known port; the peers then find each other
by gossip and connect directly.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any


_ports_handed_out: set[int] = set()


def free_port() -> int:
    """A loopback port that nothing listens on now and that this process has not handed out before.

    The kernel may give the same free port to two calls in a row, and the first caller's service
    has usually not bound it yet, so the second would collide with it.
    """
    while True:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = int(s.getsockname()[1])
        if port not in _ports_handed_out:
            _ports_handed_out.add(port)
            return port


def free_port_pair() -> int:
    """A port from ``free_port`` whose next one is free too, for the demo (dashboard and 3D view).
    A port free a moment ago says nothing of its neighbour, which a connection may hold."""
    for _ in range(100):
        port = free_port()
        if port < 65535 and port_free(port + 1):
            _ports_handed_out.add(port + 1)
            return port
    raise RuntimeError("no two free ports in a row on 127.0.0.1")


def port_free(port: int) -> bool:
    """Whether a server could listen on 127.0.0.1:``port`` now. Probed as uvicorn and asyncio
    bind, with SO_REUSEADDR: a closed connection waiting out TIME_WAIT there does not stop them,
    a listener or a live connection does."""
    with socket.socket() as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


@dataclass
class Child:
    name: str
    process: subprocess.Popen[bytes]
    log_path: Path

    def log_tail(self, lines: int = 20) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""


@dataclass
class ServiceGroup:
    """Children started with ``start`` in order; ``stop`` ends them in reverse order."""

    site: str
    log_dir: Path
    hub_port: int = field(default_factory=free_port)
    children: list[Child] = field(default_factory=list)
    _sigterm_before: Callable[[int, FrameType | None], Any] | int | None = field(default=None, init=False, repr=False)

    def bus_args(self) -> list[str]:
        hub = f"tcp/127.0.0.1:{self.hub_port}"
        if not self.children:
            return ["--mode", "peer", "--listen", hub]
        return ["--mode", "peer", "--listen", "tcp/127.0.0.1:0", "--connect", hub]

    def start(self, service: str, *extra: str, name: str | None = None) -> Child:
        name = name or service
        argv = [sys.executable, "-m", "bevflow_services.cli", "serve", service, "--site", self.site,
                *self.bus_args(), *extra]
        self.log_dir.mkdir(parents=True, exist_ok=True)
        log_path = self.log_dir / f"{name}.log"
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        with log_path.open("wb") as log:
            process = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT, env=env,
                                       start_new_session=True)
        child = Child(name, process, log_path)
        self.children.append(child)
        return child

    def dead(self) -> list[Child]:
        return [c for c in self.children if c.process.poll() is not None]

    def wait_http(self, url: str, timeout_s: float = 30.0) -> None:
        """Wait until ``url`` answers 200, or 503 (``/api/health`` while the site is not ok: the
        gateway runs, the data has yet to come); raise ``RuntimeError`` naming a child that died."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for child in self.dead():
                raise RuntimeError(f"{child.name} exited with code {child.process.returncode}:\n{child.log_tail()}")
            try:
                with urllib.request.urlopen(url, timeout=1.0) as response:
                    if response.status == 200:
                        return
            except urllib.error.HTTPError as exc:
                if exc.code == 503:
                    return
            except (urllib.error.URLError, OSError):
                pass
            time.sleep(0.2)
        raise RuntimeError(f"{url} did not answer within {timeout_s:.0f} s")

    def stop(self, timeout_s: float = 5.0) -> None:
        for child in reversed(self.children):
            if child.process.poll() is None:
                os.killpg(child.process.pid, signal.SIGTERM)
        deadline = time.monotonic() + timeout_s
        for child in reversed(self.children):
            try:
                child.process.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(child.process.pid, signal.SIGKILL)
                child.process.wait()

    def __enter__(self) -> ServiceGroup:
        # The children run in sessions of their own (a Ctrl-C in the terminal reaches only this
        # process), so a SIGTERM (systemd, docker stop, timeout) must stop them from here: by
        # default it would end this process at once and leave them running.
        if threading.current_thread() is threading.main_thread():
            self._sigterm_before = signal.signal(signal.SIGTERM, _exit_on_signal)
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            self.stop()
        finally:
            if self._sigterm_before is not None:
                signal.signal(signal.SIGTERM, self._sigterm_before)
                self._sigterm_before = None


def _exit_on_signal(signum: int, frame: object) -> None:
    raise SystemExit(128 + signum)


BOXES = ("rendered", "simulated", "recorded", "replayed")
TEMPORARY_DB = "temporary"
# With the detector on a CPU, every camera's frame of one instant waits its turn in one detector,
# so the last camera's cylinders reach the tracker about (cameras x time per frame) after capture:
# 9 x 50-60 ms on a busy 2-core machine. A tick that went without them would drop them as late,
# so the tracker waits up to a second for late cameras (the simulator's boxes need 150 ms).
DETECTOR_MAX_WAIT_MS = 1000


def start_pipeline(group: ServiceGroup, port: int, *, boxes: str = "rendered", history_db: str | Path | None = TEMPORARY_DB,
                   ingest_args: tuple[str, ...] = (), gateway_args: tuple[str, ...] = (),
                   detector_args: tuple[str, ...] = (), tracker_args: tuple[str, ...] | None = None) -> str:
    """The whole live system for a simulated site. Returns the gateway's base URL once it answers.

    ``boxes="rendered"``: the ingest renders every camera's frames and the detector service finds
    the people in them (ingest → detector → projector → tracker → gateway). ``"simulated"``: the
    ingest publishes the simulator's noisy boxes and no detector runs (the system without the
    detector's cost). ``"recorded"``: the ingest reads each camera's ``source`` from the site file
    (frames recorded before, or real cameras) and the detector finds the people. ``"replayed"``:
    the ingest publishes a recording of boxes (``ingest_args`` name it: ``--detections DIR --fps
    F``) and no detector runs. ``history_db``:
    a SQLite file (or database URL) the recorder writes and the gateway reads its history from;
    ``TEMPORARY_DB`` puts one in the group's log folder; None runs no recorder and the gateway
    keeps its history in memory. ``tracker_args`` default: a longer
    wait for late cameras (``DETECTOR_MAX_WAIT_MS``) with the detector, none without."""
    if boxes not in BOXES:
        raise ValueError(f"boxes must be one of {', '.join(BOXES)}, got {boxes!r}")
    if tracker_args is None:
        with_detector = boxes in ("rendered", "recorded")
        tracker_args = ("--max-wait-ms", str(DETECTOR_MAX_WAIT_MS)) if with_detector else ()
    # The id file lets a tracker restarted by hand (or by the chaos test) continue past old ids.
    group.start("tracker", "--id-file", str(group.log_dir / "tracker-next-id"), *tracker_args)
    group.start("projector")
    db_args: tuple[str, ...] = ()
    if history_db is not None:
        db = group.log_dir / "history.db" if history_db == TEMPORARY_DB else history_db
        db_args = ("--db", str(db))
        group.start("recorder", *db_args)
    # Everything listens on loopback only: no login in front of the dashboard unless asked for.
    auth = () if "--auth" in gateway_args else ("--auth", "off")
    group.start("gateway", "--port", str(port), *db_args, *auth, *gateway_args)
    base = f"http://127.0.0.1:{port}"
    group.wait_http(f"{base}/api/health")
    if boxes == "rendered":
        group.start("detector", *detector_args)
        group.start("ingest", "--simulate", "--render", *ingest_args)
    elif boxes == "recorded":
        group.start("detector", *detector_args)
        group.start("ingest", *ingest_args)
    elif boxes == "replayed":
        group.start("ingest", *ingest_args)
    else:
        group.start("ingest", "--simulate", *ingest_args)
    return base
