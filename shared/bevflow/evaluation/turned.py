"""How far a detector's scores hang on where people happen to lie about a fisheye's centre.

A ceiling fisheye can be mounted at any turn about its axis, so which way the people of a room lie
in the frame is chance. A detector that treats directions differently (the rim tiles cut the
frame into 45° sectors, ``bevflow.detect.tiles``) may score well on a few frames because their
people lie in its favourable directions. ``turned`` gives a frame and its truth as a camera turned
by some degrees about the image circle's centre would have seen them; scoring the same frames at
several turns (``bevflow evaluate --detector --turns N``) shows the spread a mounting could give.

On the real frames of docs/RESULTS.md, five turns 72° apart (every 9° within a tile's 45°) took the
rim tiles' AP50 from 0.85 to 0.31 at the worst turn while boxes kept their tile's angle; turned to
their radial angle, 0.64 at worst.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.detect.coco import CocoImage
from bevflow.evaluation.spread import Spread


def turned(entry: CocoImage, image: NDArray[np.uint8], centre: tuple[float, float], degrees: float) -> tuple[CocoImage, NDArray[np.uint8]]:
    """``entry`` and ``image`` turned by ``degrees`` counter-clockwise on screen about ``centre``
    (frame pixels). What leaves the frame is black; people (and crowd regions) whose box centre
    leaves it are dropped. Needs rotated truth (``entry.oriented``): an axis-aligned box turned is
    no longer the box a person would have had."""
    if not entry.oriented:
        raise ValueError(f"{entry.path.name}: turning a frame needs rotated truth boxes ([cx, cy, w, h, degrees])")
    h, w = image.shape[:2]
    m = cv2.getRotationMatrix2D(centre, degrees, 1.0)
    out = np.asarray(cv2.warpAffine(image, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT), dtype=np.uint8)

    def turn(rotated: NDArray[np.float64]) -> NDArray[np.float64]:
        boxes = rotated.copy()
        boxes[:, :2] = boxes[:, :2] @ m[:, :2].T + m[:, 2]
        boxes[:, 4] -= degrees  # box angles turn clockwise on screen (bevflow.detect.rotated)
        inside = (boxes[:, 0] >= 0) & (boxes[:, 0] < w) & (boxes[:, 1] >= 0) & (boxes[:, 1] < h)
        kept: NDArray[np.float64] = boxes[inside]
        return kept

    return replace(entry, rotated=turn(entry.rotated), crowd=turn(entry.crowd)), out


TURN_SCORED = ("AP50", "AP50_rotated", "precision", "recall", "F1")


def turn_angles(turns: int) -> list[float]:
    """``turns`` turns spread evenly round the circle, the first none: k · 360° / ``turns``. Five
    fall 9° apart within a tile's 45° (72° is 27° past one tile), as any count that shares no
    factor with 8 spreads over it."""
    if turns < 1:
        raise ValueError(f"turns must be >= 1, got {turns}")
    return [360.0 * k / turns for k in range(turns)]


@dataclass(frozen=True)
class TurnedScores:
    """Each of ``TURN_SCORED``'s mean, lowest and highest over the frames scored at ``degrees``."""

    degrees: tuple[float, ...]
    scores: dict[str, Spread]

    @classmethod
    def of(cls, degrees: Sequence[float], per_turn: Sequence[Mapping[str, Any]]) -> TurnedScores:
        return cls(tuple(degrees), {k: Spread.of([float(s[k]) for s in per_turn]) for k in TURN_SCORED})

    def as_dict(self) -> dict[str, Any]:
        return {"degrees": list(self.degrees)} | {k: s.as_dict() for k, s in self.scores.items()}
