"""A small fully-convolutional CenterNet-style person detector (about 0.5 M parameters).

Plain 3×3 convolutions with batch norm and ReLU (depthwise ones train slowly on a CPU), a
stride-16 encoder and a light top-down decoder back to stride 4, where three heads predict:

- ``heatmap``: the probability that a person's box centre falls in each cell;
- ``size``: the box width and height in input pixels (as log(size / 16), so people at every
  scale weigh the same in the loss);
- ``offset``: where the centre lies inside its cell (0–1), undoing the stride's rounding.

People are about 20 px across at the detector's input scale, 5 cells at stride 4, which is why
the encoder stops at stride 16: its receptive field covers a whole person and their
surroundings without the cost of deeper stages. ``DetectorExport`` wraps the network for ONNX:
it takes the BGR image as float 0–255 and returns the sigmoid heatmap with non-peaks zeroed (a
3×3 max-pool), sizes in pixels and offsets, so the runtime only thresholds.
"""

from __future__ import annotations

import torch
from torch import nn

STRIDE = 4
SIZE_REFERENCE_PX = 16.0


def _conv(cin: int, cout: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


class CenterNetSmall(nn.Module):
    def __init__(self, widths: tuple[int, int, int, int] = (16, 32, 64, 112), head: int = 32) -> None:
        super().__init__()
        w0, w1, w2, w3 = widths
        self.stem = nn.Sequential(_conv(3, w0, 2), _conv(w0, w1, 2), _conv(w1, w1))  # stride 4
        self.down8 = nn.Sequential(_conv(w1, w2, 2), _conv(w2, w2), _conv(w2, w2))
        self.down16 = nn.Sequential(_conv(w2, w3, 2), _conv(w3, w3), _conv(w3, w3))
        self.lateral8 = nn.Conv2d(w2, w3, 1)
        self.fuse8 = _conv(w3, w2)
        self.reduce8 = nn.Conv2d(w2, head, 1)
        self.lateral4 = nn.Conv2d(w1, head, 1)
        self.fuse4 = _conv(head, head)
        # The stride-4 maps are the costly ones: keep them thin and share one 3x3 layer.
        self.shared = nn.Sequential(nn.Conv2d(head, head, 3, 1, 1), nn.ReLU(inplace=True))
        self.heatmap = nn.Conv2d(head, 1, 1)
        self.size = nn.Conv2d(head, 2, 1)
        self.offset = nn.Conv2d(head, 2, 1)
        self.heatmap.bias.data.fill_(-2.19)  # start near p = 0.1, as CenterNet does

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """x: (B, 3, H, W) normalised; H, W multiples of 16. Returns raw heatmap logits,
        log-size and offset, each at stride 4."""
        f4 = self.stem(x)
        f8 = self.down8(f4)
        f16 = self.down16(f8)
        up8 = self.fuse8(self.lateral8(f8) + nn.functional.interpolate(f16, scale_factor=2.0, mode="nearest"))
        up4 = self.fuse4(self.lateral4(f4) + nn.functional.interpolate(self.reduce8(up8), scale_factor=2.0, mode="nearest"))
        h = self.shared(up4)
        return self.heatmap(h), self.size(h), self.offset(h)


def normalise(bgr: torch.Tensor) -> torch.Tensor:
    """BGR float 0–255 → the network's input range."""
    return (bgr - 110.0) / 60.0


class DetectorExport(nn.Module):
    """The network with its pre- and post-processing, as shipped in ONNX."""

    def __init__(self, net: CenterNetSmall) -> None:
        super().__init__()
        self.net = net

    def forward(self, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        logits, log_size, offset = self.net(normalise(image))
        heat = torch.sigmoid(logits)
        peaks = nn.functional.max_pool2d(heat, 3, 1, 1)
        heat = heat * (heat >= peaks).to(heat.dtype)
        return heat, SIZE_REFERENCE_PX * torch.exp(log_size), offset


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
