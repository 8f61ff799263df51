from __future__ import annotations

import json
import math

import pytest

from bevflow_services.benchmarks import suite
from bevflow_services.benchmarks.report import console_lines
from bevflow_services.benchmarks.suite import HEADLINE_KEYS, PARTS, Settings, json_ready, run_suite

TINY = Settings(cylinder_boxes=(5, 50), cylinder_repeats=1, cylinder_reference_repeats=1, cylinder_reference_max_boxes=5,
                tracking_people=(10,), tracking_cameras=(4,), tracking_ticks=2, tracking_warmup=3, detector_repeats=1)


def test_every_headline_key_comes_from_a_part() -> None:
    assert set(HEADLINE_KEYS.values()) <= set(PARTS)
    assert {"cylinder_batched_ms_per_box", "cylinder_reference_ms_per_box", "cylinder_max_disagreement_m",
            "tracking_ms_per_tick_1000_people_64_cameras", "detector_ms_per_frame_3_3m_2_threads", "live_latency_p50_ms",
            "live_latency_p99_ms", "live_max_cameras_10fps", "gateway_rest_p99_ms", "gateway_ws_fanout_p99_ms"} <= set(HEADLINE_KEYS)


def test_parts_not_run_leave_null_keys_with_reasons() -> None:
    result = run_suite(TINY, ("cylinder",), echo=lambda line: None)
    assert list(result)[: len(HEADLINE_KEYS)] == list(HEADLINE_KEYS)  # the headline comes first, in a fixed order
    assert 0 < result["cylinder_batched_ms_per_box"] and result["cylinder_max_disagreement_m"] < 0.01
    for key, part in HEADLINE_KEYS.items():
        if part != "cylinder":
            assert result[key] is None and result["null_reasons"][key] == f"the {part} part was not run"
    assert "cylinder_batched_ms_per_box" not in result["null_reasons"]
    assert result["failed"] == [] and result["parts_run"] == ["cylinder"]
    json.dumps(result, allow_nan=False)


def test_a_failing_part_is_listed_and_does_not_stop_the_others(monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(settings: Settings) -> None:
        raise RuntimeError("boom")

    monkeypatch.setattr(suite, "run_gateway", broken)
    monkeypatch.setattr(suite, "run_bus", lambda s: ({"bus_frame_p99_ms": 2.5, "bus_json_p99_ms": math.nan}, {}))
    result = run_suite(TINY, ("gateway", "bus"), echo=lambda line: None)
    assert result["failed"] == ["gateway"]
    assert "boom" in result["null_reasons"]["gateway_rest_p99_ms"] and "boom" in result["parts"]["gateway"]["error"]
    assert result["bus_frame_p99_ms"] == 2.5
    assert result["bus_json_p99_ms"] is None and "no finite value" in result["null_reasons"]["bus_json_p99_ms"]


def test_an_unavailable_detector_is_null_with_its_reason_not_a_failure(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(suite, "run_detector", lambda s, model: (_ for _ in ()).throw(suite.Unavailable("no detector model shipped")))
    result = run_suite(TINY, ("detector",), echo=lambda line: None)
    assert result["failed"] == []
    assert result["detector_ms_per_frame_3_3m_2_threads"] is None
    assert result["null_reasons"]["detector_ms_per_frame_3_3m_2_threads"] == "no detector model shipped"


@pytest.mark.parametrize(
    ("missing", "failed", "reason"),
    [
        ("zenoh", [], "this part needs the 'services' extra: pip install 'bevflow[services]'"),  # not installed: null, why
        ("not_a_real_package_for_bevflow_tests", ["bus"], "the bus part failed: ModuleNotFoundError"),  # a bug: a failure
    ],
)
def test_a_part_without_its_extra_is_null_naming_it(monkeypatch: pytest.MonkeyPatch, missing: str, failed: list[str],
                                                    reason: str) -> None:
    def needs(settings: Settings) -> None:
        raise ModuleNotFoundError(f"No module named {missing!r}", name=missing)

    monkeypatch.setattr(suite, "run_bus", needs)
    result = run_suite(TINY, ("bus",), echo=lambda line: None)
    assert result["failed"] == failed
    assert result["bus_frame_p99_ms"] is None and result["null_reasons"]["bus_frame_p99_ms"].startswith(reason)
    if not failed:
        assert f"not measured: {reason}" in console_lines(result)


def test_tracking_skips_crush_densities_and_reports_the_big_case(monkeypatch: pytest.MonkeyPatch) -> None:
    import bevflow_services.benchmarks.tracking as tracking

    calls = []
    monkeypatch.setattr(tracking, "bench_tick", lambda p, c, t, w: calls.append((p, c)) or {"people": p, "cameras": c, "ms_p50": 7.0, "cpu_ms_p50": 5.0})
    settings = Settings(tracking_people=(100, 1000), tracking_cameras=(4, 64))
    head, details = suite.run_tracking(settings)
    assert calls == [(100, 4), (100, 64), (1000, 64)]  # 1,000 people on 4 cameras' 400 m² is skipped
    assert details["skipped"][0]["people"] == 1000 and details["skipped"][0]["cameras"] == 4
    assert head == {"tracking_ms_per_tick_1000_people_64_cameras": 7.0, "tracking_cpu_ms_per_tick_1000_people_64_cameras": 5.0}


def test_json_ready_replaces_every_non_finite_number() -> None:
    value = {"a": math.nan, "b": [1.0, math.inf, {"c": -math.inf}], "d": (2, "x"), "e": None}
    assert json_ready(value) == {"a": None, "b": [1.0, None, {"c": None}], "d": [2, "x"], "e": None}
