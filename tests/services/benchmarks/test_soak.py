from __future__ import annotations

import math
import os

import pytest

from bevflow.schemas import CameraCylinders, Detections2D, SimulatedTruth, Tracks

from bevflow_services.benchmarks.soak import MiB, TICK_NS, StreamLog, _delta, growth, main, rss_bytes


def test_rss_of_this_process_and_of_none() -> None:
    mine = rss_bytes(os.getpid())
    assert mine is not None and 1 * MiB < mine < 64 * 1024 * MiB
    assert rss_bytes(2**22 + 12345) is None  # above the kernel's pid limit


@pytest.mark.parametrize(
    ("samples", "slope", "grew"),
    [
        ([(0.0, 100 * MiB), (60.0, 110 * MiB), (120.0, 120 * MiB)], 10.0, 20.0),
        ([(0.0, 50 * MiB), (30.0, 50 * MiB)], 0.0, 0.0),
        ([(0.0, 80 * MiB), (60.0, 70 * MiB)], -10.0, -10.0),
    ],
)
def test_growth_is_the_least_squares_slope_per_minute(samples, slope: float, grew: float) -> None:
    result = growth(samples)
    assert result["slope_mib_per_min"] == pytest.approx(slope)
    assert result["growth_mib"] == pytest.approx(grew)
    assert result["peak_mib"] == max(b for _, b in samples) / MiB


def test_growth_of_no_samples_is_unknown() -> None:
    assert math.isnan(growth([])["slope_mib_per_min"])


def test_growth_that_levels_off_has_a_flat_second_half_and_a_minute_series() -> None:
    # +40 MiB in the first minute, then flat for three.
    samples = [(t, (100 + min(t, 60.0) * 40 / 60) * MiB) for t in range(0, 241, 20)]
    result = growth([(float(t), int(b)) for t, b in samples])
    assert result["slope_mib_per_min"] > 5
    assert result["second_half_slope_mib_per_min"] == pytest.approx(0.0, abs=1e-6)
    assert result["by_minute_mib"] == [100.0, 140.0, 140.0, 140.0, 140.0]


def test_drops_are_counted_per_stage() -> None:
    log = StreamLog()
    log.on_truth(SimulatedTruth(site="s", frame=0, capture_ns=0))  # not recording yet: ignored
    log.recording = True
    for frame in (1, 2, 5, 6):  # 3 and 4 skipped at the source
        log.on_truth(SimulatedTruth(site="s", frame=frame, capture_ns=frame))
    for seq in range(30):
        log.on_detections(Detections2D(camera="a", seq=seq, capture_ns=seq))
        if seq not in (3, 7, 25):  # 25 is too recent to call lost
            log.on_cylinders(CameraCylinders(camera="a", seq=seq, capture_ns=seq))
    for tick in (0, 1, 2, 4, 5):
        log.on_tracks(Tracks(site="s", time_ns=tick * TICK_NS))
    assert log.drops() == {"scene_frames": 4, "ingest_frames_skipped": 2, "camera_frames_detected": 30,
                           "projector_frames_dropped": 2, "tracker_ticks": 5, "tracker_ticks_missing": 1}


def test_counter_deltas() -> None:
    assert _delta({"a": 5, "b": 2}, {"a": 1}) == {"a": 4, "b": 2}
    assert _delta(10, 4) == 6 and _delta(None, 3) is None


@pytest.mark.parametrize("argv", [["--minutes", "0"], ["--cameras", "0"], ["--warmup", "-1"]])
def test_bad_arguments_exit_with_usage(argv: list[str]) -> None:
    with pytest.raises(SystemExit) as caught:
        main(argv)
    assert caught.value.code == 2
