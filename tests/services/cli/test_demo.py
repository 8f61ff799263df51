"""``bevflow demo``: what it starts, by default and with its options (services stubbed out)."""

from __future__ import annotations

from pathlib import Path

import pytest

from bevflow_services import launcher
from bevflow_services.cli import main
from bevflow_services.launcher import TEMPORARY_DB


class FakeGroup:
    instances: list[FakeGroup] = []

    def __init__(self, site: str, log_dir: Path) -> None:
        self.site, self.log_dir, self.children = site, log_dir, []
        FakeGroup.instances.append(self)

    def dead(self) -> list:
        return []

    def __enter__(self) -> FakeGroup:
        return self

    def __exit__(self, *exc: object) -> None:
        pass


@pytest.fixture
def started(monkeypatch: pytest.MonkeyPatch) -> list[dict]:
    calls: list[dict] = []

    def fake_start(group: FakeGroup, port: int, **options: object) -> str:
        calls.append({"site": group.site, "port": port, **options})
        return f"http://127.0.0.1:{port}"

    monkeypatch.setattr(launcher, "ServiceGroup", FakeGroup)
    monkeypatch.setattr(launcher, "start_pipeline", fake_start)
    return calls


@pytest.mark.parametrize(
    ("argv", "boxes", "history_db", "ingest_args"),
    [
        ([], "rendered", TEMPORARY_DB, ("--camera-fps", "2.0")),
        (["--boxes", "simulated", "--people", "12"], "simulated", TEMPORARY_DB, ("--people", "12")),
        (["--no-history-db", "--camera-fps", "5"], "rendered", None, ("--camera-fps", "5.0")),
        (["--history-db", "/tmp/x.db", "--people", "3"], "rendered", "/tmp/x.db", ("--people", "3", "--camera-fps", "2.0")),
    ],
)
def test_the_demo_runs_the_detector_on_rendered_frames_by_default(started: list[dict], tmp_path: Path, argv: list[str],
                                                                   boxes: str, history_db: str | None, ingest_args: tuple) -> None:
    port = launcher.free_port_pair()
    code = main(["demo", "--port", str(port), "--duration", "0", "--log-dir", str(tmp_path), *argv])
    assert code == 0
    assert started == [{"site": "demo-hall", "port": port, "boxes": boxes, "history_db": history_db, "ingest_args": ingest_args}]


def test_camera_fps_is_refused_without_rendered_frames(started: list[dict], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    code = main(["demo", "--port", str(launcher.free_port_pair()), "--boxes", "simulated", "--camera-fps", "5", "--log-dir", str(tmp_path)])
    assert code == 2
    assert "--camera-fps sets the rate of rendered frames" in capsys.readouterr().err
    assert started == []


def test_contradicting_history_options_are_refused(started: list[dict], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    code = main(["demo", "--port", str(launcher.free_port_pair()), "--history-db", "x.db", "--no-history-db", "--log-dir", str(tmp_path)])
    assert code == 2
    assert "--history-db and --no-history-db" in capsys.readouterr().err
    assert started == []


@pytest.mark.parametrize(("fps", "expected"), [((), "4.0"), (("--fps", "2.5"), "2.5")])
def test_a_recording_of_boxes_is_replayed_without_the_detector(started: list[dict], tmp_path: Path, fps: tuple,
                                                                 expected: str) -> None:
    port = launcher.free_port_pair()
    code = main(["demo", "--port", str(port), "--duration", "0", "--log-dir", str(tmp_path), "--site", "site.yaml",
                 "--detections", str(tmp_path), *fps])
    assert code == 0
    assert started == [{"site": "site.yaml", "port": port, "boxes": "replayed", "history_db": TEMPORARY_DB,
                        "ingest_args": ("--detections", str(tmp_path.resolve()), "--fps", expected, "--loop")}]


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--detections", "DIR", "--people", "3"], "--people and --camera-fps shape the simulated hall"),
        (["--detections", "DIR/nowhere"], "no such folder"),
        (["--detections", "DIR", "--fps", "0"], "--fps must be a number of frames per second > 0"),
        (["--fps", "4"], "--fps is the frame rate of a --detections recording"),
    ],
)
def test_replay_options_are_checked(started: list[dict], tmp_path: Path, capsys: pytest.CaptureFixture, argv, message) -> None:
    argv = [a.replace("DIR", str(tmp_path)) for a in argv]
    assert main(["demo", "--port", str(launcher.free_port_pair()), "--log-dir", str(tmp_path), *argv]) == 2
    assert message in capsys.readouterr().err and started == []
