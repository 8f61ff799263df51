"""FastestDet as a trainable PyTorch module, to fine-tune its real-photograph features on our
renders.

FastestDet (BSD-3-Clause, dog-qiuqiu/FastestDet; notice in the model card) is a 0.24 M-parameter
single-scale detector: a ShuffleNetV2 backbone (stages of 4, 8 and 4 blocks, 48/96/192 channels),
its three stages pooled, concatenated and mixed at stride 16 by a block of depthwise 5×5
convolutions, and three heads per cell: objectness (sigmoid), box (centre offset in cells through
tanh, width and height as a share of the input through a sigmoid) and class (softmax over 80 COCO
classes; person is 0). ``bevflow.detect.decoders.decode_fastestdet`` reads its output.

The module's attribute names follow the published state dict, so its COCO weights load as they
are (``load_coco``). Its channel shuffle splits even and odd channels, which is what the
published reshape computes, written so that the input size stays free.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

STAGES = ((4, 48), (8, 96), (4, 192))
STEM = 24
CLASSES = 80
STRIDE = 16


def _bn_relu(channels: int) -> list[nn.Module]:
    return [nn.BatchNorm2d(channels), nn.ReLU(inplace=True)]


def _depthwise(channels: int, kernel: int, stride: int = 1) -> nn.Conv2d:
    return nn.Conv2d(channels, channels, kernel, stride, kernel // 2, groups=channels, bias=False)


def _pointwise(cin: int, cout: int) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, 1, 1, 0, bias=False)


class ShuffleBlock(nn.Module):
    """A ShuffleNetV2 unit. Stride 2 halves the map and runs both branches on the whole input;
    stride 1 passes the even channels through and transforms the odd ones."""

    def __init__(self, cin: int, cout: int, stride: int) -> None:
        super().__init__()
        self.stride, mid, out = stride, cout // 2, cout - cin
        self.branch_main = nn.Sequential(
            _pointwise(cin, mid), *_bn_relu(mid), _depthwise(mid, 3, stride), nn.BatchNorm2d(mid),
            _pointwise(mid, out), *_bn_relu(out),
        )  # fmt: skip
        self.branch_proj = (
            nn.Sequential(_depthwise(cin, 3, 2), nn.BatchNorm2d(cin), _pointwise(cin, cin), *_bn_relu(cin)) if stride == 2 else None
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.branch_proj is not None:
            return torch.cat((self.branch_proj(x), self.branch_main(x)), 1)
        return torch.cat((x[:, 0::2], self.branch_main(x[:, 1::2])), 1)


class Backbone(nn.Module):
    def __init__(self) -> None:
        super().__init__()
        self.first_conv = nn.Sequential(nn.Conv2d(3, STEM, 3, 2, 1, bias=False), *_bn_relu(STEM))
        self.maxpool = nn.MaxPool2d(3, 2, 1)
        cin = STEM
        for name, (repeats, cout) in zip(("stage2", "stage3", "stage4"), STAGES, strict=True):
            blocks = [ShuffleBlock(cin, cout, 2)] + [ShuffleBlock(cout // 2, cout, 1) for _ in range(repeats - 1)]
            setattr(self, name, nn.Sequential(*blocks))
            cin = cout

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        p1 = self.stage2(self.maxpool(self.first_conv(x)))
        p2 = self.stage3(p1)
        return p1, p2, self.stage4(p2)


class Conv1x1(nn.Module):
    def __init__(self, cin: int, cout: int) -> None:
        super().__init__()
        self.conv1x1 = nn.Sequential(_pointwise(cin, cout), *_bn_relu(cout))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv1x1(x)


class Mixer(nn.Module):
    """Three stacks of one, two and three depthwise 5×5 convolutions side by side (receptive
    fields of growing size), merged back with a residual."""

    def __init__(self, cin: int, channels: int) -> None:
        super().__init__()
        self.Conv1x1 = Conv1x1(cin, channels)
        for depth in (1, 2, 3):
            layers: list[nn.Module] = []
            for _ in range(depth):
                layers += [_depthwise(channels, 5), *_bn_relu(channels)]
            setattr(self, f"S{depth}", nn.Sequential(*layers))
        self.output = nn.Sequential(_pointwise(3 * channels, channels), nn.BatchNorm2d(channels))
        self.relu = nn.ReLU(inplace=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.Conv1x1(x)
        return self.relu(x + self.output(torch.cat((self.S1(x), self.S2(x), self.S3(x)), 1)))


class Head(nn.Module):
    def __init__(self, channels: int, outputs: int) -> None:
        super().__init__()
        self.conv5x5 = nn.Sequential(_depthwise(channels, 5), *_bn_relu(channels), _pointwise(channels, outputs), nn.BatchNorm2d(outputs))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv5x5(x)


class DetectHead(nn.Module):
    def __init__(self, channels: int, classes: int) -> None:
        super().__init__()
        self.conv1x1 = Conv1x1(channels, channels)
        self.obj_layers, self.reg_layers, self.cls_layers = Head(channels, 1), Head(channels, 4), Head(channels, classes)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.conv1x1(x)
        return torch.cat((torch.sigmoid(self.obj_layers(x)), self.reg_layers(x), torch.softmax(self.cls_layers(x), 1)), 1)


class FastestDet(nn.Module):
    """Input (B, 3, H, W): BGR / 255, H and W multiples of 32. Output (B, 5 + 80, H/16, W/16)."""

    def __init__(self) -> None:
        super().__init__()
        self.backbone = Backbone()
        self.upsample = nn.Upsample(scale_factor=2, mode="nearest")
        self.avg_pool = nn.AvgPool2d(3, 2, 1)
        self.SPP = Mixer(sum(c for _, c in STAGES), STAGES[1][1])
        self.detect_head = DetectHead(STAGES[1][1], CLASSES)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        p1, p2, p3 = self.backbone(x)
        return self.detect_head(self.SPP(torch.cat((self.avg_pool(p1), p2, self.upsample(p3)), 1)))


def load_coco(weights: Path) -> FastestDet:
    """FastestDet with its published COCO weights (the ``.pth`` state dict)."""
    model = FastestDet()
    model.load_state_dict(torch.load(Path(weights), map_location="cpu", weights_only=True))
    return model


def export_onnx(model: FastestDet, out: Path, input_px: int) -> Path:
    """``model`` as an ONNX file of a fixed ``input_px`` square input and a free batch size (the
    rim-tile detector runs all of a frame's tiles in one call)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    with torch.no_grad():
        torch.onnx.export(model.eval(), (torch.zeros(1, 3, input_px, input_px),), str(out), input_names=["images"],
                          output_names=["output"], opset_version=18, external_data=False, dynamo=False,
                          dynamic_axes={"images": {0: "batch"}, "output": {0: "batch"}})  # fmt: skip
    return out


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description="write FastestDet's COCO weights as the rim-tile model")
    parser.add_argument("--weights", type=Path, required=True, help="the published state dict (.pth)")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--input-px", type=int, default=352, help="the input it was trained at (default 352)")
    args = parser.parse_args()
    export_onnx(load_coco(args.weights), args.out, args.input_px)
