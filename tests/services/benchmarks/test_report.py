from __future__ import annotations

import pytest

from bevflow_services.benchmarks.report import TARGETS, Target, console_lines, headline_rows, markdown
from bevflow_services.benchmarks.suite import HEADLINE_KEYS


@pytest.mark.parametrize(("value", "verdict"), [(0.04, "met"), (0.05, "met"), (0.051, "missed"), (None, "-"), ("x", "-")])
def test_target_verdict(value: object, verdict: str) -> None:
    assert Target(0.05, "").verdict(value) == verdict


@pytest.mark.parametrize(("value", "verdict"), [(6, "met"), (8, "met"), (5, "missed"), (None, "-")])
def test_an_at_least_target_is_met_from_its_limit_up(value: object, verdict: str) -> None:
    assert Target(6.0, "", at_least=True).verdict(value) == verdict


def test_a_caveat_qualifies_the_verdict() -> None:
    assert Target(150.0, "", "(without the detector)").verdict(45.0) == "met (without the detector)"


def test_targets_are_headline_keys() -> None:
    assert set(TARGETS) <= set(HEADLINE_KEYS)


def fake_result() -> dict:
    result = {key: None for key in HEADLINE_KEYS}
    result |= {"cylinder_batched_ms_per_box": 0.03, "tracking_ms_per_tick_1000_people_64_cameras": 12.5}
    reasons = {k: "the x part was not run" for k, v in result.items() if v is None}
    machine = {"cpus": 2, "cpus_usable": 2, "cpu_model": "Test CPU", "load_average_1_5_15": [1.5, 1.0, 0.5],
               "python": "3.11", "platform": "Linux"}
    cylinder = {"camera": "fisheye-5.5", "rows": [{"boxes": 50, "batched_ms_per_box": 0.03, "batched_cpu_ms_per_box": 0.03,
                "batched_cold_ms": 200.0, "reference_boxes": 50, "reference_ms_per_box": 25.0, "speedup": 800.0,
                "max_disagreement_m": 1e-7, "nan_mismatches": 0}]}
    return result | {"machine": machine, "started": "2024-01-01T00:00:00", "null_reasons": reasons, "failed": ["gateway"],
                     "seconds": {"cylinder": 3.0, "gateway": 1.0}, "parts": {"cylinder": cylinder, "gateway": {"error": "Traceback\nRuntimeError: boom\n"}}}


def test_headline_rows_give_verdicts_and_null_reasons() -> None:
    rows = {key: (value, note) for key, value, _, note in headline_rows(fake_result())}
    assert rows["cylinder_batched_ms_per_box"] == ("0.03", "met")
    assert rows["tracking_ms_per_tick_1000_people_64_cameras"] == ("12.5", "missed")
    assert rows["live_latency_p99_ms"] == ("null", "the x part was not run")


def test_console_and_markdown_show_parts_failures_and_the_machine() -> None:
    text = "\n".join(console_lines(fake_result()))
    assert "Test CPU" in text and "50 boxes" in text and "failed: RuntimeError: boom" in text and "FAILED parts: gateway" in text
    page = markdown(fake_result(), "bevflow bench --json x.json", note="shared with other jobs")
    assert page.startswith("# Benchmarks") and "bevflow bench --json x.json" in page
    assert "load average at the start (1, 5, 15 min): 1.5, 1.0, 0.5" in page and "- shared with other jobs" in page
    assert "| `cylinder_batched_ms_per_box` | 0.03 | <= 0.05 ms per box at 50 boxes | met |" in page


def every_part() -> dict:
    """One made-up result of each part, in the shapes the benchmarks return."""
    stages = {"fusion": 1.0, "tracker": 0.5, "analytics": 0.5, "rest": 0.2}
    run = {"cameras": 4, "people": 30, "duration_s": 30.0, "alerts": 12, "alert_types": {"distance_violation": 12},
           "live_latency_p50_ms": 20.0, "live_latency_p99_ms": 45.0, "tracks_messages": 300, "tracks_latency_p50_ms": 21.0,
           "tracks_latency_p99_ms": 40.0, "frames_published": 300, "frames_dropped_at_source": 0,
           "cpu_cores_by_service": {"tracker": 0.1}}
    return {
        "tracking": {"rows": [{"people": 10, "cameras": 4, "cylinders_per_tick": 15.0, "ms_p50": 3.1, "ms_p95": 3.3, "cpu_ms_p50": 2.2,
                               "stage_cpu_ms_p50": stages, "MOTA": 0.99, "IDF1": 0.98}],
                     "skipped": [{"people": 1000, "cameras": 4, "why": "2.5 people/m²"}]},
        "detector": {"available": True, "reason": None, "rows": [{"height_m": 3.3, "threads": 2, "frame": "369x369", "input": "256x256",
                                                                 "ms_p50": 6.2, "ms_p90": 6.3, "boxes": 13}],
                     "int8": {"available": True, "height_m": 5.5, "threads": 2, "ms_p50": {"float32": 22.6, "int8": 25.5},
                              "speedup": 0.886},
                     "workers": {"available": True, "height_m": 5.5, "cores": 2, "speedup": 1.07,
                                 "fps": {"one_at_a_time": 56.0, "workers": 59.9, "batched": 57.4}}},
        "live": {"latency_4_cameras": run, "detector": "simulator boxes",
                 "max_cameras": {"max_cameras": 8, "lower_bound_only": False, "probes": [
                     {"cameras": 4, "kept_up": True, "why": "kept up", "tracks_latency_p99_ms": 40.0, "frames_dropped_at_source": 0, "people": 30},
                     {"cameras": 16, "kept_up": False, "why": "7 frames dropped at the source", "tracks_latency_p99_ms": 300.0,
                      "frames_dropped_at_source": 7, "people": 120}]},
                 "detector_latency_4_cameras": {**run, "live_latency_p99_ms": 900.0, "frames_detected": 1100,
                                                "frames_skipped_by_detector": 90},
                 "rendered_latency_4_cameras": {**run, "live_latency_p99_ms": 1500.0},
                 "detector_max_cameras": {"max_cameras": 1, "lower_bound_only": False, "probes": [
                     {"cameras": 1, "kept_up": True, "why": "kept up", "tracks_latency_p99_ms": 120.0, "frames_dropped_at_source": 0, "people": 8},
                     {"cameras": 2, "kept_up": False, "why": "30 frames dropped at the source", "tracks_latency_p99_ms": 700.0,
                      "frames_dropped_at_source": 30, "people": 15}]}},
        "gateway": {"rest": {"requests": 800, "rate": 200.0, "duration_s": 4.0, "achieved_rate": 199.0, "errors": 0, "p50_ms": 2.0,
                             "p99_ms": 7.0, "max_ms": 20.0, "gateway_cpu_cores": 0.3},
                    "websocket": {"subscribers": 100, "alert_hz": 5.0, "alert_messages": 40, "deliveries": 4000, "undelivered": 0,
                                  "deliveries_per_subscriber_min": 40, "deliveries_per_subscriber_max": 40, "p50_ms": 9.0,
                                  "p99_ms": 25.0, "max_ms": 30.0, "gateway_cpu_cores": 0.07}},
        "bus": {"frame": {"received": 30, "sent": 30, "p50_ms": 3.0, "p99_ms": 4.0, "put_p50_ms": 2.0}},
    }


def test_every_part_has_a_table() -> None:
    result = fake_result()
    result["parts"] |= every_part()
    text = "\n".join(console_lines(result))
    for expected in ("skipped: 1000 people on 4 cameras: 2.5 people/m²", "3.3 m, 2 threads: frame 369x369 -> input 256x256: 6.2 ms p50",
                     "general model at 5.5 m, 2 threads, alternating: float32 22.6 ms, INT8 25.5 ms p50 (speedup 0.886)",
                     "general model at 5.5 m on 2 cores, alternating, frames a second: one at a time 56, workers 59.9, "
                     "batched 57.4 (workers' speedup 1.07)",
                     "largest number of simulated 10 fps cameras kept up with: 8", "4 cameras, 30 people: kept up",
                     "camera folders recorded before the run, through the detector service:", "p99 900 ms",
                     "frames detected 1100, skipped by the detector 90", "largest number of recorded 10 fps cameras kept up with: 1",
                     "frames rendered during the run (as bevflow demo), through the detector service:", "p99 1500 ms", "2 cameras, 15 people: NO, 30 frames dropped at the source",
                     "16 cameras, 120 people: NO, 7 frames dropped at the source", "0 undelivered", "frame: received 30/30"):
        assert expected in text, expected
    not_run = fake_result()
    not_run["parts"]["detector"] = {"available": False, "reason": "no detector model shipped", "rows": []}
    assert "not measured: no detector model shipped" in "\n".join(console_lines(not_run))
