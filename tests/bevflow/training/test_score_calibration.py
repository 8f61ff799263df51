"""Fitting a tile model's score map on rendered frames: both models must give boxes to fit on."""

from __future__ import annotations

from pathlib import Path

import pytest

from bevflow.detect.confidence import ScoreMap
from bevflow.detect.tiles import TILE_MODEL
from bevflow.training.dataset import render_evaluation_set
from bevflow.training.score_calibration import calibrate_tile_scores


def test_frames_of_high_cameras_alone_give_the_tiles_nothing_to_fit_and_say_so(tmp_path: Path) -> None:
    annotations = render_evaluation_set(tmp_path, 2, seed=21, heights=(6.0, 8.0))
    with pytest.raises(ValueError, match=r"gave the rim tiles \(cameras under 5 m\) no boxes: give frames of cameras both under and over 5 m"):
        calibrate_tile_scores(TILE_MODEL, annotations, threads=1)


@pytest.mark.slow
def test_a_fit_reads_the_tiles_raw_scores_whatever_map_the_file_keeps(tmp_path: Path) -> None:
    """Refitting a file that keeps another map gives the same map: it is fitted on raw scores, not on mapped ones."""
    pytest.importorskip("onnx")
    from bevflow.training.metadata import set_score_map

    annotations = render_evaluation_set(tmp_path, 8, seed=11)
    shipped = calibrate_tile_scores(TILE_MODEL, annotations, threads=1)
    other = tmp_path / "other.onnx"
    other.write_bytes(TILE_MODEL.read_bytes())
    set_score_map(other, ScoreMap(2.0, 1.0))
    again = calibrate_tile_scores(other, annotations, threads=1)
    assert again.score_map == shipped.score_map and not shipped.score_map.is_identity
    assert shipped.tile_boxes > 0 and shipped.general_boxes > 0
    assert 0 <= shipped.ap50_raw <= 1 and 0 <= shipped.ap50_mapped <= 1
