"""``bevflow train-detector render``, ``quantize``, ``set-threshold`` and ``calibrate-scores``: options checked
before anything is written."""

from __future__ import annotations

from pathlib import Path

import pytest

from bevflow_services.cli import main


@pytest.mark.parametrize(
    ("heights", "message"),
    [(["5", "3"], "--heights needs 2 <= LOW < HIGH <= 20 metres, got 5 3"),
     (["1", "4"], "--heights needs 2 <= LOW < HIGH <= 20 metres, got 1 4"),
     (["3", "30"], "--heights needs 2 <= LOW < HIGH <= 20 metres, got 3 30")],
)
def test_bad_heights_exit_2_and_write_nothing(tmp_path: Path, capsys: pytest.CaptureFixture, heights: list[str],
                                              message: str) -> None:
    out = tmp_path / "shards"
    assert main(["train-detector", "render", "--out", str(out), "--count", "1", "--heights", *heights]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_render_for_low_ceilings(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "shards"
    assert main(["train-detector", "render", "--out", str(out), "--count", "1", "--seed", "9", "--heights", "3", "4"]) == 0
    assert [p.name for p in out.glob("*.npz")] == ["shard-0009-00000.npz"]
    assert "1 new shards" in capsys.readouterr().out


@pytest.mark.parametrize("step", ["render", "render-eval"])
@pytest.mark.parametrize(("option", "share"), [("--groups", "-0.1"), ("--groups", "1.5"), ("--shifted-tiles", "2"),
                                              ("--squared", "-1")])
def test_a_share_outside_0_to_1_exits_2_and_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture, step: str,
                                                           option: str, share: str) -> None:
    out = tmp_path / "shards"
    assert main(["train-detector", step, "--out", str(out), "--count", "1", option, share]) == 2
    assert f"{option} is a share, 0 to 1, got {float(share):g}" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("zoom", ["0.3", "2.5"])
def test_a_zoom_outside_half_to_twice_the_scale_exits_2_and_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                                           zoom: str) -> None:
    out = tmp_path / "shards"
    assert main(["train-detector", "render", "--out", str(out), "--count", "1", "--zoom", zoom]) == 2
    assert f"--zoom is a multiple of the detector's scale, 0.5 to 2, got {float(zoom):g}" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize(
    ("model", "frames", "count", "message"),
    [("missing.onnx", "frames.json", "32", "--model {dir}/missing.onnx: no such model file"),
     (None, "missing.json", "32", "missing.json"),
     (None, "frames.json", "0", "--count must be positive, got 0")],
)
def test_quantize_refuses_what_it_cannot_use_and_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture, model: str | None,
                                                                frames: str, count: str, message: str) -> None:
    from bevflow.detect.runtime import DEFAULT_MODEL

    (tmp_path / "frames.json").write_text('{"images": [], "annotations": [], "categories": []}')
    out = tmp_path / "int8.onnx"
    args = ["train-detector", "quantize", "--model", str(tmp_path / model) if model else str(DEFAULT_MODEL),
            "--frames", str(tmp_path / frames), "--count", count, "--out", str(out)]
    assert main(args) == 2
    assert message.format(dir=tmp_path) in capsys.readouterr().err
    assert not out.exists()


def test_quantize_with_no_frames_in_the_file_says_so(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from bevflow.detect.runtime import DEFAULT_MODEL

    pytest.importorskip("onnx")
    (tmp_path / "frames.json").write_text('{"images": [], "annotations": [], "categories": []}')
    out = tmp_path / "int8.onnx"
    assert main(["train-detector", "quantize", "--model", str(DEFAULT_MODEL), "--frames", str(tmp_path / "frames.json"),
                 "--out", str(out)]) == 2
    assert "has no frames to calibrate on" in capsys.readouterr().err
    assert not out.exists()


def test_render_eval_draws_its_cameras_from_the_heights_given(tmp_path: Path) -> None:
    import json

    out = tmp_path / "frames"
    assert main(["train-detector", "render-eval", "--out", str(out), "--count", "2", "--seed", "5", "--heights", "3", "3.5"]) == 0
    heights = [im["camera_height_m"] for im in json.loads((out / "annotations.json").read_text())["images"]]
    assert len(heights) == 2 and all(3.0 <= h <= 3.5 for h in heights)


@pytest.mark.parametrize(("frame_px", "code", "width"), [("320", 0, 320), ("10", 2, None), ("9000", 2, None)])
def test_render_eval_draws_frames_of_a_camera_s_size(tmp_path: Path, capsys: pytest.CaptureFixture, frame_px: str, code: int,
                                                     width: int | None) -> None:  # fmt: skip
    import json

    out = tmp_path / "frames"
    assert main(["train-detector", "render-eval", "--out", str(out), "--count", "1", "--seed", "5", "--frame-px", frame_px]) == code
    if width is None:
        assert f"--frame-px must be 64 to 8192 pixels, got {frame_px}" in capsys.readouterr().err
        assert not out.exists()
    else:
        assert [im["width"] for im in json.loads((out / "annotations.json").read_text())["images"]] == [width]


def _model_copy(path: Path) -> Path:
    """A shipped model copied to ``path`` (its file keeps no threshold)."""
    from bevflow.detect.tiles import TILE_MODEL

    path.write_bytes(TILE_MODEL.with_name("fastestdet-coco.onnx").read_bytes())
    return path


def test_set_threshold_keeps_it_in_the_file_and_the_detector_reads_it(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from bevflow.detect.runtime import SCORE_THRESHOLD, Detector

    pytest.importorskip("onnx")
    model = _model_copy(tmp_path / "m.onnx")
    assert Detector(model, threads=1).score_threshold == SCORE_THRESHOLD
    assert main(["train-detector", "set-threshold", "--model", str(model), "--threshold", "0.56"]) == 0
    assert "reports people scoring at least 0.56" in capsys.readouterr().out
    assert Detector(model, threads=1).score_threshold == 0.56


@pytest.mark.parametrize(
    ("model", "threshold", "message"),
    [("missing.onnx", "0.5", "--model {dir}/missing.onnx: no such model file"),
     ("m.onnx", "1.5", "--threshold must lie between 0 and 1, got 1.5"),
     ("m.onnx", "0", "--threshold must lie between 0 and 1, got 0"),
     ("m.onnx", "nan", "--threshold must lie between 0 and 1, got nan"),
     ("junk.onnx", "0.5", "cannot write the threshold into {dir}/junk.onnx")],
)
def test_set_threshold_refuses_and_leaves_the_file_as_it_was(tmp_path: Path, capsys: pytest.CaptureFixture, model: str,
                                                             threshold: str, message: str) -> None:
    pytest.importorskip("onnx")
    _model_copy(tmp_path / "m.onnx")
    (tmp_path / "junk.onnx").write_bytes(b"not a model")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert main(["train-detector", "set-threshold", "--model", str(tmp_path / model), "--threshold", threshold]) == 2
    assert message.format(dir=tmp_path) in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


@pytest.mark.slow
def test_calibrate_scores_keeps_the_map_in_the_file_and_the_detector_reports_on_it(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    import json

    import cv2
    import numpy as np

    from bevflow.detect.confidence import ScoreMap
    from bevflow.detect.runtime import Detector

    pytest.importorskip("onnx")
    frames = tmp_path / "frames"
    assert main(["train-detector", "render-eval", "--out", str(frames), "--count", "8", "--seed", "11"]) == 0
    model = _model_copy(tmp_path / "tiles.onnx")
    capsys.readouterr()
    assert main(["train-detector", "calibrate-scores", "--model", str(model), "--annotations", str(frames / "annotations.json")]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["tile_boxes"] > 0 and result["general_boxes"] > 0
    assert 0 <= result["AP50_raw"] <= 1 and 0 <= result["AP50_mapped"] <= 1
    score_map = ScoreMap.from_text(result["score_map"])
    assert not score_map.is_identity
    mapped, raw = Detector(model, threads=1, score_threshold=0.3), Detector(model, threads=1, score_threshold=0.01, score_map=ScoreMap())
    assert mapped.score_map == score_map
    frame = np.asarray(cv2.imread(str(frames / "frame-00000.png")), np.uint8)[:352, :352]
    tile = np.pad(frame, ((0, 352 - frame.shape[0]), (0, 352 - frame.shape[1]), (0, 0)))  # one tile's input
    got, expected = mapped.detect_scaled(tile).confidence, raw.detect_scaled(tile).confidence
    expected = score_map(expected[expected >= score_map.raw(0.3)])
    assert sorted(got.tolist()) == pytest.approx(sorted(expected.tolist()))


@pytest.mark.parametrize(
    ("model", "annotations", "extra", "message"),
    [("missing.onnx", "frames.json", [], "no such model file: {dir}/missing.onnx"),
     ("m.onnx", "missing.json", [], "no such annotation file: {dir}/missing.json"),
     ("m.onnx", "frames.json", ["--threads", "0"], "--threads must be >= 1, got 0"),
     ("junk.onnx", "frames.json", [], "cannot calibrate {dir}/junk.onnx"),
     ("m.onnx", "frames.json", [], "the frames need camera_height_m and focal_px")],
)
def test_calibrate_scores_refuses_and_leaves_the_file_as_it_was(tmp_path: Path, capsys: pytest.CaptureFixture, model: str,
                                                                annotations: str, extra: list[str], message: str) -> None:
    import json

    import cv2
    import numpy as np

    pytest.importorskip("onnx")
    _model_copy(tmp_path / "m.onnx")
    (tmp_path / "junk.onnx").write_bytes(b"not a model")
    cv2.imwrite(str(tmp_path / "a.png"), np.full((200, 200, 3), 90, np.uint8))  # a frame without its camera's height
    (tmp_path / "frames.json").write_text(json.dumps({"images": [{"id": 1, "file_name": "a.png", "width": 200, "height": 200}],
                                                      "annotations": [], "categories": [{"id": 1, "name": "person"}]}))  # fmt: skip
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert main(["train-detector", "calibrate-scores", "--model", str(tmp_path / model),
                 "--annotations", str(tmp_path / annotations), *extra]) == 2  # fmt: skip
    assert message.format(dir=tmp_path) in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
