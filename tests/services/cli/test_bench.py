from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import pytest

from bevflow_services.benchmarks import suite
from bevflow_services.benchmarks.suite import HEADLINE_KEYS, Settings
from bevflow_services.cli import bench
from bevflow_services.runtime import UserError

# Settings small enough for a test: the point is the command's output, never its speed.
TINY = Settings(cylinder_boxes=(5, 50), cylinder_repeats=1, cylinder_reference_repeats=1, cylinder_reference_max_boxes=5,
                tracking_people=(10,), tracking_cameras=(4,), tracking_ticks=2, tracking_warmup=3, detector_repeats=1)


def run_bench(argv: list[str]) -> int:
    """``bevflow bench ARGV`` through the subcommand's own parser."""
    parser = argparse.ArgumentParser(prog="bevflow")
    bench.register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["bench", *argv])
    return args.func(args)


@pytest.fixture
def tiny_quick(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(suite, "QUICK", TINY)
    # No model file: the detector part must say why it has no number rather than make one up.
    monkeypatch.setattr("bevflow_services.benchmarks.detector.default_model", lambda: Path("/nonexistent/model.onnx"))


def test_quick_run_prints_and_writes_every_headline_key(tiny_quick: None, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out, page = tmp_path / "bench.json", tmp_path / "BENCHMARKS.md"
    rc = run_bench(["--quick", "--skip", "live", "gateway", "bus", "--json", str(out), "--markdown", str(page), "--note", "shared machine"])
    assert rc == 0
    result = json.loads(out.read_text())  # strict JSON: NaN would not parse back as a number
    for key in HEADLINE_KEYS:
        value = result[key]
        if value is None:
            assert result["null_reasons"][key], key
        else:
            assert isinstance(value, (int, float)) and math.isfinite(value), key
    for key in ("cylinder_batched_ms_per_box", "cylinder_reference_ms_per_box", "cylinder_max_disagreement_m",
                "tracking_ms_per_tick_1000_people_64_cameras"):
        assert key in result
    assert isinstance(result["cylinder_batched_ms_per_box"], float) and result["cylinder_max_disagreement_m"] < 0.01
    assert result["tracking_ms_per_tick_1000_people_64_cameras"] is None  # not among the tiny settings' cases
    assert result["detector_ms_per_frame_3_3m_2_threads"] is None
    assert result["null_reasons"]["detector_ms_per_frame_3_3m_2_threads"] in ("no detector model shipped", "onnxruntime is not installed")
    assert result["null_reasons"]["gateway_rest_p99_ms"] == "the gateway part was not run"
    assert result["machine"]["cpus"] >= 1 and result["settings"]["tracking_ticks"] == 2
    printed = capsys.readouterr().out
    assert "headline numbers:" in printed and "cylinder_batched_ms_per_box" in printed and f"wrote {out}" in printed
    assert "- shared machine" in page.read_text()
    assert result["command"] == f"bevflow bench --quick --skip live gateway bus --markdown {page} --note 'shared machine'"
    assert result["command"] in page.read_text()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--only", "cylinder", "--skip", "cylinder"], "no part to run"),
        (["--detector-model", "/nonexistent/model.onnx"], "--detector-model"),
        (["--json", "/nonexistent/folder/out.json"], "does not exist"),
    ],
)
def test_usage_errors(argv: list[str], message: str) -> None:
    with pytest.raises(UserError, match=message):
        run_bench(argv)


def test_an_unknown_part_is_refused_by_the_parser(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exit_info:
        run_bench(["--only", "everything"])
    assert exit_info.value.code == 2 and "invalid choice" in capsys.readouterr().err


def test_a_failed_part_makes_the_exit_status_1(tiny_quick: None, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(suite, "run_bus", lambda s: 1 / 0)
    assert run_bench(["--quick", "--only", "bus"]) == 1
