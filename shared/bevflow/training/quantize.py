"""An INT8 copy of a detector file: ONNX Runtime's static quantisation, calibrated on frames.

``quantize_detector(model, frames, out)`` feeds each frame to the model as ``Detector`` would
(resized to its camera's height-adaptive scale, from the COCO file's ``camera_height_m`` and
``focal_px``), records the range of every activation, and writes the model with 8-bit weights
(per output channel, signed) and activations (unsigned) as QuantizeLinear / DequantizeLinear
pairs around each convolution. The input scale in the file's metadata (``bevflow.zoom``) is
carried over, so ``Detector`` resizes frames for the copy as for the original.

Calibrate on renders that are not the held-out evaluation set (``bevflow train-detector
render-eval`` with another seed). Whether the copy is faster depends on the CPU: ONNX Runtime's
integer convolutions gain where the CPU has dot-product instructions for 8-bit integers (VNNI);
``bevflow bench`` times both on the machine that will run them.

Needs the ``onnx`` package (the ``train`` extra).
"""

from __future__ import annotations

import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from bevflow.detect.coco import CocoImage
from bevflow.detect.runtime import Detector


def calibration_tensors(detector: Detector, frames: Sequence[CocoImage]) -> Iterator[NDArray[np.float32]]:
    """Each frame as the model's input tensor, at its camera's scale (scale 1 without one)."""
    import cv2

    for frame in frames:
        image = cv2.imread(str(frame.path))
        if image is None:
            raise ValueError(f"{frame.path}: not an image OpenCV can read")
        scale = 1.0
        if frame.camera_height_m is not None and frame.focal_px is not None:
            scale = detector.scale_for(frame.camera_height_m, frame.focal_px)
        yield detector.prepare(np.asarray(image, dtype=np.uint8), scale).tensor


def quantize_detector(model: Path, frames: Sequence[CocoImage], out: Path) -> Path:
    """Write ``model`` quantised to INT8 to ``out``, calibrated on ``frames`` (module docstring)."""
    import onnx
    from onnxruntime.quantization import CalibrationDataReader, CalibrationMethod, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    if not frames:
        raise ValueError("calibration needs at least one frame")
    detector = Detector(model, threads=1)
    input_name = detector.session.get_inputs()[0].name

    class Frames(CalibrationDataReader):  # type: ignore[misc]  # onnxruntime ships no type hints
        def __init__(self) -> None:
            self.tensors = calibration_tensors(detector, frames)

        def get_next(self) -> dict[str, NDArray[np.float32]] | None:
            tensor = next(self.tensors, None)
            return None if tensor is None else {input_name: tensor}

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as scratch:
        prepared = Path(scratch) / "prepared.onnx"
        # The input's height and width are free: symbolic shape inference cannot settle them.
        quant_pre_process(str(model), str(prepared), skip_symbolic_shape=True)
        quantize_static(str(prepared), str(out), Frames(), quant_format=QuantFormat.QDQ, per_channel=True,
                        activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
                        calibrate_method=CalibrationMethod.MinMax)  # fmt: skip
    source, written = onnx.load(str(model)), onnx.load(str(out))
    onnx.helper.set_model_props(written, {p.key: p.value for p in source.metadata_props})
    onnx.save(written, str(out))
    return out
