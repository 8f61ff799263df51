"""The recorder's command line and main loop (the process itself: test_durability.py)."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from bevflow.capture_time import CaptureWindow

from bevflow_services.launcher import free_port
from bevflow_services.cli.serve import run_service
from bevflow_services.recorder.main import run
from bevflow_services.runtime import UserError
from bevflow_services.storage import RetentionPolicy, RetentionResult, StorageUnavailable
from tests.services.storage.databases import damaged_sqlite_history


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--commit-interval", "2"], "--commit-interval must be between 0.05 and 1 s"),
        (["--track-period", "0"], "--track-period must be positive"),
        (["--fine-days", "30", "--occupancy-days", "7"], "--fine-days .* must not exceed --occupancy-days"),
        (["--track-days", "0"], "--track-days must be positive"),
        (["--db", "mysql://db/history"], "use a SQLite file path"),
    ],
)
def test_bad_arguments_are_one_line_for_the_user(tmp_path: Path, extra: list[str], message: str) -> None:
    argv = ["--site", "example-hall", "--db", str(tmp_path / "h.db"), *extra]
    with pytest.raises(UserError, match=message):
        run_service("recorder", argv)


class Loop:
    """A recorder and database that count calls, fail when told to, and stop the loop after ``calls`` flushes."""

    def __init__(self, calls: int, retention_done: list[bool], flush_failures: int = 0) -> None:
        self.stop = threading.Event()
        self.calls, self.flushes, self.retentions = calls, 0, 0
        self.retention_done = retention_done
        self.flush_failures = flush_failures
        self.db = self
        self.clock, self.window = time.time_ns, CaptureWindow()
        self.latest_ns: list[int | None] = []

    def flush(self) -> int:
        self.flushes += 1
        if self.flushes >= self.calls:
            self.stop.set()
        if self.flush_failures:
            self.flush_failures -= 1
            raise StorageUnavailable("down")
        return 0

    def pending(self) -> int:
        return 0

    def end_lapsed_alerts(self) -> int:
        return 0

    def apply_retention(self, policy: RetentionPolicy, now_ns: int, latest_ns: int | None = None) -> RetentionResult:
        self.retentions += 1
        self.latest_ns.append(latest_ns and latest_ns - now_ns)
        return RetentionResult(done=self.retention_done.pop(0) if self.retention_done else True)


@pytest.mark.parametrize(
    ("retention_done", "flush_failures", "retentions"),
    [
        ([True], 0, 1),  # once at start, then not before retention_every
        ([False, False, True], 0, 3),  # a backlog: one slice per flush until done
        ([True], 3, 1),  # a database down for three flushes: the loop goes on, retention waits
    ],
)
def test_the_loop_flushes_and_works_off_retention_between_flushes(retention_done, flush_failures, retentions) -> None:
    loop = Loop(calls=6, retention_done=retention_done, flush_failures=flush_failures)
    run(loop, RetentionPolicy(), loop.stop, commit_interval=0.05, retention_every=3600)  # type: ignore[arg-type]
    assert loop.flushes == 6
    assert loop.retentions == retentions
    assert loop.latest_ns == [5 * 10**9] * retentions  # rows beyond the clock's future bound are purged


def test_a_damaged_database_stops_the_recorder_with_one_line(tmp_path: Path) -> None:
    """A SQLite file corrupted in the middle made the recorder exit with a 29-line traceback."""
    path = damaged_sqlite_history(tmp_path / "history.db")
    argv = [sys.executable, "-m", "bevflow_services.recorder.main", "--site", "example-hall", "--db", str(path),
            "--listen", f"tcp/127.0.0.1:{free_port()}"]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    (line,) = [x for x in done.stderr.splitlines() if x.startswith("bevflow serve recorder:")]
    assert f"database {path} is damaged" in line and "restore the latest backup" in line
