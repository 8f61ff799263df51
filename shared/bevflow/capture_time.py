"""How far a received message's capture times may stray from the receiver's clock.

A capture time is when a camera saw something, so where it arrives it is always a little in the
past (hosts keep their clocks in step with NTP, ``docs/INSTALL.md``). A time far in the future is
a wrong clock or a forged message, and trusting it does lasting harm: every "keep the newest"
rule would refuse the true messages that follow until the wall clock caught up (for
``2**63 - 1`` ns, until the year 2262). So:

- no received message may carry a time beyond ``future_s`` after the receiver's clock
  (``bevflow_services.bus`` refuses and counts it), and readers of stored history ignore rows
  beyond that bound, so a bad row written before this rule cannot pin anything either;
- live state (the gateway's latest tracks and occupancy, the recorder's samples) refuses data
  older than ``past_s``: it is no longer live, and storing it only makes holes in the history.
  Alerts are exempt from the past bound, since an over-capacity alert may have started hours ago;
  they end by themselves instead (``bevflow.alert_lease``).

Both bounds can be set per process with ``BEVFLOW_CLOCK_FUTURE_S`` and ``BEVFLOW_CLOCK_PAST_S``.

>>> window = CaptureWindow(future_s=5.0, past_s=60.0)
>>> now = 1_700_000_000 * NS_PER_S
>>> window.too_new(now + 4 * NS_PER_S, now), window.too_new(2**63 - 1, now), window.too_old(now - 61 * NS_PER_S, now)
(False, True, True)
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel

from bevflow.units import NS_PER_S

# A few seconds: NTP keeps hosts within milliseconds, and nothing is captured in the future.
FUTURE_S = 5.0
# An hour: the gateway's live history; older data is a replay or a stuck clock, not live.
PAST_S = 3600.0
FUTURE_VARIABLE, PAST_VARIABLE = "BEVFLOW_CLOCK_FUTURE_S", "BEVFLOW_CLOCK_PAST_S"


@dataclass(frozen=True)
class CaptureWindow:
    """The span around the receiver's clock (``now_ns``) that received capture times must fall in."""

    future_s: float = FUTURE_S
    past_s: float = PAST_S

    def __post_init__(self) -> None:
        for name, value in (("future_s", self.future_s), ("past_s", self.past_s)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number of seconds >= 0, got {value!r}")

    def latest_ns(self, now_ns: int) -> int:
        """The newest capture time trusted at ``now_ns``."""
        return now_ns + int(self.future_s * NS_PER_S)

    def earliest_ns(self, now_ns: int) -> int:
        """The oldest capture time still live at ``now_ns``."""
        return now_ns - int(self.past_s * NS_PER_S)

    def too_new(self, time_ns: int, now_ns: int) -> bool:
        return time_ns > self.latest_ns(now_ns)

    def too_old(self, time_ns: int, now_ns: int) -> bool:
        return time_ns < self.earliest_ns(now_ns)

    def first_too_new(self, message: Any, now_ns: int) -> tuple[str, int] | None:
        """The first time field of ``message`` beyond the future bound, as (name, value); None if
        there is none. Every ``*_ns`` field of a message is a capture time (``bevflow.schemas``)."""
        for name, value in capture_times(message).items():
            if self.too_new(value, now_ns):
                return name, value
        return None

    @classmethod
    def from_environment(cls, environ: Mapping[str, str] = os.environ) -> CaptureWindow:
        """The window the variables set (the defaults for those unset); ``ValueError`` naming the
        variable for a value that is not a number of seconds >= 0."""
        return cls(future_s=_seconds(environ, FUTURE_VARIABLE, FUTURE_S), past_s=_seconds(environ, PAST_VARIABLE, PAST_S))


def _seconds(environ: Mapping[str, str], variable: str, default: float) -> float:
    text = environ.get(variable, "").strip()
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{variable}={text!r}: give a number of seconds >= 0")
    return value


def capture_times(message: Any) -> dict[str, int]:
    """The ``*_ns`` fields of a message (a pydantic model, or anything with a ``header`` that is
    one, like a frame) that are set."""
    model = getattr(message, "header", message)
    if not isinstance(model, BaseModel):
        return {}
    return {name: value for name in type(model).model_fields
            if name.endswith("_ns") and isinstance(value := getattr(model, name), int)}
