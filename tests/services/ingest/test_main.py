"""The ingest's command line and simulation modes: rendered frames in step across cameras, with ground truth."""

from __future__ import annotations

import argparse
import threading
import time

import pytest

from bevflow.schemas import SimulatedTruth
from bevflow.sim.render_feed import detector_frame_size
from bevflow.site import parse_site

from bevflow_services import bus
from bevflow_services.cli.serve import service_parser
from bevflow_services.ingest import main as ingest
from bevflow_services.ingest.sources import Timeouts
from bevflow_services.launcher import free_port
from bevflow_services.runtime import UserError

SITE = parse_site("""
site: ingest-test
floor: [-4, -4, 10, 4]
cameras:
  - {id: a, image_size: [800, 800], intrinsics: {fx: 250, fy: 250, cx: 399.5, cy: 399.5}, pose: {position: [0, 0, 3.5]}}
  - {id: b, image_size: [800, 800], intrinsics: {fx: 250, fy: 250, cx: 399.5, cy: 399.5}, pose: {position: [6, 0, 3.5]}}
""")


def args_for(*argv: str) -> argparse.Namespace:
    return service_parser("ingest", ingest).parse_args(["--site", "demo-hall", *argv])


def test_render_needs_the_simulation() -> None:
    with pytest.raises(UserError, match="--render.*--simulate"):
        ingest.main(args_for("--render"))


@pytest.mark.parametrize(
    ("camera_fps", "expected"),
    [(None, 1), (10.0, 1), (5.0, 2), (2.0, 5), (3.0, 3), (0.0, UserError), (12.0, UserError)],
)
def test_camera_fps_publishes_every_nth_scene_frame(camera_fps, expected) -> None:
    if expected is UserError:
        with pytest.raises(UserError, match="--camera-fps must be above 0 and at most the scene's 10 fps"):
            ingest.camera_frame_stride(10.0, camera_fps)
    else:
        assert ingest.camera_frame_stride(10.0, camera_fps) == expected


def test_camera_fps_needs_rendered_frames() -> None:
    with pytest.raises(UserError, match="--camera-fps.*--simulate --render"):
        ingest.main(args_for("--simulate", "--camera-fps", "2"))


@pytest.mark.parametrize(
    ("argv", "expected"),
    [((), Timeouts()), (("--open-timeout", "4", "--read-timeout", "1.5"), Timeouts(open_s=4, read_s=1.5)),
     (("--read-timeout", "0"), UserError), (("--open-timeout", "-1"), UserError)],
)
def test_stream_timeouts_come_from_the_command_line(argv, expected) -> None:
    if expected is UserError:
        with pytest.raises(UserError, match="--open-timeout and --read-timeout must be above 0"):
            ingest.stream_timeouts(args_for(*argv))
    else:
        assert ingest.stream_timeouts(args_for(*argv)) == expected
    assert Timeouts().read_s < 5  # a stall shows before camera health's 5 s of silence would call the camera down


def test_rendered_frames_come_in_step_with_the_ground_truth() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    publisher = bus.open_session(bus.BusConfig(listen=(endpoint,)))
    listener = bus.open_session(bus.BusConfig(connect=(endpoint,)))
    keys = bus.Keys(f"ingest-{time.monotonic_ns()}")
    frames: list[bus.Frame] = []
    truths: list[SimulatedTruth] = []
    lock = threading.Lock()

    def keep(into: list):  # noqa: ANN202
        def on(message) -> None:  # noqa: ANN001
            with lock:
                into.append(message)
        return on

    subs = [bus.subscribe(listener, keys.frame("*"), bus.FRAMES, keep(frames)),
            bus.subscribe(listener, keys.truth, bus.JsonCodec(SimulatedTruth), keep(truths))]
    stop = threading.Event()
    worker = threading.Thread(target=ingest.simulate_frames,
                              args=(publisher, keys, SITE, ["a", "b"], args_for("--simulate", "--render", "--people", "4", "--camera-fps", "5"), stop))
    try:
        time.sleep(0.3)  # let the subscriptions reach the publisher
        worker.start()
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            with lock:
                if len(truths) >= 6:
                    break
            time.sleep(0.05)
    finally:
        stop.set()
        worker.join(10)
        for sub in subs:
            sub.close()
        listener.close()
        publisher.close()
    assert not worker.is_alive()
    with lock:
        assert len(truths) >= 6
        by_capture: dict[int, dict[str, bus.Frame]] = {}
        for frame in frames:
            by_capture.setdefault(frame.header.capture_ns, {})[frame.header.camera] = frame
    for camera in ("a", "b"):
        w, h = detector_frame_size(SITE, camera)
        shots = [f for f in frames if f.header.camera == camera]
        assert shots and all(f.image.shape == (h, w, 3) and (f.header.width, f.header.height) == (w, h) for f in shots)
        seqs = [f.header.seq for f in shots]
        assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    # Both cameras show the same instant: same capture time, same sequence number, and that
    # instant's ground truth was published with it.
    # An instant's truth goes out after its frames, so the newest frames may have come in
    # without theirs when the test stopped listening; every earlier instant must have it.
    truth_at = {t.capture_ns: t for t in truths}
    last_truth = max(truth_at)
    both = [shots for capture, shots in by_capture.items() if len(shots) == 2 and capture <= last_truth]
    assert len(both) >= 3
    for shots in both:
        assert shots["a"].header.seq == shots["b"].header.seq
        assert truth_at[shots["a"].header.capture_ns].frame == shots["a"].header.seq
    # People are on the floor and the frames show them walking (the static scene alone would
    # render the same picture every time).
    assert max(len(t.tracks) for t in truths) > 0
    shots = sorted((f for f in frames if f.header.camera == "a"), key=lambda f: f.header.seq)
    assert (shots[0].image != shots[-1].image).any(axis=2).sum() > 20
