"""Training tiles for the rim-tile detector (``bevflow.detect.tiles``), cut from renders exactly as
the detector cuts real frames.

A whole ceiling fisheye frame is rendered at a random low ceiling and a random resolution, then
cut into the detector's rim tiles, each turned so that its sector stands upright. The id buffer
is cut with the same map (nearest neighbour), so each tile's boxes are the exact upright bounding
boxes of the people's pixels in it (``bevflow.training.augment.boxes_from_owner``). The frame's
resolution varies between the detector's scale (renders, where a tile is enlarged and blurred) and
several times it (real cameras, where a person at the rim spans hundreds of pixels), so the tile
model sees people at every size a tile can show them.

Before cutting, frames get the failures seen on real frames: a burnt-in timestamp (the real
frames' clock drew boxes), the image circle cut at the top and bottom by a 16:9 sensor, and
light from very dark to washed out; seated people are drawn from ``pose_bodies``' postures.
"""

from __future__ import annotations

import math
from pathlib import Path
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.detect.tiles import TileLayout, tile_affine
from bevflow.training.augment import boxes_from_owner, clahe, jitter_colors
from bevflow.training.dataset import SceneMix, render_sample

FloatArray = NDArray[np.float64]
LOW_CEILINGS_M = (2.4, 5.5)
TILES = TileLayout()


@dataclass(frozen=True)
class TileSample:
    image: NDArray[np.uint8]  # (S, S, 3) BGR, upright
    xyxy: FloatArray  # (N, 4) in tile pixels
    ignore: NDArray[np.bool_]  # (N,) people too hidden or cut to count either way


def render_tiles(rng: np.random.Generator, input_px: int, layout: TileLayout = TILES,
                 zoom: tuple[float, float] = (1.0, 4.0), heights: tuple[float, float] = LOW_CEILINGS_M) -> list[TileSample]:  # fmt: skip
    """One rendered frame's rim tiles, each ``input_px`` square."""
    z = float(math.exp(rng.uniform(math.log(zoom[0]), math.log(zoom[1]))))
    sample = render_sample(rng, size=None, zoom=z, max_people=25, min_pixels=int(20 * z * z), heights=heights,
                           mix=SceneMix(grouped=0.3, squared=0.3))  # fmt: skip
    image, owner = _real_failures(rng, sample.image, sample.owner)
    h, w = owner.shape
    radius = w / 2.0  # the renderer's circle fills the frame's width
    centre = ((w - 1) / 2.0, (h - 1) / 2.0)
    reference = np.bincount(np.where(sample.owner >= 0, sample.owner.astype(np.int64) + 1, 0).ravel())[1:]
    turn = rng.uniform(0, 2 * math.pi / layout.tiles)  # tiles at every angle, not only at the detector's
    out = []
    for t in range(layout.tiles):
        m, _, _ = tile_affine(turn + 2 * math.pi * t / layout.tiles, centre, radius, layout, input_px)
        tile = cv2.warpAffine(image, m, (input_px, input_px), flags=cv2.INTER_AREA if m[0, 0] ** 2 + m[0, 1] ** 2 < 1 else cv2.INTER_LINEAR)
        own = cv2.warpAffine(owner.astype(np.float32), m, (input_px, input_px), flags=cv2.INTER_NEAREST, borderValue=-1)
        scale = math.hypot(m[0, 0], m[0, 1])
        xyxy, ignore = boxes_from_owner(own.astype(np.int16), np.round(reference * scale * scale).astype(np.int64), min_pixels=12)
        out.append(TileSample(np.asarray(tile, dtype=np.uint8), xyxy, ignore))
    return out


def _real_failures(rng: np.random.Generator, image: NDArray[np.uint8], owner: NDArray[np.int16]) -> tuple[NDArray[np.uint8], NDArray[np.int16]]:
    h, w = owner.shape
    image = image.copy()
    if rng.random() < 0.3:  # a 16:9 sensor cuts the circle at the top and bottom
        band = int(h * rng.uniform(0.1, 0.22))
        image[:band], image[h - band :] = 0, 0
        owner = owner.copy()
        owner[:band], owner[h - band :] = -1, -1
    if rng.random() < 0.5:
        _burn_text(rng, image)
    if rng.random() < 0.3:
        image = clahe(image, clip_limit=rng.uniform(1.0, 3.0))
    if rng.random() < 0.8:
        image = jitter_colors(rng, image)
    if rng.random() < 0.2:  # low light: dark and noisy
        image = np.clip(image.astype(np.float32) * rng.uniform(0.25, 0.6) + rng.normal(0, 6, image.shape), 0, 255).astype(np.uint8)
    return image, owner


def _burn_text(rng: np.random.Generator, image: NDArray[np.uint8]) -> None:
    """A camera's date and clock overlay, white or yellow, somewhere in the frame."""
    h, w = image.shape[:2]
    text = f"{rng.integers(2015, 2027)}-{rng.integers(1, 13):02d}-{rng.integers(1, 29):02d} {rng.integers(0, 24):02d}:{rng.integers(0, 60):02d}:{rng.integers(0, 60):02d}"
    scale = w / 900 * rng.uniform(0.6, 1.6)
    thick = max(1, int(round(scale * 2)))
    (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)
    x = int(rng.uniform(0, max(1, w - tw)))
    y = int(rng.uniform(th, h))
    colour = (255, 255, 255) if rng.random() < 0.6 else (0, 255, 255)
    cv2.putText(image, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, scale, colour, thick, cv2.LINE_AA)


def write_tile_shards(folder: Path, frames: int, input_px: int, seed: int, per_shard: int = 8) -> None:
    """Render ``frames`` frames' tiles into ``folder`` as ``tiles-SEED-K.npz`` shards of
    ``per_shard`` frames; shards already there are kept, so an interrupted run resumes."""
    folder.mkdir(parents=True, exist_ok=True)
    for k in range(math.ceil(frames / per_shard)):
        path = folder / f"tiles-{seed}-{k:05d}.npz"
        if path.exists():
            continue
        samples = [s for f in range(per_shard) for s in render_tiles(np.random.default_rng([seed, k, f]), input_px)]
        boxes = [np.column_stack([s.xyxy, s.ignore]) for s in samples]
        tmp = path.with_suffix(".tmp.npz")
        np.savez_compressed(tmp, images=np.stack([s.image for s in samples]), boxes=np.concatenate(boxes),
                            counts=np.array([len(b) for b in boxes]))  # fmt: skip
        tmp.replace(path)


def read_tile_shards(folder: Path) -> tuple[NDArray[np.uint8], list[FloatArray]]:
    """Every tile in ``folder``'s shards and its boxes (N, 5: x0, y0, x1, y1, ignore)."""
    images, boxes = [], []
    for path in sorted(folder.glob("tiles-*[0-9].npz")):
        with np.load(path) as shard:
            images.append(shard["images"])
            boxes += np.split(shard["boxes"], np.cumsum(shard["counts"])[:-1])
    return np.concatenate(images), boxes


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description="render rim-tile training shards")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--input-px", type=int, default=256)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    write_tile_shards(args.out, args.frames, args.input_px, args.seed)
