"""``bevflow train-detector render`` and ``quantize``: options checked before anything is written."""

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
