"""``bevflow evaluate --detector --images DIR --annotations FILE``: what it prints and writes, and
the options it refuses. Tiny synthetic frames through the shipped model (fast)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from bevflow_services.cli import main


def _frames(tmp_path: Path) -> tuple[Path, Path]:
    images = tmp_path / "images"
    images.mkdir()
    frame = np.zeros((320, 320, 3), np.uint8)
    cv2.circle(frame, (160, 160), 150, (110, 120, 130), -1)
    cv2.imwrite(str(images / "a.jpg"), frame)
    doc = {"images": [{"id": 1, "file_name": "a.jpg"}], "categories": [{"id": 1, "name": "person"}],
           "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [160, 250, 30, 60, 0]}]}
    (tmp_path / "ann.json").write_text(json.dumps(doc))
    return images, tmp_path / "ann.json"


def test_scores_draws_and_says_what_it_assumed(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, ann = _frames(tmp_path)
    args = ["evaluate", "--detector", "--images", str(images), "--annotations", str(ann), "--draw", str(tmp_path / "drawn"),
            "--json", str(tmp_path / "out.json")]  # fmt: skip
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "a.jpg: no calibration given; assumed image circle centre (160, 160), radius 150 px" in out
    assert "190° equidistant lens; camera 3 m above the floor" in out
    assert "AP50_rotated" in out and "ms per frame" in out
    assert "models by camera height: under 5 m: rim-tiles; from 5 m: bevflow-person-centernet" in out
    result = json.loads((tmp_path / "out.json").read_text())
    assert {"AP50", "AP50_rotated", "precision", "recall", "F1", "ms_per_frame"} <= set(result)
    assert cv2.imread(str(tmp_path / "drawn" / "a.jpg")).shape == (320, 320, 3)


def test_given_calibration_is_used_and_nothing_is_assumed(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, ann = _frames(tmp_path)
    assert main(["evaluate", "--detector", "--images", str(images), "--annotations", str(ann), "--camera-height", "3.3", "--focal", "95"]) == 0
    out = capsys.readouterr().out
    assert "assumed" not in out


@pytest.mark.parametrize(
    ("extra", "message"),
    [(["--camera-height", "3"], "give --camera-height and --focal together"),
     (["--scale", "0"], "--scale must be a number > 0, got 0.0"),
     (["--threads", "0"], "--threads must be positive, got 0"),
     (["--turns", "0"], "--turns must be a number of turns >= 1, got 0"),
     (["--model", "rim-tiles", "--scale", "0.5"], "--model rim-tiles sizes its tiles from the focal length"),
     (["--tile-model", "x.onnx"], "--tile-model goes with --model rim-tiles"),
     (["--model", "nope"], "detector model 'nope' is neither an ONNX file nor a shipped model (shipped: "),
     (["--model", "rim-tiles", "--tile-model", "nope"], "detector model 'nope' is neither"),
     (["--model", "rim-tiles:nope"], "detector model 'nope' is neither"),
     (["--model", "rim-tiles:"], "'rim-tiles:' names no tile model: write rim-tiles:MODEL"),
     (["--model", "rim-tiles:yolox-nano-coco", "--tile-model", "yolox-nano-coco"],
      "--tile-model goes with --model rim-tiles (or --model rim-tiles:MODEL alone)"),
     (["--model", "rim-tiles:yolox-nano-coco", "--scale", "0.5"], "--model rim-tiles sizes its tiles from the focal length")],
)
def test_bad_options_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture, extra: list[str], message: str) -> None:
    images, ann = _frames(tmp_path)
    assert main(["evaluate", "--detector", "--images", str(images), "--annotations", str(ann), *extra]) == 2
    assert message in capsys.readouterr().err


def test_rim_tiles_runs_on_the_same_frames(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, ann = _frames(tmp_path)
    assert main(["evaluate", "--detector", "--model", "rim-tiles", "--images", str(images), "--annotations", str(ann)]) == 0
    assert "AP50_rotated" in capsys.readouterr().out


@pytest.mark.parametrize("model", [["--model", "bevflow-person-centernet-int8", "--scale", "1"],
                                   ["--model", "rim-tiles", "--tile-model", "yolox-nano-coco"],
                                   ["--model", "rim-tiles:yolox-nano-coco"]])
def test_a_shipped_model_is_named_as_in_a_site_file(tmp_path: Path, capsys: pytest.CaptureFixture, model: list[str]) -> None:
    images, ann = _frames(tmp_path)
    assert main(["evaluate", "--detector", *model, "--images", str(images), "--annotations", str(ann)]) == 0
    assert "AP50_rotated" in capsys.readouterr().out


def test_turns_print_and_write_each_scores_spread(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, ann = _frames(tmp_path)
    assert main(["evaluate", "--detector", "--images", str(images), "--annotations", str(ann), "--turns", "3", "--json", str(tmp_path / "out.json")]) == 0
    assert "3 turns (0, 120, 240 degrees): AP50 " in capsys.readouterr().out
    turned = json.loads((tmp_path / "out.json").read_text())["turned"]
    assert turned["degrees"] == [0.0, 120.0, 240.0]
    for key in ("AP50", "AP50_rotated", "precision", "recall", "F1"):
        assert turned[key]["min"] <= turned[key]["mean"] <= turned[key]["max"]


def test_turns_need_rotated_truth(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, ann = _frames(tmp_path)
    doc = json.loads(ann.read_text())
    doc["annotations"][0]["bbox"] = [145, 220, 30, 60]  # [x, y, w, h]: no angle
    ann.write_text(json.dumps(doc))
    assert main(["evaluate", "--detector", "--images", str(images), "--annotations", str(ann), "--turns", "2"]) == 2
    out, err = capsys.readouterr()
    assert f"--turns needs rotated truth boxes ([cx, cy, w, h, degrees]); {ann} has axis-aligned ones" in err
    assert "AP50" not in out  # refused before any frame went through the detector


def test_without_annotations_each_frame_is_counted_and_drawn_not_scored(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    images, _ = _frames(tmp_path)
    cv2.imwrite(str(images / "b.PNG"), cv2.imread(str(images / "a.jpg")))
    (images / "notes.txt").write_text("not a frame")
    args = ["evaluate", "--detector", "--images", str(images), "--draw", str(tmp_path / "drawn"), "--json", str(tmp_path / "out.json")]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "a.jpg: no calibration given; assumed image circle centre (160, 160)" in out
    assert "a.jpg: 0 people" in out and "b.PNG: 0 people" in out
    assert "2 images, 0 people as the live detector reports them" in out and "nothing scored: no --annotations" in out
    assert "AP50" not in out
    assert json.loads((tmp_path / "out.json").read_text())["people"] == {"a.jpg": 0, "b.PNG": 0}
    assert sorted(p.name for p in (tmp_path / "drawn").iterdir()) == ["a.jpg", "b.jpg"]


@pytest.mark.parametrize(
    ("setup", "extra", "message"),
    [("no images", [], "holds no image (.jpg, .jpeg, .png"),
     ("broken image", [], "cannot read image"),
     (None, ["--turns", "2"], "--turns scores turned frames against their truth: it needs --annotations FILE")],
)
def test_frames_without_annotations_refuse_bad_input_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture, setup, extra, message) -> None:  # noqa: ANN001
    images, _ = _frames(tmp_path)
    if setup == "no images":
        (images / "a.jpg").unlink()
    elif setup == "broken image":
        (images / "c.jpg").write_bytes(b"not a jpeg")
    assert main(["evaluate", "--detector", "--images", str(images), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
