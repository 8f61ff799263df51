"""Standard-library timers shared by the benchmarks: repeated calls, medians, percentiles.

Every benchmark reports the wall-clock median (``time.perf_counter``) and the median CPU time of
the calling thread (``time.thread_time``). On a machine that other jobs share, wall-clock time
includes waiting for a core; CPU time does not, so it is the steadier of the two, and the gap
between them says how busy the machine was.
"""

from __future__ import annotations

import math
import os
import platform
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Generic, TypeVar

from bevflow_services.runtime import usable_cores

R = TypeVar("R")


@dataclass(frozen=True)
class Timing(Generic[R]):
    """Seconds of repeated calls, as lists (one entry per call), and what the last call returned."""

    wall_s: list[float]
    cpu_s: list[float]
    result: R

    @property
    def wall_ms(self) -> float:
        """Median wall-clock milliseconds per call."""
        return statistics.median(self.wall_s) * 1e3 if self.wall_s else math.nan

    @property
    def cpu_ms(self) -> float:
        """Median milliseconds of the calling thread's CPU time per call."""
        return statistics.median(self.cpu_s) * 1e3 if self.cpu_s else math.nan

    def wall_percentile_ms(self, q: float) -> float:
        return percentile([s * 1e3 for s in self.wall_s], q)


def time_calls(call: Callable[[], R], repeats: int) -> Timing[R]:
    """Call ``call`` ``repeats`` times (at least once) and time each call."""
    wall, cpu = [], []
    for _ in range(max(repeats, 1)):
        start, start_cpu = time.perf_counter(), time.thread_time()
        result = call()
        wall.append(time.perf_counter() - start)
        cpu.append(time.thread_time() - start_cpu)
    return Timing(wall, cpu, result)


def percentile(values: list[float], q: float) -> float:
    """The ``q``-th percentile (0-100) by nearest rank; NaN for no values."""
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q / 100 * (len(ordered) - 1))))]


def finite_or_none(value: float | None) -> float | None:
    """``value`` for JSON: NaN and infinities become null (strict JSON has no NaN)."""
    return value if value is not None and math.isfinite(value) else None


def machine() -> dict[str, object]:
    """What a benchmark ran on: cores, CPU model, load average when asked, Python."""
    model = platform.processor() or "unknown"
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            model = next((line.split(":", 1)[1].strip() for line in cpuinfo if line.startswith("model name")), model)
    except OSError:
        pass
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = []
    return {
        "cpus": os.cpu_count(),
        "cpus_usable": usable_cores(),
        "cpu_model": model,
        "load_average_1_5_15": load,
        "python": platform.python_version(),
        "platform": platform.platform(),
    }
