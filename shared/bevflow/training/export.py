"""Export a trained checkpoint to one self-contained ONNX file (weights inside, dynamic batch,
height and width), the file ``bevflow.detect.runtime.Detector`` loads."""

from __future__ import annotations

from pathlib import Path

import torch

from bevflow.training.model import CenterNetSmall, DetectorExport

OUTPUT_NAMES = ["heatmap", "size", "offset"]


def load_checkpoint(path: Path) -> CenterNetSmall:
    state = torch.load(Path(path), map_location="cpu", weights_only=False)
    model = CenterNetSmall()
    model.load_state_dict(state["model"] if "model" in state else state)
    return model.eval()


def export_onnx(model: CenterNetSmall, out: Path, opset: int = 18) -> Path:
    """Write ``model`` (with pre- and post-processing) to ``out``; weights are embedded."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    wrapper = DetectorExport(model.eval()).eval()
    example = torch.zeros(1, 3, 256, 256)
    batch, height, width = torch.export.Dim("batch", min=1, max=64), torch.export.Dim("h32", min=1, max=128), torch.export.Dim("w32", min=1, max=128)
    with torch.no_grad():
        torch.onnx.export(
            wrapper, (example,), str(out), input_names=["image"], output_names=OUTPUT_NAMES, opset_version=opset,
            dynamic_shapes={"image": {0: batch, 2: 32 * height, 3: 32 * width}}, external_data=False, dynamo=True,
        )  # fmt: skip
    return out
