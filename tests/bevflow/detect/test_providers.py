"""Execution providers: the requested order, what the installed build offers, the CPU last."""

from __future__ import annotations

import logging

import onnxruntime
import pytest

from bevflow.detect import runtime
from bevflow.detect.providers import plan_providers
from bevflow.detect.runtime import Detector

CPU, CUDA, TRT, OV = "CPUExecutionProvider", "CUDAExecutionProvider", "TensorrtExecutionProvider", "OpenVINOExecutionProvider"


@pytest.mark.parametrize(
    ("requested", "available", "use", "unavailable"),
    [
        (["cpu"], [CPU], [CPU], []),
        (["cuda", "cpu"], [CUDA, CPU], [CUDA, CPU], []),
        (["tensorrt", "cuda"], [TRT, CUDA, CPU], [TRT, CUDA, CPU], []),
        (["cuda", "cpu"], [CPU], [CPU], ["cuda"]),
        (["openvino"], [CPU], [CPU], ["openvino"]),
        (["OpenVINO", " cpu "], [OV, CPU], [OV, CPU], []),
        (["cpu", "cuda"], [CUDA, CPU], [CUDA, CPU], []),  # the CPU is always the last resort
    ],
)
def test_plan(requested: list[str], available: list[str], use: list[str], unavailable: list[str]) -> None:
    plan = plan_providers(requested, available)
    assert (plan.use, plan.unavailable) == (use, unavailable)


@pytest.mark.parametrize("requested", [["gpu"], [], ["cuda", "tpu"], [" "]])
def test_unknown_or_no_provider_is_refused_naming_the_choices(requested: list[str]) -> None:
    with pytest.raises(ValueError, match="tensorrt, cuda, openvino, cpu"):
        plan_providers(requested, [CPU])


@pytest.mark.skipif(CUDA in onnxruntime.get_available_providers(), reason="this machine has the CUDA build")
def test_a_missing_accelerator_falls_back_to_the_cpu_with_a_warning(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="bevflow.detect.runtime"):
        detector = Detector(providers=["cuda", "cpu"])
    assert detector.providers == [CPU]
    assert any("not available in this onnxruntime build: cuda" in m for m in caplog.messages)


def test_an_offered_accelerator_that_does_not_load_is_reported(monkeypatch: pytest.MonkeyPatch,
                                                               caplog: pytest.LogCaptureFixture) -> None:
    """onnxruntime-gpu without the driver or CUDA's libraries: the build offers CUDA, the session
    falls back to the CPU on its own, and the log says so (checked with the real build too)."""
    real = onnxruntime.InferenceSession
    preloaded: list[bool] = []
    monkeypatch.setattr(onnxruntime, "get_available_providers", lambda: [TRT, CUDA, CPU])
    monkeypatch.setattr(onnxruntime, "InferenceSession", lambda path, options, providers: real(path, options, providers=[CPU]))
    monkeypatch.setattr(onnxruntime, "preload_dlls", lambda: preloaded.append(True), raising=False)
    runtime._preload_cuda_libraries.cache_clear()
    with caplog.at_level(logging.WARNING, logger="bevflow.detect.runtime"):
        detector = Detector(providers=["tensorrt", "cuda", "cpu"])
    runtime._preload_cuda_libraries.cache_clear()
    assert detector.providers == [CPU] and preloaded == [True]
    assert any("tensorrt, cuda offered by this onnxruntime build but did not load" in m and m.endswith("runs on " + CPU)
               for m in caplog.messages)


def test_the_cpu_alone_loads_no_cuda_libraries(monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    preloaded: list[bool] = []
    monkeypatch.setattr(onnxruntime, "preload_dlls", lambda: preloaded.append(True), raising=False)
    runtime._preload_cuda_libraries.cache_clear()
    with caplog.at_level(logging.WARNING, logger="bevflow.detect.runtime"):
        Detector(providers=["cpu"])
    assert preloaded == [] and not caplog.messages


def test_the_list_reaches_the_session(monkeypatch: pytest.MonkeyPatch) -> None:
    asked: list[list[str]] = []
    real = onnxruntime.InferenceSession

    def recording(path: str, options: object, providers: list[str]) -> object:
        asked.append(providers)
        return real(path, options, providers=[CPU])

    monkeypatch.setattr(onnxruntime, "get_available_providers", lambda: [OV, CPU])
    monkeypatch.setattr(onnxruntime, "InferenceSession", recording)
    Detector(providers=["openvino", "cpu"])
    assert asked == [[OV, CPU]]
