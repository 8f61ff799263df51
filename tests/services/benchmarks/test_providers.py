"""The providers benchmark: every case on every list, the CPU first, what loaded reported."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest

from bevflow.detections import Boxes

from bevflow_services.benchmarks import providers as providers_bench
from bevflow_services.benchmarks.providers import CASES, bench_accelerators, bench_providers, loaded_providers

CPU, CUDA, OV = "CPUExecutionProvider", "CUDAExecutionProvider", "OpenVINOExecutionProvider"


class StandIn:
    """A detector whose session ran on ``providers``; counts its calls."""

    def __init__(self, providers: Sequence[str]) -> None:
        self.providers = list(providers)
        self.calls = 0

    def detect(self, image: np.ndarray, height: float, focal: float) -> Boxes:
        self.calls += 1
        return Boxes(xyxy=np.zeros((0, 4)))


@pytest.fixture(autouse=True)
def small_frames(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(providers_bench, "frame_for", lambda h: (np.zeros((64, 64, 3), np.uint8), 20.0))
    monkeypatch.setattr(providers_bench, "camera_sized", lambda detector, frame, focal: (frame, focal))


@pytest.mark.parametrize(
    ("candidates", "lists"),
    [
        ([["openvino", "cpu"]], ["cpu", "openvino,cpu"]),
        ([["CUDA", " cpu"], ["tensorrt", "cuda"]], ["cpu", "cuda,cpu", "tensorrt,cuda"]),
        ([["cpu"]], ["cpu"]),  # the baseline is timed once
        ([["openvino"], ["OpenVINO"]], ["cpu", "openvino"]),  # a list given twice is timed once
        ([], ["cpu"]),
    ],
)
def test_every_case_is_timed_on_every_list_the_cpu_first(candidates: list[list[str]], lists: list[str]) -> None:
    made: list[StandIn] = []

    def make(case: str, names: Sequence[str], threads: int) -> StandIn:
        # an accelerator that "did not load" runs on the CPU, as ONNX Runtime falls back
        made.append(StandIn([CPU] if "cuda" in names else [f"{names[0]} session"]))
        return made[-1]

    rows = bench_providers(candidates, threads=2, rounds=2, calls=3, make=make)  # type: ignore[arg-type]
    assert [(r["case"], r["height_m"]) for r in rows] == list(CASES)
    for row in rows:
        assert list(row["ms_p50"]) == lists and all(ms >= 0 for ms in row["ms_p50"].values())
        assert list(row["loaded"]) == lists
    assert all(d.calls == 1 + 2 * 3 for d in made)  # a warm-up, then every round's calls
    if "cuda,cpu" in lists:
        assert rows[0]["loaded"]["cuda,cpu"] == [CPU]


def test_an_unknown_provider_is_refused_before_anything_loads() -> None:
    with pytest.raises(ValueError, match="choose from tensorrt, cuda, openvino, cpu"):
        bench_providers([["gpu"]], make=lambda *a: pytest.fail("nothing may load"))


def test_a_rim_tile_detector_reports_its_tiles_providers() -> None:
    class Tiles:
        tile_detector = StandIn(["OpenVINOExecutionProvider", "CPUExecutionProvider"])

    assert loaded_providers(Tiles()) == ["OpenVINOExecutionProvider", "CPUExecutionProvider"]  # type: ignore[arg-type]
    assert loaded_providers(StandIn(["CPUExecutionProvider"])) == ["CPUExecutionProvider"]  # type: ignore[arg-type]


def _loading(works: set[str]):  # noqa: ANN202
    """A maker whose sessions load the accelerators in ``works`` and fall back to the CPU otherwise."""
    def make(case: str, names: Sequence[str], threads: int) -> StandIn:
        full = {"cuda": CUDA, "openvino": OV, "tensorrt": "TensorrtExecutionProvider"}
        return StandIn([full[names[0]], CPU] if names[0] in works else [CPU])
    return make


@pytest.mark.parametrize(
    ("available", "works", "reason"),
    [
        ([CPU], set(), "offers no accelerator"),
        (["AzureExecutionProvider", CPU], set(), "offers no accelerator"),
        ([CUDA, CPU], set(), "cuda offered by this onnxruntime build but not loaded"),
    ],
)
def test_no_accelerator_timed_says_why(available: list[str], works: set[str], reason: str) -> None:
    result = bench_accelerators(available, rounds=1, calls=1, make=_loading(works))  # type: ignore[arg-type]
    assert not result["available"] and reason in result["reason"] and "speedup" not in result


@pytest.mark.parametrize(("available", "works", "timed"), [([CUDA, CPU], {"cuda"}, ["cpu", "cuda,cpu"]),
                                                           ([OV, CUDA, CPU], {"openvino"}, ["cpu", "cuda,cpu", "openvino,cpu"])])
def test_an_accelerator_that_loaded_gets_a_speedup(monkeypatch: pytest.MonkeyPatch, available: list[str], works: set[str],
                                                   timed: list[str]) -> None:
    # every list that is not the CPU alone takes 8 ms where the CPU takes 20
    monkeypatch.setattr(providers_bench, "alternately", lambda detectors, *a: {k: 20.0 if k == "cpu" else 8.0 for k in detectors})
    result = bench_accelerators(available, rounds=1, calls=2, make=_loading(works))  # type: ignore[arg-type]
    assert result["available"] and result["best"] == f"{next(iter(works))},cpu"
    assert [list(r["ms_p50"]) for r in result["rows"]] == [timed] * len(CASES)
    assert result["speedup"] == 2.5  # only from a list whose accelerator loaded
