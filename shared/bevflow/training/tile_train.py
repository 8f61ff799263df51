"""Fine-tune FastestDet's COCO weights on rendered rim tiles (``bevflow.training.tile_samples``).

The network keeps what it learnt from real photographs and learns our renders' people at the
tile input size (its box sizes are a share of the input, so a smaller input than its 352 px needs
them relearnt). Targets follow FastestDet's own scheme, so its pretrained heads start close: a
box is claimed by the (up to) four cells whose corner lies within one cell of its centre, the
better half of them by IoU are positives, their objectness target is that IoU, box loss is
1 − GIoU; cells under boxes marked ignore (people too hidden or cut) are left out of the
objectness loss. The class head and the first layers stay as COCO left them (``FROZEN``).

Renders alone teach the network our renders and make it forget real rooms: at 352 px, 400 to
1,200 steps on 1,920 tiles of 240 renders, the rendered frames under 5 m rose from AP50 0.78 to
0.87–0.90 while the real frames fell from 0.87 / AP50_rotated 0.85 to 0.36–0.39 (the head alone
trained: 0.81, and 0.71 / 0.74). Exported a quarter of the way from COCO's weights (``--share
0.25``, ``interpolated``) it keeps both: renders 0.86, the real frames turned ten ways as with
COCO's weights. That is the shipped tile model; the model card has its command.

    python -m bevflow.training.tile_train --data TILES --out RUN --steps 3000

Checkpoints (``RUN/checkpoint.pt``) are written every few minutes; running the same command
again resumes (or, once trained, only exports). ``--export FILE`` writes the ONNX model the
rim-tile detector loads, ``--share F`` the weights F of the way from COCO's to the fine-tuned.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np
import torch
from numpy.typing import NDArray

from bevflow.training.fastestdet import STRIDE, FastestDet, export_onnx, load_coco
from bevflow.training.tile_samples import read_tile_shards

FloatArray = NDArray[np.float64]
ZOOM_IN_SHARE = 0.5
# Kept as COCO learnt them: the class head, which tells people from chairs, bags and tables (our
# renders have few such things, and trained on people alone its softmax says "person"
# everywhere), and the first layers' edge and colour filters.
FROZEN = ("detect_head.cls_layers", "backbone.first_conv", "backbone.stage2")


@dataclass(frozen=True)
class TileTrainConfig:
    steps: int = 2500
    batch: int = 32
    lr: float = 2e-4
    weight_decay: float = 1e-4
    warmup: int = 100
    threads: int = 2
    seed: int = 0
    checkpoint_every_s: float = 180.0
    reload_every: int = 200


def tile_loss(output: torch.Tensor, boxes: list[torch.Tensor]) -> tuple[torch.Tensor, dict[str, float]]:
    """``output`` (B, 85, H, W) of FastestDet; ``boxes`` per image (N, 5): x0, y0, x1, y1 in input
    pixels and 1 where the box is to be ignored."""
    b, _, h, w = output.shape
    obj, reg = output[:, 0], output[:, 1:5]
    target = torch.zeros_like(obj)
    weight = torch.full_like(obj, 0.75)
    box_terms = []
    for i, bx in enumerate(boxes):
        _ignore_cells(weight[i], bx[bx[:, 4] > 0, :4])
        real = bx[bx[:, 4] == 0, :4] / STRIDE
        if len(real) == 0:
            continue
        cx, cy = (real[:, 0] + real[:, 2]) / 2, (real[:, 1] + real[:, 3]) / 2
        gi = torch.stack([cx.floor(), cx.floor() + 1, cx.floor(), cx.floor() + 1], 1).long()
        gj = torch.stack([cy.floor(), cy.floor(), cy.floor() + 1, cy.floor() + 1], 1).long()
        owner = torch.arange(len(real))[:, None].expand(-1, 4)
        inside = (gi >= 0) & (gi < w) & (gj >= 0) & (gj < h)
        gi, gj, owner = gi[inside], gj[inside], owner[inside]
        r = reg[i, :, gj, gi]
        pred = torch.stack([gi + torch.tanh(r[0]), gj + torch.tanh(r[1]), torch.sigmoid(r[2]) * w, torch.sigmoid(r[3]) * h], 1)
        truth = real[owner]
        truth_cxcywh = torch.stack([(truth[:, 0] + truth[:, 2]) / 2, (truth[:, 1] + truth[:, 3]) / 2, truth[:, 2] - truth[:, 0], truth[:, 3] - truth[:, 1]], 1)
        giou = _giou(pred, truth_cxcywh)
        best = giou > giou.mean()
        if not bool(best.any()):
            best = torch.ones_like(giou, dtype=torch.bool)
        gi, gj, giou = gi[best], gj[best], giou[best]
        box_terms.append(1 - giou)
        target[i, gj, gi] = giou.detach().clamp_min(0)
        weight[i, gj, gi] = 0.25 * h * w / max(1, len(gi))
    obj_loss = (torch.nn.functional.smooth_l1_loss(obj, target, reduction="none") * weight).mean()
    box_loss = torch.cat(box_terms).mean() if box_terms else obj.sum() * 0
    total = 8 * box_loss + 16 * obj_loss
    return total, {"box": float(box_loss.detach()), "obj": float(obj_loss.detach())}


def _ignore_cells(weight: torch.Tensor, ignored: torch.Tensor) -> None:
    """No objectness loss at cells (grid point i ↔ pixel i · stride) inside an ignored box."""
    for x0, y0, x1, y1 in (ignored / STRIDE).tolist():
        weight[max(0, math.ceil(y0)) : max(0, math.floor(y1) + 1), max(0, math.ceil(x0)) : max(0, math.floor(x1) + 1)] = 0


def _giou(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Generalised IoU of (N, 4) cx, cy, w, h boxes, row by row."""
    a0, a1 = a[:, :2] - a[:, 2:] / 2, a[:, :2] + a[:, 2:] / 2
    b0, b1 = b[:, :2] - b[:, 2:] / 2, b[:, :2] + b[:, 2:] / 2
    inter = (torch.min(a1, b1) - torch.max(a0, b0)).clamp_min(0).prod(1)
    union = a[:, 2:].prod(1) + b[:, 2:].prod(1) - inter + 1e-7
    hull = (torch.max(a1, b1) - torch.min(a0, b0)).prod(1) + 1e-7
    return inter / union - (hull - union) / hull


def zoom_in(rng: np.random.Generator, image: NDArray[np.uint8], boxes: FloatArray) -> tuple[NDArray[np.uint8], FloatArray]:
    """A random square part of a tile (half to all of it) enlarged back to the tile's size: people
    as large as a low ceiling over a high-resolution sensor shows them. People the crop cuts to
    under half their width or height are marked ignore."""
    n = image.shape[0]
    side = n * rng.uniform(0.5, 1.0)
    x0, y0 = rng.uniform(0, n - side), rng.uniform(0, n - side)
    k = n / side
    m = np.array([[k, 0.0, -k * x0], [0.0, k, -k * y0]])
    out = np.asarray(cv2.warpAffine(image, m, (n, n), flags=cv2.INTER_LINEAR), dtype=np.uint8)
    b = boxes.copy()
    b[:, [0, 2]] = (b[:, [0, 2]] - x0) * k
    b[:, [1, 3]] = (b[:, [1, 3]] - y0) * k
    clipped = np.clip(b[:, :4], -0.5, n - 0.5)
    kept = (clipped[:, 2] - clipped[:, 0] > 1) & (clipped[:, 3] - clipped[:, 1] > 1)
    share = np.minimum((clipped[:, 2] - clipped[:, 0]) / (b[:, 2] - b[:, 0]), (clipped[:, 3] - clipped[:, 1]) / (b[:, 3] - b[:, 1]))
    b[:, :4] = clipped
    b[:, 4] = np.where(share < 0.5, 1.0, b[:, 4])
    return out, b[kept]


class TileBatches:
    """Random batches from the tile shards, flipped left-right at random (tiles stay upright)."""

    def __init__(self, folder: Path, rng: np.random.Generator) -> None:
        self.folder, self.rng = folder, rng
        self.reload()

    def reload(self) -> None:
        self.images, self.boxes = read_tile_shards(self.folder)

    def batch(self, n: int) -> tuple[torch.Tensor, list[torch.Tensor]]:
        picks = self.rng.integers(0, len(self.images), n)
        images, boxes = [], []
        for i in picks:
            img, bx = self.images[i], self.boxes[i].copy()
            if self.rng.random() < ZOOM_IN_SHARE:
                img, bx = zoom_in(self.rng, img, bx)
            if self.rng.random() < 0.5:
                img = img[:, ::-1]
                bx[:, [0, 2]] = img.shape[1] - 1 - bx[:, [2, 0]]
            images.append(img)
            boxes.append(torch.from_numpy(bx).float())
        x = torch.from_numpy(np.ascontiguousarray(np.stack(images))).permute(0, 3, 1, 2).float() / 255.0
        return x, boxes


def train_tiles(data: Path, out: Path, weights: Path, config: TileTrainConfig, log: object = print) -> Path:
    """Fine-tune (or resume) into ``out/checkpoint.pt``; return its path."""
    torch.set_num_threads(config.threads)
    out.mkdir(parents=True, exist_ok=True)
    ckpt = out / "checkpoint.pt"
    rng = np.random.default_rng(config.seed)
    model = load_coco(weights)
    for part in FROZEN:
        model.get_submodule(part).requires_grad_(False)
    opt = torch.optim.AdamW([p for p in model.parameters() if p.requires_grad], lr=config.lr, weight_decay=config.weight_decay)
    step = 0
    if ckpt.exists():
        state = torch.load(ckpt, map_location="cpu", weights_only=False)
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["optimizer"])
        step, rng.bit_generator.state = state["step"], state["rng"]
    batches = TileBatches(data, rng)
    model.train()
    for part in FROZEN:  # their batch norms keep COCO's statistics too
        model.get_submodule(part).eval()
    last_save = time.monotonic()
    while step < config.steps:
        if step and step % config.reload_every == 0:
            batches.reload()
        lr = config.lr * min(1.0, (step + 1) / config.warmup) * 0.5 * (1 + math.cos(math.pi * step / config.steps))
        for group in opt.param_groups:
            group["lr"] = lr
        x, boxes = batches.batch(config.batch)
        loss, parts = tile_loss(model(x), boxes)
        opt.zero_grad()
        loss.backward()
        opt.step()
        step += 1
        if step % 25 == 0:
            print(f"step {step} loss {float(loss):.3f} " + " ".join(f"{k} {v:.3f}" for k, v in parts.items()) + f" lr {lr:.2e} tiles {len(batches.images)}", flush=True)
        if time.monotonic() - last_save > config.checkpoint_every_s or step == config.steps:
            _save(ckpt, model, opt, step, rng, config)
            last_save = time.monotonic()
    return ckpt


def _save(path: Path, model: FastestDet, opt: torch.optim.Optimizer, step: int, rng: np.random.Generator, config: TileTrainConfig) -> None:
    tmp = path.with_suffix(".tmp")
    torch.save({"model": model.state_dict(), "optimizer": opt.state_dict(), "step": step, "rng": rng.bit_generator.state,
                "config": asdict(config)}, tmp)  # fmt: skip
    tmp.replace(path)


def export_tiles(checkpoint: Path, out: Path, input_px: int, coco: Path | None = None, share: float = 1.0) -> Path:
    """The fine-tuned network as an ONNX file of fixed input ``input_px`` square (BGR / 255); with
    ``coco`` (FastestDet's COCO state dict), its weights are ``share`` × the fine-tuned ones plus
    the rest × COCO's (``interpolated``)."""
    state = torch.load(checkpoint, map_location="cpu", weights_only=False)["model"]
    if coco is not None:
        state = interpolated(state, torch.load(coco, map_location="cpu", weights_only=True), share)
    model = FastestDet()
    model.load_state_dict(state)
    return export_onnx(model, out, input_px)


def interpolated(fine_tuned: dict[str, torch.Tensor], start: dict[str, torch.Tensor], share: float) -> dict[str, torch.Tensor]:
    """``share`` of the way from ``start``'s weights to ``fine_tuned``'s, every floating-point
    tensor alike (batch-norm statistics included); counters are the fine-tuned ones. Fine-tuned
    weights learn the new images and forget the old; a point between them keeps much of both
    (Wortsman et al., "Robust fine-tuning of zero-shot models", CVPR 2022)."""
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"share must be within [0, 1], got {share}")
    if fine_tuned.keys() != start.keys():
        raise ValueError("the two state dicts hold different tensors")
    return {k: torch.lerp(start[k], v, share) if v.is_floating_point() else v for k, v in fine_tuned.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="fine-tune FastestDet on rendered rim tiles")
    parser.add_argument("--data", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--weights", type=Path, required=True, help="FastestDet's COCO state dict (.pth)")
    parser.add_argument("--steps", type=int, default=TileTrainConfig.steps)
    parser.add_argument("--batch", type=int, default=TileTrainConfig.batch)
    parser.add_argument("--lr", type=float, default=TileTrainConfig.lr)
    parser.add_argument("--warmup", type=int, default=TileTrainConfig.warmup, help="steps of rising learning rate")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--export", type=Path, help="write the ONNX model here after training")
    parser.add_argument("--input-px", type=int, default=256)
    parser.add_argument("--share", type=float, default=1.0,
                        help="with --export: the exported weights are this share of the way from --weights to the fine-tuned ones")  # fmt: skip
    args = parser.parse_args(argv)
    config = TileTrainConfig(steps=args.steps, batch=args.batch, lr=args.lr, warmup=args.warmup, threads=args.threads)
    ckpt = train_tiles(args.data, args.out, args.weights, config)
    if args.export:
        export_tiles(ckpt, args.export, args.input_px, args.weights if args.share < 1 else None, args.share)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
