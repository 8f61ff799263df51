"""Crowd surges: for a while, more people come in and all head for one area (boarding at a gate,
a sale in a shop), then things go back to normal as they leave.

A ``Surge`` in ``SceneConfig.surges`` raises the number of people inside at once by ``extra`` from
``start_s`` to ``end_s`` (repeating every ``every_s`` seconds if given); a ``share`` of the visits
planned meanwhile go to ``area`` and stay there a while (a queue). Nothing changes outside a surge, so a
scene without surges runs exactly as before.

>>> s = Surge(start_s=60.0, end_s=180.0, area=((0, 0), (4, 0), (4, 4), (0, 4)), extra=20, every_s=600.0)
>>> [s.active(t) for t in (59.0, 60.0, 179.9, 180.0, 665.0)]
[False, True, True, False, True]
>>> extra_people((s,), 100.0), surge_area((s,), 300.0) is None
(20, True)
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Surge:
    start_s: float
    end_s: float
    area: tuple[tuple[float, float], ...]
    extra: int = 0
    every_s: float | None = None
    share: float = 1.0  # of the visits planned during the surge, the share that go to the area
    stay_s: tuple[float, float] = (60.0, 150.0)  # how long each visitor stays in the area

    def __post_init__(self) -> None:
        if not 0 <= self.start_s < self.end_s:
            raise ValueError(f"a surge runs from start_s to a later end_s, got {self.start_s}..{self.end_s}")
        if self.every_s is not None and self.every_s < self.end_s - self.start_s:
            raise ValueError("every_s must be at least the surge's length")
        if len(self.area) < 3 or self.extra < 0 or not 0.0 <= self.share <= 1.0:
            raise ValueError("a surge needs an area polygon (3 or more corners), extra >= 0 and a share in [0, 1]")

    def active(self, t: float) -> bool:
        if t < self.start_s:
            return False
        since = t - self.start_s if self.every_s is None else (t - self.start_s) % self.every_s
        return since < self.end_s - self.start_s


def extra_people(surges: tuple[Surge, ...], t: float) -> int:
    """How many more people than usual are inside at ``t``."""
    return sum(s.extra for s in surges if s.active(t))


def surge_area(surges: tuple[Surge, ...], t: float) -> Surge | None:
    """The first surge going on at ``t``, whose area every new visit heads for; None outside one."""
    return next((s for s in surges if s.active(t)), None)
