from __future__ import annotations

import math

import pytest

from bevflow_services.benchmarks.timing import Timing, finite_or_none, machine, percentile, time_calls


def test_time_calls_times_every_call_and_keeps_the_last_result() -> None:
    calls = []
    timing = time_calls(lambda: calls.append(len(calls)) or len(calls), 4)
    assert calls == [0, 1, 2, 3]
    assert timing.result == 4
    assert len(timing.wall_s) == len(timing.cpu_s) == 4
    assert all(s >= 0 for s in timing.wall_s + timing.cpu_s)


def test_time_calls_calls_at_least_once() -> None:
    assert len(time_calls(lambda: None, 0).wall_s) == 1


def test_medians_are_in_milliseconds() -> None:
    timing = Timing(wall_s=[0.001, 0.003, 0.002], cpu_s=[0.0005, 0.0005, 0.004], result=None)
    assert timing.wall_ms == pytest.approx(2.0)
    assert timing.cpu_ms == pytest.approx(0.5)
    assert timing.wall_percentile_ms(100) == pytest.approx(3.0)


@pytest.mark.parametrize(
    ("values", "q", "expected"),
    [
        ([3.0, 1.0, 2.0], 50, 2.0),
        ([3.0, 1.0, 2.0], 0, 1.0),
        ([3.0, 1.0, 2.0], 100, 3.0),
        (list(range(101)), 99, 99),
        ([5.0], 99, 5.0),
    ],
)
def test_percentile_by_nearest_rank(values: list[float], q: float, expected: float) -> None:
    assert percentile(values, q) == expected


def test_percentile_of_nothing_is_nan() -> None:
    assert math.isnan(percentile([], 50))


@pytest.mark.parametrize(("value", "expected"), [(1.5, 1.5), (math.nan, None), (math.inf, None), (None, None), (0.0, 0.0)])
def test_finite_or_none(value: float | None, expected: float | None) -> None:
    assert finite_or_none(value) == expected


def test_machine_names_cores_model_and_load() -> None:
    m = machine()
    assert isinstance(m["cpus"], int) and m["cpus"] >= 1
    assert isinstance(m["cpu_model"], str) and m["cpu_model"]
    assert len(m["load_average_1_5_15"]) == 3
