"""The paper suite with the shipped detector on rendered frames (``run_suite(detector=True)``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bevflow.detections import Boxes
from bevflow.evaluation.rendered import MATCH_IOU, attribute
from bevflow.evaluation.suite import SuiteResult, paper_presets, run_suite, simulate
from bevflow.sim.views import CameraView
from bevflow_services.cli import main

pytest.importorskip("onnxruntime")


def view_of(xyxy: list[list[float]]) -> CameraView:
    n = len(xyxy)
    boxes = Boxes(xyxy=np.asarray(xyxy, dtype=np.float64).reshape(-1, 4))
    return CameraView(0, boxes, np.arange(10, 10 + n), np.ones(n), np.zeros(n, bool), np.zeros((n, 2)))


@pytest.mark.parametrize(
    ("detected", "expected"),
    [
        ([[51, 50, 61, 60], [1, 0, 11, 10]], [1, 0]),  # each box to the silhouette it overlaps
        ([[0, 0, 10, 10], [1, 0, 11, 10]], [0, -1]),  # one box per person: the better one wins
        ([[100, 100, 110, 110]], [-1]),  # overlaps nobody: a false positive
        ([[0, 0, 10, 25]], [0]),  # loose (IoU 0.4), still above the IoU floor
        ([[0, 0, 10, 40]], [-1]),  # IoU 0.25: below it
    ],
)
def test_attribute_matches_boxes_one_to_one(detected: list[list[float]], expected: list[int]) -> None:
    view = view_of([[0, 0, 10, 10], [50, 50, 60, 60]])
    assert attribute(Boxes(xyxy=np.asarray(detected, float)), view).tolist() == expected


def test_the_iou_floor_is_between_the_two_loose_boxes() -> None:
    assert 0.25 < MATCH_IOU <= 0.4


def test_attribute_with_nothing_on_either_side() -> None:
    assert attribute(Boxes.empty(), view_of([[0, 0, 10, 10]])).tolist() == []
    assert attribute(Boxes(xyxy=np.array([[0.0, 0, 10, 10]])), view_of([])).tolist() == [-1]


def test_detected_boxes_land_on_the_people_the_simulator_sees() -> None:
    (preset,) = paper_presets(0.02, [4])
    seq = simulate(preset, detector=True)
    assert seq.detected is not None and len(seq.detected) == len(seq)
    found = matched = 0
    for boxes_per_camera, views in zip(seq.detected, seq.views, strict=True):
        for boxes, view in zip(boxes_per_camera, views, strict=True):
            found += len(view)
            matched += int((attribute(boxes, view) >= 0).sum())
    # The detector finds most of the boxed people, in the calibrated image's pixels.
    assert found > 20 and matched >= 0.8 * found


@pytest.fixture(scope="module")
def detector_run() -> SuiteResult:
    return run_suite("paper", frames_scale=0.03, sequences=[4], methods=["cylinder", "bbox-center"], detector=True)


def test_the_detector_suite_runs_end_to_end_with_sane_scores(detector_run: SuiteResult) -> None:
    assert detector_run.detector and detector_run.as_dict()["detector"] is True
    rows = {(r.cameras, r.method): r.record() for r in detector_run.rows}
    assert set(rows) == {(c, m) for c in [("cam1", "cam2"), ("cam1",), ("cam2",)] for m in ("cylinder", "bbox-center")}
    for cameras in [("cam1", "cam2"), ("cam1",), ("cam2",)]:
        cyl, centre = rows[(cameras, "cylinder")], rows[(cameras, "bbox-center")]
        assert cyl["F1"] > 0.8 and cyl["MOTA"] > 0.6
        assert cyl["box_APE"] < 0.2
        assert centre["box_APE"] > 2 * cyl["box_APE"]  # the paper's point holds on real detections too


def test_the_detector_replaces_the_noise_model(detector_run: SuiteResult) -> None:
    noisy = run_suite("paper", frames_scale=0.03, sequences=[4], methods=["cylinder"])
    box_ape = [r.box_ape for r in detector_run.rows if r.method == "cylinder"]
    assert box_ape != [r.box_ape for r in noisy.rows]


# --- the command line (``bevflow evaluate --suite paper --detector``) ------------------------------
@pytest.mark.parametrize(
    ("extra", "message"),
    [(["--jitter", "0.1"], "drop --jitter"), (["--drop", "0.1"], "drop --jitter"), (["--model", "no-such.onnx"], "no such file")],
)
def test_detector_suite_mistakes_are_user_errors(capsys: pytest.CaptureFixture, extra: list[str], message: str) -> None:
    assert main(["evaluate", "--suite", "paper", "--detector", "--frames-scale", "0.01", *extra]) == 2
    assert message in capsys.readouterr().err


def test_detector_suite_prints_both_tables_and_writes_the_rows(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "suite.json"
    args = ["evaluate", "--suite", "paper", "--detector", "--frames-scale", "0.01", "--jobs", "1", "--json", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "shipped detectors (by camera height) on rendered frames" in printed.splitlines()[0]
    assert "Table 2" in printed and "Table 3" in printed
    payload = json.loads(out.read_text())
    assert payload["detector"] is True
    assert len(payload["rows"]) == 51  # (5 sequences x 3 camera sets + 2 x 1) x 3 methods


def test_detector_suite_runs_another_model(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    import shutil

    from bevflow.detect.runtime import DEFAULT_MODEL

    model = shutil.copy(DEFAULT_MODEL, tmp_path / "mine.onnx")
    out = tmp_path / "suite.json"
    args = ["evaluate", "--suite", "paper", "--detector", "--model", str(model), "--frames-scale", "0.005", "--jobs", "1", "--json", str(out)]
    assert main(args) == 0
    assert f"the detector {model} on rendered frames" in capsys.readouterr().out.splitlines()[0]
    assert json.loads(out.read_text())["model"] == str(model)


def test_model_without_detector_is_a_user_error(capsys: pytest.CaptureFixture) -> None:
    assert main(["evaluate", "--suite", "paper", "--model", "m.onnx"]) == 2
    assert "--model needs --detector" in capsys.readouterr().err
