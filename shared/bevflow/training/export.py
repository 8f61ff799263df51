"""Export a trained checkpoint to one self-contained ONNX file (weights inside, dynamic batch,
height and width), the file ``bevflow.detect.runtime.Detector`` loads, and read such a file back
into a trainable model (to fine-tune the shipped detector on a site's own frames).

The exporter folds every batch norm into its convolution, so the file holds one weight and one
bias per convolution. Reading it back, each batch norm is rebuilt to compute exactly what the
file computes in eval mode, with its running statistics set to those the folded convolution
produces on a calibration batch: in train mode its batch statistics then start near its
running ones, and the first steps of fine-tuning do not jolt the network.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import torch
from torch import nn

from bevflow.detect.runtime import ZOOM_METADATA_KEY
from bevflow.training.model import CenterNetSmall, DetectorExport

OUTPUT_NAMES = ["heatmap", "size", "offset"]


def load_checkpoint(path: Path) -> tuple[CenterNetSmall, float]:
    """The trained network and the input scale it learnt (``TrainConfig.zoom``; 1 for
    checkpoints older than it)."""
    state = torch.load(Path(path), map_location="cpu", weights_only=False)
    model = CenterNetSmall()
    model.load_state_dict(state["model"] if "model" in state else state)
    return model.eval(), float(state.get("config", {}).get("zoom", 1.0))


def export_onnx(model: CenterNetSmall, out: Path, opset: int = 18, zoom: float = 1.0) -> Path:
    """Write ``model`` (with pre- and post-processing) to ``out``; weights are embedded, and the
    input scale it learnt is in the metadata (``ZOOM_METADATA_KEY``, which ``Detector`` reads)."""
    import onnx

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
    proto = onnx.load(str(out))
    onnx.helper.set_model_props(proto, {ZOOM_METADATA_KEY: f"{zoom:g}"})
    onnx.save(proto, str(out))
    return out


def model_from_onnx(path: Path, calibration: torch.Tensor) -> CenterNetSmall:
    """The network inside an exported file, as a trainable ``CenterNetSmall`` whose eval-mode
    output equals the file's. ``calibration``: a normalised batch (B, 3, H, W) of typical inputs."""
    import onnx
    from onnx import numpy_helper

    weights = {i.name.removeprefix("net."): torch.from_numpy(numpy_helper.to_array(i).copy())
               for i in onnx.load(str(path)).graph.initializer if i.name.startswith("net.")}  # fmt: skip
    model = CenterNetSmall()
    model.eval()
    norms: dict[str, nn.BatchNorm2d] = {}
    with torch.no_grad():
        for name, module in model.named_modules():
            if isinstance(module, nn.Conv2d):
                module.weight.copy_(weights.pop(f"{name}.weight"))
                bias = weights.pop(f"{name}.bias", None)
                if bias is not None:
                    module.bias.copy_(bias)
            elif isinstance(module, nn.BatchNorm2d):
                conv = name.rsplit(".", 1)[0] + ".0"
                module.weight.fill_(1.0)
                module.bias.copy_(weights.pop(f"{conv}.weight_bias"))
                module.running_mean.zero_()
                module.running_var.fill_(1.0 - module.eps)
                norms[name] = module
    if weights:
        raise ValueError(f"{path}: weights the model has no place for: {sorted(weights)}")
    _calibrate(model, norms, calibration)
    return model


def _calibrate(model: CenterNetSmall, norms: dict[str, nn.BatchNorm2d], batch: torch.Tensor) -> None:
    stats: dict[str, tuple[torch.Tensor, torch.Tensor]] = {}

    def keep(name: str) -> Callable[[nn.Module, tuple[torch.Tensor, ...], torch.Tensor], None]:
        def record(_module: nn.Module, inputs: tuple[torch.Tensor, ...], _output: torch.Tensor) -> None:
            stats[name] = (inputs[0].mean((0, 2, 3)), inputs[0].var((0, 2, 3)))

        return record

    hooks = [norm.register_forward_hook(keep(name)) for name, norm in norms.items()]
    with torch.no_grad():
        model(batch)
        for hook in hooks:
            hook.remove()
        for name, norm in norms.items():
            mean, var = stats[name]
            std = torch.sqrt(var.clamp_min(10 * norm.eps))
            norm.bias.add_(mean)  # the folded conv's output is gamma·(x − mean)/std + mean + bias
            norm.weight.copy_(std)
            norm.running_mean.copy_(mean)
            norm.running_var.copy_(std**2 - norm.eps)

