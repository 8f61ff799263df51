"""FastestDet as a trainable module: shapes at any input size, its channel split, and a loss that
rewards a box at the right place."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from bevflow.detect.decoders import decode_fastestdet  # noqa: E402
from bevflow.training.fastestdet import FastestDet, ShuffleBlock  # noqa: E402
from bevflow.training.tile_train import interpolated, tile_loss  # noqa: E402


@pytest.mark.parametrize("size", [(64, 64), (96, 160)])
def test_output_grid_is_a_sixteenth_of_the_input(size: tuple[int, int]) -> None:
    with torch.no_grad():
        out = FastestDet().eval()(torch.zeros(2, 3, *size))
    assert out.shape == (2, 85, size[0] // 16, size[1] // 16)
    assert torch.allclose(out[:, 5:].sum(1), torch.ones(1))  # class scores are a softmax


def test_a_stride_one_block_passes_its_even_channels_through() -> None:
    block = ShuffleBlock(8, 16, stride=1).eval()
    x = torch.randn(1, 16, 4, 4)
    with torch.no_grad():
        y = block(x)
    assert torch.equal(y[:, :8], x[:, 0::2])


def test_the_loss_prefers_the_true_box_and_decodes_to_it() -> None:
    h = w = 4
    truth = torch.tensor([[20.0, 12.0, 36.0, 44.0, 0.0]])  # centre (28, 28) px: cells 1–2
    good = torch.zeros(1, 85, h, w)
    good[:, 5] = 1.0  # person
    cx, cy = 28 / 16, 28 / 16
    for gi in (1, 2):
        for gj in (1, 2):
            good[0, 1, gj, gi], good[0, 2, gj, gi] = float(np.arctanh(cx - gi)), float(np.arctanh(cy - gj))
            good[0, 3, gj, gi], good[0, 4, gj, gi] = float(np.log(16 / 48)), float(np.log(32 / 32))  # w 16/64, h 32/64
            good[0, 0, gj, gi] = 1.0
    bad = good.clone()
    bad[0, 1:5] = 0.0  # boxes at the cells' corners, half the input across
    assert float(tile_loss(good, [truth])[0]) < float(tile_loss(bad, [truth])[0])
    xyxy, scores = decode_fastestdet(good[0].numpy(), (64, 64), 0.5)
    assert len(xyxy) == 4 and np.allclose(xyxy, [20, 12, 36, 44], atol=1e-3) and np.allclose(scores, 1.0)


@pytest.mark.parametrize(
    ("share", "weight", "counter"),
    [
        (0.0, 1.0, 7),  # all the start's weights; counters always the fine-tuned ones
        (0.25, 1.75, 7),
        (1.0, 4.0, 7),
    ],
)
def test_interpolated_weights_lie_between_the_start_and_the_fine_tuned(share: float, weight: float, counter: int) -> None:
    start = {"w": torch.ones(2), "n": torch.tensor(3)}
    tuned = {"w": torch.full((2,), 4.0), "n": torch.tensor(7)}
    got = interpolated(tuned, start, share)
    assert torch.allclose(got["w"], torch.full((2,), weight)) and int(got["n"]) == counter


@pytest.mark.parametrize(
    ("tuned", "share", "message"),
    [
        ({"w": torch.ones(2)}, 1.5, "within"),
        ({"v": torch.ones(2)}, 0.5, "different tensors"),
    ],
)
def test_interpolated_refuses(tuned: dict, share: float, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        interpolated(tuned, {"w": torch.zeros(2)}, share)
