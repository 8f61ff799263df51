"""A score's mean, lowest and highest over several takes of one evaluation (perturbed replays,
turned frames), so a change is judged by more than one take."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Spread:
    mean: float
    low: float
    high: float

    @classmethod
    def of(cls, values: Sequence[float]) -> Spread:
        v = np.asarray(values, dtype=np.float64)
        return cls(float(v.mean()), float(v.min()), float(v.max()))

    def as_dict(self) -> dict[str, float]:
        return {"mean": self.mean, "min": self.low, "max": self.high}
