from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from bevflow.detections import Boxes

from bevflow_services.benchmarks import detector as detector_bench
from bevflow_services.benchmarks.detector import bench_detector, lookup, unavailable_reason
from bevflow_services.benchmarks.timing import Timing, time_calls


def test_a_missing_model_is_named_and_nothing_is_timed(tmp_path: Path) -> None:
    missing = tmp_path / "none.onnx"
    reason = unavailable_reason(missing)
    assert reason is not None and "none.onnx" in reason
    result = bench_detector(missing)
    assert result == {"available": False, "reason": reason, "rows": []}


def test_no_shipped_model_says_so(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(detector_bench, "default_model", lambda: tmp_path / "bevflow-person-centernet.onnx")
    if unavailable_reason(None) == "onnxruntime is not installed":
        pytest.skip("onnxruntime is not installed")
    assert unavailable_reason(None) == "no detector model shipped"


class FakeDetector:
    """Stands in for ``Detector``: a fixed input size per height, two boxes per frame."""

    def __init__(self, threads: int) -> None:
        self.threads = threads
        self.calls = 0

    def scale_for(self, height: float, focal: float) -> float:
        return 40.0 * (height - 1.4) / focal

    def prepare(self, image: np.ndarray, scale: float):  # noqa: ANN201
        side = int(round(image.shape[0] * scale / 32)) * 32

        class Prepared:
            tensor = np.zeros((1, 3, side, side), np.float32)

        return Prepared()

    def detect(self, image: np.ndarray, height: float, focal: float) -> Boxes:
        self.calls += 1
        return Boxes(xyxy=np.array([[0.0, 0.0, 5.0, 5.0], [1.0, 1.0, 9.0, 9.0]]))


def test_every_height_and_thread_count_gets_a_row(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(detector_bench, "frame_for", lambda h: (np.zeros((int(100 * h), int(100 * h), 3), np.uint8), 100.0 * h / 3))
    made: list[FakeDetector] = []

    def make(threads: int, _height: float) -> FakeDetector:
        made.append(FakeDetector(threads))
        return made[-1]

    result = bench_detector(heights_m=(3.3, 8.1), threads=(1, 2), repeats=4, warmup=1, make_detector=make)
    assert result["available"] and result["reason"] is None
    assert [(r["height_m"], r["threads"]) for r in result["rows"]] == [(3.3, 1), (3.3, 2), (8.1, 1), (8.1, 2)]
    assert [d.calls for d in made] == [5, 5, 5, 5]  # warm-up + repeats
    assert all(r["boxes"] == 2 and r["ms_p50"] >= 0 for r in result["rows"])
    assert lookup(result, 3.3, 2) == result["rows"][1]["ms_p50"]
    assert lookup(result, 5.5, 2) is None


def test_rendering_is_timed_per_camera_at_the_detectors_scale() -> None:
    from bevflow.sim.render_feed import detector_frame_size
    from bevflow.site import load_site_or_builtin

    result = detector_bench.bench_rendering("demo-hall", people=10, frames=2, warmup=1, cameras=("hall-5",))
    assert [r["camera"] for r in result["rows"]] == ["hall-5"]
    site = load_site_or_builtin("demo-hall")
    for row in result["rows"]:
        assert row["frame"] == "{}x{}".format(*detector_frame_size(site, row["camera"]))
        assert 0 < row["ms_p50"] <= row["ms_p90"]
        assert row["people_shown"] >= 0
    assert result["people"] == 10 and result["frames"] == 2


class FixedTiles:
    fixed_hw = (352, 352)


@pytest.mark.parametrize(
    ("side", "focal", "tiles", "sized"),
    [
        (300, 60.0, True, 2048),  # a rendered frame: the tiles are timed at a real camera's size
        (2048, 618.0, True, 2048),  # already a real camera's frame
        (300, 60.0, False, 300),  # other models take the rendered frame
    ],
)
def test_rim_tiles_are_timed_on_a_frame_of_a_real_cameras_size(side: int, focal: float, tiles: bool, sized: int) -> None:
    from bevflow.detect.tiles import RimTileDetector

    detector = RimTileDetector(FixedTiles()) if tiles else FakeDetector(2)  # type: ignore[arg-type]
    frame, f = detector_bench.camera_sized(detector, np.zeros((side, side, 3), np.uint8), focal)  # type: ignore[arg-type]
    assert frame.shape == (sized, sized, 3) and f == pytest.approx(focal * sized / side)


def test_int8_and_float32_are_timed_in_alternating_rounds(monkeypatch: pytest.MonkeyPatch) -> None:
    from bevflow.detect.runtime import DEFAULT_MODEL, INT8_MODEL

    from bevflow_services.benchmarks.detector import bench_int8

    monkeypatch.setattr(detector_bench, "frame_for", lambda h: (np.zeros((64, 64, 3), np.uint8), 50.0))
    calls: list[str] = []

    class Named(FakeDetector):
        def __init__(self, name: str) -> None:
            super().__init__(threads=2)
            self.name = name

        def detect(self, image: np.ndarray, height: float, focal: float) -> Boxes:
            calls.append(self.name)
            return super().detect(image, height, focal)

    seconds = {"float32": 0.004, "int8": 0.002}  # what the stand-in clock says each call took

    def clocked(call, repeats: int) -> Timing:  # noqa: ANN001
        timings = [time_calls(call, 1) for _ in range(repeats)]
        return Timing([seconds[calls[-1]]] * repeats, [0.0] * repeats, timings[-1].result)

    monkeypatch.setattr(detector_bench, "time_calls", clocked)
    names = {DEFAULT_MODEL: "float32", INT8_MODEL: "int8"}
    result = bench_int8(rounds=2, calls=3, make_detector=lambda path: Named(names[path]))  # type: ignore[arg-type,return-value]
    assert result["available"]
    assert calls == ["float32", "int8"] + ["float32"] * 3 + ["int8"] * 3 + ["float32"] * 3 + ["int8"] * 3  # warm-ups first
    assert result["ms_p50"] == {"float32": 4.0, "int8": 2.0}
    assert result["speedup"] == 2.0


def test_int8_without_the_shipped_copy_says_so(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from bevflow.detect import runtime

    from bevflow_services.benchmarks.detector import bench_int8

    monkeypatch.setattr(runtime, "INT8_MODEL", tmp_path / "bevflow-person-centernet-int8.onnx")
    result = bench_int8()
    assert result == {"available": False, "reason": "no bevflow-person-centernet-int8.onnx shipped beside bevflow-person-centernet.onnx"}


class CountingDetector(FakeDetector):
    """Counts frames and batches; with ``meeting``, each frame waits for the other worker's."""

    def __init__(self, threads: int, meeting: threading.Barrier | None = None) -> None:
        super().__init__(threads)
        self.meeting = meeting
        self.batches: list[int] = []

    def detect(self, image: np.ndarray, height: float, focal: float) -> Boxes:
        if self.meeting is not None:
            self.meeting.wait(timeout=10)  # BrokenBarrierError if the workers ran one after the other
        return super().detect(image, height, focal)

    def detect_batch_scaled(self, images: list[np.ndarray], scales: list[float]) -> list[Boxes]:
        self.batches.append(len(images))
        return [Boxes.empty() for _ in images]


def test_the_workers_one_at_a_time_and_batches_each_get_the_same_frames(monkeypatch: pytest.MonkeyPatch) -> None:
    from bevflow_services.benchmarks.detector import bench_workers

    monkeypatch.setattr(detector_bench, "frame_for", lambda h: (np.zeros((64, 64, 3), np.uint8), 50.0))
    meeting, made = threading.Barrier(2), []

    def make(threads: int) -> CountingDetector:
        made.append(CountingDetector(threads, meeting if threads == 1 else None))
        return made[-1]

    result = bench_workers(cores=2, rounds=3, calls=4, make_detector=make)  # type: ignore[arg-type]
    shared, *single = made
    assert [d.threads for d in made] == [2, 1, 1]  # one session of both cores, one of one thread per worker
    frames = (1 + 3) * 4 * 2  # warm-up and three rounds, 4 calls of 2 frames each
    assert shared.calls == frames and shared.batches == [2] * (frames // 2)
    assert [d.calls for d in single] == [frames // 2] * 2  # each worker's frames, in parallel (the meeting)
    assert result["available"] and set(result["fps"]) == {"one_at_a_time", "workers", "batched"}
    ratio = result["fps"]["workers"] / result["fps"]["one_at_a_time"]
    assert result["speedup"] == pytest.approx(ratio, rel=0.01, abs=1e-3)  # rounded to 3 decimals
