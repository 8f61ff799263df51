"""Settings kept in a model file: written beside its other keys, read back by the detector."""

from __future__ import annotations

from pathlib import Path

import pytest

onnx = pytest.importorskip("onnx")

from onnx import TensorProto, helper  # noqa: E402

from bevflow.detect.confidence import ScoreMap  # noqa: E402
from bevflow.training.metadata import set_metadata, set_score_map, set_score_threshold  # noqa: E402


def _model(path: Path, props: dict[str, str]) -> Path:
    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "tiny",
                              [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])])  # fmt: skip
    model = helper.make_model(graph)
    helper.set_model_props(model, props)
    onnx.save(model, str(path))
    return path


def _props(path: Path) -> dict[str, str]:
    return {p.key: p.value for p in onnx.load(str(path)).metadata_props}


def test_a_key_is_written_and_the_others_kept(tmp_path: Path) -> None:
    path = _model(tmp_path / "m.onnx", {"bevflow.zoom": "1.5", "bevflow.score_threshold": "0.3"})
    set_metadata(path, "bevflow.score_threshold", "0.6")
    assert _props(path) == {"bevflow.zoom": "1.5", "bevflow.score_threshold": "0.6"}


@pytest.mark.parametrize("threshold", [0.0, 1.0, -0.2, float("nan"), float("inf")])
def test_a_threshold_outside_0_to_1_is_refused_before_the_file_is_touched(tmp_path: Path, threshold: float) -> None:
    path = _model(tmp_path / "m.onnx", {})
    before = path.read_bytes()
    with pytest.raises(ValueError, match="between 0 and 1"):
        set_score_threshold(path, threshold)
    assert path.read_bytes() == before


def test_a_score_map_is_kept_as_the_detector_reads_it(tmp_path: Path) -> None:
    path = _model(tmp_path / "m.onnx", {"bevflow.score_threshold": "0.41"})
    set_score_map(path, ScoreMap(0.568162, -0.507443))
    assert _props(path) == {"bevflow.score_threshold": "0.41", "bevflow.score_map": "0.568162 -0.507443"}
    assert ScoreMap.from_text(_props(path)["bevflow.score_map"]) == ScoreMap(0.568162, -0.507443)
