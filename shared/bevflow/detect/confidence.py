"""One confidence scale for every detector: a model's scores mapped onto the general model's.

Each network scores in its own way (FastestDet: objectness^0.6 · class^0.4; the general model: a
heatmap peak), so the same number means a different chance of a real person. Where one site
runs both (the rim tiles under 5 m, the general model above and under the camera), boxes ranked
together, by a threshold or by average precision, mix two scales. A ``ScoreMap`` kept in a model
file (``SCORE_MAP_METADATA_KEY``) turns its scores into the general model's: the score at which
the general model's boxes are as often right. It is a logistic (Platt) map, monotone, so each
model alone ranks its boxes as before and its own AP is unchanged:

    mapped = σ(slope · logit(raw) + offset)

``fit_score_map`` finds it from boxes of both models judged right or wrong on the same held-out
frames (``bevflow.training.score_calibration``). On the held-out renders of docs/RESULTS.md
(mixed heights, at a camera's 2048 px) FastestDet's 0.56 maps to 0.36, and AP50 with the boxes of
both models ranked together rose from 0.925 to 0.963.

>>> m = ScoreMap(slope=0.5, offset=-0.5)
>>> round(float(m(np.array(0.5))), 3), round(float(m.raw(m(np.array(0.8)))), 3)
(0.378, 0.8)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
SCORE_MAP_METADATA_KEY = "bevflow.score_map"
"""ONNX metadata: ``"SLOPE OFFSET"`` of the model's ``ScoreMap`` (written by ``bevflow
train-detector calibrate-scores``); a model without it scores on the general model's scale."""
_EPS = 1e-9  # scores are clipped this far inside 0 and 1 before the logit
_SLOPES = (0.05, 20.0)  # fitted slopes below say the scores mean nothing; above, too few boxes to fit


@dataclass(frozen=True)
class ScoreMap:
    """``mapped = σ(slope · logit(raw) + offset)``; the default changes nothing."""

    slope: float = 1.0
    offset: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.slope) and self.slope > 0 and math.isfinite(self.offset)):
            raise ValueError(f"a score map needs a finite slope > 0 and a finite offset, got {self.slope}, {self.offset}")

    @property
    def is_identity(self) -> bool:
        return self.slope == 1.0 and self.offset == 0.0

    def __call__(self, raw: ArrayLike) -> FloatArray:
        """The mapped scores of ``raw`` scores (0 and 1 stay 0 and 1)."""
        r = np.asarray(raw, np.float64)
        if self.is_identity:
            return r
        return np.where((r <= 0) | (r >= 1), np.clip(r, 0, 1), _sigmoid(self.slope * _logit(r) + self.offset))

    def raw(self, mapped: float) -> float:
        """The raw score that maps to ``mapped``: what a threshold on mapped scores asks of the model."""
        if self.is_identity or mapped <= 0 or mapped >= 1:
            return float(mapped)
        return float(_sigmoid((_logit(np.array([mapped], np.float64)) - self.offset) / self.slope)[0])

    def to_text(self) -> str:
        return f"{self.slope:.6g} {self.offset:.6g}"

    @classmethod
    def from_text(cls, text: str) -> ScoreMap:
        """``"SLOPE OFFSET"`` as ``to_text`` writes it; ValueError saying what is wrong otherwise."""
        parts = text.split()
        try:
            slope, offset = (float(p) for p in parts)
        except ValueError:
            raise ValueError(f"a score map is two numbers, 'SLOPE OFFSET', got {text!r}") from None
        return cls(slope, offset)


def fit_platt(scores: ArrayLike, right: ArrayLike, iterations: int = 50) -> tuple[float, float]:
    """(a, b) of P(right | score) = σ(a · logit(score) + b), by maximum likelihood (Newton's
    method on the two parameters). ValueError without both right and wrong boxes."""
    x = _logit(np.asarray(scores, np.float64).ravel())
    y = np.asarray(right, np.float64).ravel()
    if len(x) != len(y):
        raise ValueError(f"{len(x)} scores but {len(y)} judgements")
    if not (0 < y.sum() < len(y)):
        raise ValueError("fitting a score map needs boxes judged right and boxes judged wrong")
    design = np.column_stack([x, np.ones_like(x)])
    ab = np.array([1.0, 0.0])
    for _ in range(iterations):
        p = _sigmoid(design @ ab)
        w = p * (1 - p) + 1e-12
        step = np.linalg.solve(design.T @ (design * w[:, None]) + 1e-9 * np.eye(2), design.T @ (y - p))
        ab += step
        if np.abs(step).max() < 1e-10:
            break
    return float(ab[0]), float(ab[1])


def fit_score_map(model: tuple[ArrayLike, ArrayLike], reference: tuple[ArrayLike, ArrayLike]) -> ScoreMap:
    """The map from ``model``'s scores onto ``reference``'s, each given as (scores, judged right):
    a model score goes to the reference score with the same fitted chance of being right."""
    a_m, b_m = fit_platt(*model)
    a_r, b_r = fit_platt(*reference)
    slopes = f"fitted slopes {a_m:.3g} for the model, {a_r:.3g} for the reference"
    if min(a_m, a_r) <= _SLOPES[0]:
        raise ValueError(f"the scores say little about being right ({slopes}): no map fitted")
    if max(a_m, a_r) >= _SLOPES[1]:
        raise ValueError(f"a score splits the boxes judged right from the wrong ones too cleanly to fit ({slopes}): "
                         "too few boxes? give more frames")  # fmt: skip
    return ScoreMap(slope=a_m / a_r, offset=(b_m - b_r) / a_r)


def _logit(p: FloatArray) -> FloatArray:
    q = np.clip(p, _EPS, 1 - _EPS)
    return np.asarray(np.log(q / (1 - q)), np.float64)


def _sigmoid(z: FloatArray) -> FloatArray:
    return np.asarray(0.5 * (1 + np.tanh(0.5 * z)), np.float64)
