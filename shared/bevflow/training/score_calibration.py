"""The rim tiles' scores put on the general model's scale (``bevflow.detect.confidence``):
``bevflow train-detector calibrate-scores --model TILES.onnx --annotations FILE``.

On held-out rendered frames of mixed heights (``render-eval`` with a seed of its own), the
default detectors run as a site runs them: the rim tiles through ``TILES.onnx`` on frames under
5 m, the general model on the rest and under the camera. Each box is judged right (it matches a
person at IoU 0.5, greedy by score, as AP50 matches) or wrong; the tiles' scores are read raw,
whatever map the file holds. ``fit_score_map`` then gives the map from the tiles' scores to the
general model's, and the result says the frames' AP50, all boxes ranked together, before and
after it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from bevflow.detect.confidence import ScoreMap, fit_score_map
from bevflow.detect.runtime import DEFAULT_RANGES, DetectorBank
from bevflow.detect.tiles import RIM_TILES, RimTileDetector
from bevflow.evaluation.detector import FrameResult, detect_frames, in_crowd, match_image, score_frames

FloatArray = NDArray[np.float64]
SCORE_FLOOR = 0.05  # as evaluations: every box down to this raw score is judged
RIM_TILES_BELOW_M = DEFAULT_RANGES[0].max_m


@dataclass(frozen=True)
class ScoreCalibration:
    """The fitted map, how many boxes of each model it was fitted on, and the frames' AP50 with
    every box ranked together, with the tiles' raw scores and with them mapped."""

    score_map: ScoreMap
    tile_boxes: int
    general_boxes: int
    ap50_raw: float
    ap50_mapped: float

    def as_dict(self) -> dict[str, object]:
        return {"score_map": self.score_map.to_text(), "tile_boxes": self.tile_boxes, "general_boxes": self.general_boxes,
                "AP50_raw": round(self.ap50_raw, 4), "AP50_mapped": round(self.ap50_mapped, 4)}  # fmt: skip


def calibrate_tile_scores(tile_model: Path, annotations: Path, images_dir: Path | None = None, threads: int = 2) -> ScoreCalibration:
    """Fit ``tile_model``'s ``ScoreMap`` on the frames of a COCO file whose images carry their
    camera's height and focal length (``render-eval`` writes them). ValueError, saying why, where
    the frames lack those or give either model too few boxes to fit (``fit_score_map``)."""
    low, high = DEFAULT_RANGES
    bank = DetectorBank((replace(low, model=f"{RIM_TILES}:{tile_model}"), high), threads=threads, score_threshold=SCORE_FLOOR)
    tiles = bank.for_height(low.min_m)
    assert isinstance(tiles, RimTileDetector)
    tiles.tile_detector.score_map = ScoreMap()  # judged by its raw scores, whatever map its file keeps
    results, _ = detect_frames(bank, annotations, images_dir)
    from_tiles = [_tile_boxes(tiles, r) for r in results]
    scores, right, counted = (np.concatenate(x) for x in zip(*[_judged(r) for r in results], strict=True))
    tiled = np.concatenate(from_tiles)
    for boxes, which in ((counted & tiled, f"the rim tiles (cameras under {RIM_TILES_BELOW_M:g} m)"),
                         (counted & ~tiled, f"the general model (cameras from {RIM_TILES_BELOW_M:g} m)")):  # fmt: skip
        if not boxes.any():
            raise ValueError(f"the frames gave {which} no boxes: give frames of cameras both under and over {RIM_TILES_BELOW_M:g} m")
    score_map = fit_score_map((scores[counted & tiled], right[counted & tiled]), (scores[counted & ~tiled], right[counted & ~tiled]))
    mapped = [replace(r, confidence=np.where(m, score_map(r.confidence), r.confidence)) for r, m in zip(results, from_tiles, strict=True)]
    return ScoreCalibration(score_map, int((counted & tiled).sum()), int((counted & ~tiled).sum()),
                            score_frames(results).AP50, score_frames(mapped).AP50)  # fmt: skip


def _tile_boxes(tiles: RimTileDetector, result: FrameResult) -> NDArray[np.bool_]:
    """Which of a frame's boxes the tiles gave (frames under ``RIM_TILES_BELOW_M`` only)."""
    setup = result.setup
    if setup.assumed is not None or setup.camera_height_m is None or setup.focal_px is None:
        raise ValueError(f"{result.entry.path.name}: the frames need camera_height_m and focal_px (render-eval writes them)")
    if setup.camera_height_m >= RIM_TILES_BELOW_M:
        return np.zeros(len(result.confidence), dtype=bool)
    return tiles.from_tiles(result.rotated, setup.focal_px, setup.centre)


def _judged(result: FrameResult) -> tuple[FloatArray, NDArray[np.bool_], NDArray[np.bool_]]:
    """A frame's scores, whether each box is right, and whether it counts: a wrong box inside a
    crowd region does not (nor does it for AP50)."""
    right = match_image(result.xyxy, result.confidence, result.truth_xyxy)
    return result.confidence, right, right | ~in_crowd(result.xyxy, result.crowd_xyxy)
