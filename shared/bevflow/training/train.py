"""A resumable training loop for ``CenterNetSmall`` on rendered shards.

Training can span several sittings on a 2-core CPU: every ``checkpoint_every_s`` seconds (and at
the end) the model, optimiser, step and random state are written atomically to
``<out>/checkpoint.pt``; starting again with the same ``out`` folder continues from there. New
shards that appear in the data folder while training runs (a renderer still at work) are picked
up every ``reload_every`` steps.

Targets follow CenterNet: a Gaussian peak per box centre on the stride-4 heatmap (radius from the
box size), log-size and sub-cell offset at the peak cell. Boxes marked ignore (people too hidden
or cut by the crop) neither count as positives nor as negatives.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from numpy.typing import NDArray

from bevflow.detect.coco import CocoImage
from bevflow.detect.rotated import outline_xyxy
from bevflow.detect.scaling import scale_factor
from bevflow.training.augment import augment_sample, boxes_from_owner, clahe, jitter_colors, rotate_rotated_boxes
from bevflow.training.dataset import read_shards
from bevflow.training.export import model_from_onnx
from bevflow.training.model import SIZE_REFERENCE_PX, STRIDE, CenterNetSmall, normalise

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class TrainConfig:
    steps: int = 6000
    batch: int = 16
    crop: int = 192
    lr: float = 2e-3
    weight_decay: float = 1e-4
    warmup: int = 200
    threads: int = 2
    seed: int = 0
    checkpoint_every_s: float = 180.0
    reload_every: int = 300
    log_every: int = 25
    zoom: float = 1.0  # the input scale learnt, × bevflow.detect.scaling's (match ``render --zoom``)


def build_targets(boxes: FloatArray, ignore: NDArray[np.bool_], size: int) -> dict[str, NDArray[Any]]:
    """CenterNet targets for one image of ``size`` px: heatmap (1, S, S), negative-loss mask,
    and per-box cell index, log-size and offset (padded to 64 boxes with a validity mask)."""
    s = size // STRIDE
    heat = np.zeros((s, s), np.float32)
    neg_mask = np.ones((s, s), np.float32)
    index = np.zeros(64, np.int64)
    log_size = np.zeros((64, 2), np.float32)
    offset = np.zeros((64, 2), np.float32)
    valid = np.zeros(64, np.float32)
    yy, xx = np.mgrid[0:s, 0:s]
    k = 0
    for (x0, y0, x1, y1), skip in zip(boxes, ignore, strict=True):
        w, h = x1 - x0, y1 - y0
        c = np.array([(x0 + x1) / 2 + 0.5, (y0 + y1) / 2 + 0.5]) / STRIDE  # cell units
        cell = np.floor(c).astype(int)
        if not (0 <= cell[0] < s and 0 <= cell[1] < s):
            continue
        if skip:
            cx0, cy0 = max(int(x0 // STRIDE), 0), max(int(y0 // STRIDE), 0)
            neg_mask[cy0 : int(y1 // STRIDE) + 1, cx0 : int(x1 // STRIDE) + 1] = 0.0
            continue
        sigma = max(_gaussian_radius(h / STRIDE, w / STRIDE), 0.0) * 2 / 6 + 0.3
        g = np.exp(-((xx - cell[0]) ** 2 + (yy - cell[1]) ** 2) / (2 * sigma * sigma)).astype(np.float32)
        heat = np.maximum(heat, g)
        if k < 64:
            index[k] = cell[1] * s + cell[0]
            log_size[k] = np.log(np.maximum([w, h], 1.0) / SIZE_REFERENCE_PX)
            offset[k] = c - cell
            valid[k] = 1.0
            k += 1
    return {"heat": heat[None], "neg_mask": neg_mask[None], "index": index, "log_size": log_size, "offset": offset, "valid": valid}


def _gaussian_radius(h: float, w: float, min_overlap: float = 0.7) -> float:
    """CenterNet's radius: how far a corner may move while the box keeps ``min_overlap`` IoU."""
    a1, b1, c1 = 1, h + w, w * h * (1 - min_overlap) / (1 + min_overlap)
    r1 = (b1 + math.sqrt(b1**2 - 4 * a1 * c1)) / 2
    a2, b2, c2 = 4, 2 * (h + w), (1 - min_overlap) * w * h
    r2 = (b2 + math.sqrt(b2**2 - 4 * a2 * c2)) / 2
    a3, b3, c3 = 4 * min_overlap, -2 * min_overlap * (h + w), (min_overlap - 1) * w * h
    r3 = (b3 + math.sqrt(b3**2 - 4 * a3 * c3)) / 2
    return min(r1, r2, r3)


def detection_loss(outputs: tuple[torch.Tensor, ...], targets: dict[str, torch.Tensor]) -> tuple[torch.Tensor, dict[str, float]]:
    """Penalty-reduced focal loss on the heatmap + L1 on log-size and offset at the centres."""
    logits, log_size, offset = outputs
    p = torch.sigmoid(logits).clamp(1e-4, 1 - 1e-4)
    gt = targets["heat"]
    pos = (gt >= 1.0).float()
    neg = (1.0 - pos) * targets["neg_mask"]
    pos_loss = -(torch.log(p) * (1 - p) ** 2 * pos).sum()
    neg_loss = -(torch.log(1 - p) * p**2 * (1 - gt) ** 4 * neg).sum()
    n_pos = pos.sum().clamp(min=1.0)
    heat_loss = (pos_loss + neg_loss) / n_pos
    b = logits.shape[0]
    idx, valid = targets["index"], targets["valid"]
    n_valid = valid.sum().clamp(min=1.0)

    def gather(t: torch.Tensor) -> torch.Tensor:
        flat = t.reshape(b, t.shape[1], -1)
        return flat.gather(2, idx[:, None, :].expand(-1, t.shape[1], -1)).permute(0, 2, 1)

    size_loss = ((gather(log_size) - targets["log_size"]).abs().sum(-1) * valid).sum() / n_valid
    off_loss = ((gather(offset) - targets["offset"]).abs().sum(-1) * valid).sum() / n_valid
    total = heat_loss + size_loss + off_loss
    return total, {"heat": heat_loss.item(), "size": size_loss.item(), "offset": off_loss.item()}


class ShardSampler:
    """Random augmented batches from the shards in a folder (re-read on ``reload``)."""

    def __init__(self, folder: Path, crop: int, rng: np.random.Generator) -> None:
        self.folder, self.crop, self.rng = Path(folder), crop, rng
        self.reload()

    def reload(self) -> None:
        self.images, self.owners, self.heights = read_shards(self.folder)
        self.reference = [np.bincount(np.where(o >= 0, o.astype(np.int64) + 1, 0).ravel())[1:] for o in self.owners]

    def __len__(self) -> int:
        return len(self.images)

    def batch(self, n: int) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        images, targets = [], []
        for i in self.rng.integers(0, len(self.images), n):
            img, own = augment_sample(self.rng, self.images[i], self.owners[i], self.crop)
            boxes, ignore = boxes_from_owner(own, self.reference[i])
            images.append(img)
            targets.append(build_targets(boxes, ignore, self.crop))
        x = torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2).float()
        t = {k: torch.from_numpy(np.stack([tt[k] for tt in targets])) for k in targets[0]}
        return normalise(x), t


class CocoSampler:
    """Random augmented batches from a user's annotated frames (``bevflow.detect.coco``). Each
    image is brought to the detector's scale times ``zoom`` (from its ``camera_height_m`` and
    ``focal_px``, else by ``scale``), rotated about its centre (rotated boxes turn with it; their outlines,
    ``bevflow.detect.rotated.outline_xyxy``, are the targets), flipped, equalised, and cropped."""

    def __init__(self, images: list[CocoImage], crop: int, rng: np.random.Generator, scale: float = 1.0,
                 zoom: float = 1.0) -> None:
        self.crop, self.rng = crop, rng
        self.images: list[np.ndarray] = []
        self.rotated: list[FloatArray] = []
        for entry in images:
            img = cv2.imread(str(entry.path), cv2.IMREAD_COLOR)
            if img is None:
                raise FileNotFoundError(f"cannot read image {entry.path}")
            s = scale_factor(entry.camera_height_m, entry.focal_px) * zoom if entry.camera_height_m and entry.focal_px else scale
            img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
            r = entry.rotated.copy()
            r[:, :2] = (r[:, :2] + 0.5) * s - 0.5
            r[:, 2:4] *= s
            self.images.append(img)
            self.rotated.append(r)

    def __len__(self) -> int:
        return len(self.images)

    def sample(self) -> tuple[np.ndarray, FloatArray]:
        i = int(self.rng.integers(0, len(self.images)))
        img, r = self.images[i], self.rotated[i]
        h, w = img.shape[:2]
        centre = ((w - 1) / 2.0, (h - 1) / 2.0)
        angle = self.rng.uniform(0, 360)
        img = np.asarray(cv2.warpAffine(img, cv2.getRotationMatrix2D(centre, angle, 1.0), (w, h)), dtype=np.uint8)
        r = rotate_rotated_boxes(r, angle, centre)
        if self.rng.random() < 0.5:
            img = np.ascontiguousarray(img[:, ::-1])
            r[:, 0] = w - 1 - r[:, 0]
            r[:, 4] = -r[:, 4]
        if self.rng.random() < 0.3:
            img = clahe(img, clip_limit=self.rng.uniform(1.0, 3.0))
        img = jitter_colors(self.rng, img)
        pad = np.zeros((max(h, self.crop), max(w, self.crop), 3), np.uint8)
        pad[:h, :w] = img
        y0 = int(self.rng.integers(0, pad.shape[0] - self.crop + 1))
        x0 = int(self.rng.integers(0, pad.shape[1] - self.crop + 1))
        boxes = outline_xyxy(r) - [x0, y0, x0, y0]
        return pad[y0 : y0 + self.crop, x0 : x0 + self.crop], boxes


def train(
    data: Path | None,
    out: Path,
    config: TrainConfig,
    log: Callable[[str], None] = print,
    coco: list[CocoImage] | None = None,
    coco_fraction: float = 0.5,
    coco_scale: float = 1.0,
    init: Path | None = None,
) -> Path:
    """Train (or resume) on rendered shards in ``data`` and/or ``coco`` frames (a share
    ``coco_fraction`` of each batch when both are given); return the checkpoint path. A new run
    starts from the weights of the exported model ``init`` when given (fine-tuning), else from
    random weights."""
    if data is None and not coco:
        raise ValueError("training needs rendered shards, COCO images, or both")
    torch.set_num_threads(config.threads)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ckpt_path = out / "checkpoint.pt"
    torch.manual_seed(config.seed)
    model = CenterNetSmall()
    opt = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    step, rng = 0, np.random.default_rng(config.seed)
    if ckpt_path.exists():
        state = torch.load(ckpt_path, weights_only=False)
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["optimizer"])
        step = int(state["step"])
        rng.bit_generator.state = state["rng"]
        log(f"resumed at step {step}")
    sampler = ShardSampler(data, config.crop, rng) if data is not None else None
    user = CocoSampler(coco, config.crop, rng, coco_scale, config.zoom) if coco else None
    share = (coco_fraction if sampler is not None else 1.0) if user is not None else 0.0
    if step == 0 and init is not None:
        model = model_from_onnx(init, _mixed_batch(sampler, user, share, config, rng)[0])
        opt = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
        log(f"starting from the weights of {init}")
    log(f"{len(sampler) if sampler else 0} rendered + {len(user) if user else 0} annotated samples; "
        f"{sum(p.numel() for p in model.parameters())} parameters")
    model.train()
    running: dict[str, float] = {}
    last_save, t0 = time.monotonic(), time.monotonic()
    while step < config.steps:
        if step and step % config.reload_every == 0 and sampler is not None:
            sampler.reload()
        for g in opt.param_groups:
            g["lr"] = _learning_rate(step, config)
        x, targets = _mixed_batch(sampler, user, share, config, rng)
        loss, parts = detection_loss(model(x), targets)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 10.0)
        opt.step()
        step += 1
        for k, v in parts.items():
            running[k] = 0.9 * running.get(k, v) + 0.1 * v
        if step % config.log_every == 0:
            rate = (time.monotonic() - t0) / config.log_every
            t0 = time.monotonic()
            log(f"step {step} lr {_learning_rate(step, config):.2e} " + " ".join(f"{k} {v:.3f}" for k, v in running.items()) + f" ({rate:.2f} s/step)")
        if time.monotonic() - last_save > config.checkpoint_every_s or step == config.steps:
            _save(ckpt_path, model, opt, step, rng, config)
            last_save = time.monotonic()
    _save(ckpt_path, model, opt, step, rng, config)
    return ckpt_path


def _mixed_batch(
    shards: ShardSampler | None, user: CocoSampler | None, share: float, config: TrainConfig, rng: np.random.Generator
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    n_user = int(rng.binomial(config.batch, share)) if user is not None else 0
    parts = []
    if n_user < config.batch and shards is not None:
        parts.append(shards.batch(config.batch - n_user))
    if n_user and user is not None:
        samples = [user.sample() for _ in range(n_user)]
        x = torch.from_numpy(np.stack([im for im, _ in samples])).permute(0, 3, 1, 2).float()
        t = [build_targets(b, np.zeros(len(b), bool), config.crop) for _, b in samples]
        parts.append((normalise(x), {k: torch.from_numpy(np.stack([tt[k] for tt in t])) for k in t[0]}))
    x = torch.cat([p[0] for p in parts])
    return x, {k: torch.cat([p[1][k] for p in parts]) for k in parts[0][1]}


def _learning_rate(step: int, config: TrainConfig) -> float:
    if step < config.warmup:
        return config.lr * (step + 1) / config.warmup
    progress = (step - config.warmup) / max(config.steps - config.warmup, 1)
    return config.lr * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(progress, 1.0))))


def _save(path: Path, model: torch.nn.Module, opt: torch.optim.Optimizer, step: int, rng: np.random.Generator, config: TrainConfig) -> None:
    tmp = path.with_suffix(".tmp")
    torch.save({"model": model.state_dict(), "optimizer": opt.state_dict(), "step": step, "rng": rng.bit_generator.state, "config": asdict(config)}, tmp)
    tmp.replace(path)
