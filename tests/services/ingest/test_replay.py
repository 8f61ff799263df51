"""The ingest's replay of recorded boxes: every camera, every frame, in order, in real time."""

from __future__ import annotations

import itertools
import threading
import time
from pathlib import Path

import pytest

from bevflow.schemas import Detections2D

from bevflow_services import bus
from bevflow_services.ingest import main as ingest
from bevflow_services.ingest import replay
from bevflow_services.launcher import free_port
from bevflow_services.runtime import UserError
from tests.services.ingest.test_main import SITE, args_for

ROWS = {  # frames 1..3; camera b sees nothing in frame 2, and one weak box in frame 3
    "a": "1,-1,100,100,40,90,0.9\n2,-1,110,100,40,90,0.8\n3,-1,120,100,40,90,0.95\n",
    "b": "1,-1,500,300,40,90,0.9\n3,-1,520,300,40,90,0.3\n",
}


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    for camera, rows in ROWS.items():
        (tmp_path / f"{camera}.txt").write_text(rows)
    return tmp_path


def play(folder: Path, *options: str, until: int, timeout_s: float = 10.0) -> tuple[list[Detections2D], bool]:
    """Replay ``folder`` on a loopback bus until ``until`` messages came in (or the deadline);
    returns them and whether the replay had ended by itself."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    publisher = bus.open_session(bus.BusConfig(listen=(endpoint,)))
    listener = bus.open_session(bus.BusConfig(connect=(endpoint,)))
    keys = bus.Keys(f"replay-{time.monotonic_ns()}")
    got: list[Detections2D] = []
    lock = threading.Lock()

    def keep(message: Detections2D) -> None:
        with lock:
            got.append(message)

    sub = bus.subscribe(listener, keys.detections("*"), bus.JsonCodec(Detections2D), keep)
    args = args_for("--detections", str(folder), "--fps", "20", *options)
    loaded = replay.load_recording(args, SITE, ["a", "b"])
    stop = threading.Event()
    worker = threading.Thread(target=replay.replay, args=(publisher, keys, loaded, args, stop))
    try:
        deadline = time.monotonic() + 5  # the subscription reaches the publisher: a probe gets through
        probe = bus.Publication(publisher, keys.detections("probe"), bus.JsonCodec(Detections2D))
        while time.monotonic() < deadline and not got:
            probe.put(Detections2D(camera="probe", seq=0, capture_ns=0))
            time.sleep(0.05)
        probe.close()
        with lock:
            got.clear()
        worker.start()
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and worker.is_alive():
            with lock:
                if len(got) >= until:
                    break
            time.sleep(0.02)
        # The last frames may still be on their way over the bus when the replay's thread returns.
        grace = time.monotonic() + 2.0
        while time.monotonic() < grace:
            with lock:
                if len(got) >= until:
                    break
            time.sleep(0.02)
    finally:
        ended = not worker.is_alive()
        stop.set()
        worker.join(10)
        sub.close()
        listener.close()
        publisher.close()
    assert not worker.is_alive()
    with lock:
        return [m for m in got if m.camera != "probe"], ended


def test_every_camera_reports_every_frame_in_order(recording: Path) -> None:
    # Listen until the replay ends by itself (not until the 6th message: its thread may not have
    # returned yet when that arrives, a race a loaded machine lost once).
    messages, ended = play(recording, until=10**6)
    assert ended  # once through, then done
    by_camera = {c: [m for m in messages if m.camera == c] for c in ("a", "b")}
    assert [m.seq for m in by_camera["a"]] == [m.seq for m in by_camera["b"]] == [0, 1, 2]
    assert [len(m.boxes) for m in by_camera["b"]] == [1, 0, 0]  # nothing in frame 2, frame 3's box too weak
    assert by_camera["a"][0].boxes == [(100.0, 100.0, 140.0, 190.0)] and by_camera["a"][0].confidence == [0.9]
    times = [m.capture_ns for m in by_camera["a"]]
    assert all(later - earlier >= 40_000_000 for earlier, later in itertools.pairwise(times))  # 20 fps: 50 ms apart


def test_a_loop_starts_again_and_keeps_counting(recording: Path) -> None:
    messages, ended = play(recording, "--loop", "--min-confidence", "0.2", until=14)
    a = [m for m in messages if m.camera == "a"]
    b = [m for m in messages if m.camera == "b"]
    assert not ended and len(a) >= 5
    assert [m.seq for m in a] == list(range(len(a)))
    assert a[3].boxes == a[0].boxes and [len(m.boxes) for m in b[:4]] == [1, 0, 1, 1]  # the weak box kept at 0.2


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (("--detections", "DIR"), "--detections needs --fps"),
        (("--detections", "DIR", "--fps", "4", "--simulate"), "--detections publishes recorded boxes"),
        (("--detections", "DIR", "--fps", "4", "--min-confidence", "-1"), "--min-confidence must be"),
        (("--detections", "DIR/nowhere", "--fps", "4"), "no such folder"),
    ],
)
def test_bad_options_are_one_clear_message(recording: Path, options: tuple[str, ...], message: str) -> None:
    argv = [o.replace("DIR", str(recording)) for o in options]
    args = args_for(*argv)
    with pytest.raises(UserError, match=message):
        ingest.main(args) if "--simulate" in argv else replay.load_recording(args, SITE, ["a", "b"])


def test_a_frame_number_typed_wrong_is_refused_before_anything_is_published(recording: Path) -> None:
    with (recording / "b.txt").open("a") as f:
        f.write("9999999,-1,10,10,5,5,0.9\n")
    with pytest.raises(UserError, match=r"frames \d+\.\.9999998 hold no row at all, .* and frame 9999999 \(b\.txt\)"):
        replay.load_recording(args_for("--detections", str(recording), "--fps", "4"), SITE, ["a", "b"])


def test_a_missing_camera_file_names_the_camera(recording: Path) -> None:
    (recording / "b.txt").unlink()
    with pytest.raises(UserError, match="no detections file for camera 'b'"):
        replay.load_recording(args_for("--detections", str(recording), "--fps", "4"), SITE, ["a", "b"])
