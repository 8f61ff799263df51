"""Detector speed at the scaled input of cameras at given heights: ``python -m
bevflow.detect.benchmark [--model PATH | --model rim-tiles | --model rim-tiles:PATH] [--heights 3.3 8.1] [--threads 1 2] [--repeats 30]``.

Prints, per height and thread count, the model input size and the median and 90th-percentile
milliseconds of ``Detector.detect`` on a rendered frame (resize + inference + decoding + NMS).
The frame is rendered at 1.5x the detector's scale, as a camera's own frame would be larger.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from bevflow.camera import FisheyeCamera
from bevflow.detect.runtime import Detector
from bevflow.detect.scaling import scaled_focal
from bevflow.detect.tiles import RimTileDetector, is_rim_tiles, load_rim_tiles, rim_tiles_model
from bevflow.sim.bodies import BodyShape, pose_bodies
from bevflow.sim.render import FisheyeRenderer, Room


def rendered_frame(height: float, people: int = 15, zoom: float = 1.5, seed: int = 0) -> tuple[np.ndarray, float]:
    """A frame of a camera ``height`` m up, ``zoom`` x the detector's scale; returns it and its focal length."""
    f = scaled_focal(height) * zoom
    size = int(math.ceil(2 * f * math.radians(92.5)))
    cam = FisheyeCamera.looking_down((0.0, 0.0, height), (size, size), 185.0)
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-1.2 * height, 1.2 * height, (people, 2))
    bodies = pose_bodies(BodyShape.sample(rng, people), xy, rng.uniform(0, 6.3, people), rng.uniform(0, 6.3, people),
                         np.full(people, 1.2), np.zeros(people, int))  # fmt: skip
    room = Room((-3.0 * height, -3.0 * height, 3.0 * height, 3.0 * height))
    return FisheyeRenderer(cam, room).render(bodies, np.arange(people)).image, float(cam.K[0, 0])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", type=Path, help="ONNX model (default: the shipped one), or rim-tiles or rim-tiles:PATH (bevflow.detect.tiles)")
    parser.add_argument("--heights", type=float, nargs="+", default=[3.3, 8.1])
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args(argv)
    rows = []
    for h in args.heights:
        frame, focal = rendered_frame(h)
        for t in args.threads:
            det, shape = _detector(args.model, t, frame, h, focal)
            for _ in range(3):
                det.detect(frame, h, focal)
            times = []
            for _ in range(args.repeats):
                start = time.perf_counter()
                det.detect(frame, h, focal)
                times.append(1000 * (time.perf_counter() - start))
            rows.append({"height_m": h, "threads": t, "input": shape, "frame": f"{frame.shape[1]}x{frame.shape[0]}",
                         "median_ms": round(float(np.median(times)), 2), "p90_ms": round(float(np.percentile(times, 90)), 2)})  # fmt: skip
            print(json.dumps(rows[-1]), flush=True)
    return 0


def _detector(
    model: Path | None, threads: int, frame: NDArray[np.uint8], height: float, focal: float
) -> tuple[Detector | RimTileDetector, str]:
    """The detector to time and a description of its input."""
    if is_rim_tiles(model):
        tiles = load_rim_tiles(threads=threads, tile_model=rim_tiles_model(str(model)))
        return tiles, f"{tiles.layout.tiles} tiles of {tiles.input_px}x{tiles.input_px}"
    det = Detector(model, threads=threads)
    shape = det.prepare(frame, det.scale_for(height, focal)).tensor.shape
    return det, f"{shape[3]}x{shape[2]}"


if __name__ == "__main__":
    raise SystemExit(main())
