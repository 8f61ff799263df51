"""Where a rotation-aware detector's boxes put people on the floor, on rendered ceiling frames
whose people's floor positions are known.

AP50 scores boxes, but what the pipeline takes from a box is the floor position the cylinder fit
makes of it (``bevflow.cylinder``), from the box's point nearest the image centre and its size.
Each frame here is a level camera looking down from a height drawn from ``heights``, with people
walking, standing and seated within 1.2 × that height of the nadir each way, rendered at ``zoom``
× the detector's scale (1: as our renders; 3: about a real camera's frame). Each detection that
matches a person (IoU ≥ ``MATCH_IOU`` between its rotated box's enclosing rectangle and the
person's rendered box) is fitted three ways, and the distance to where the person stands is
kept:

- ``pipeline``: the upright box the detector gives the pipeline (``detect_boxes``);
- ``enclosing``: the enclosing rectangle of its rotated box, which the rim tiles gave before;
- ``rendered``: the person's own rendered box: what the fit makes of a perfect upright box.

    python -m bevflow.evaluation.placement --frames 40 --zoom 1 3 --seated 0 1

prints the median, mean and 90th percentile of each (metres), for the shipped rim tiles, with
nobody seated and with everybody seated: the fit models a standing person, and a seated one's
rendered box places them 0.5 m off as well (docs/RESULTS.md, "Real frames").
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from bevflow.camera import FisheyeCamera
from bevflow.cylinder import fit_cylinders
from bevflow.detect.coco import rotated_to_xyxy
from bevflow.detect.scaling import scaled_focal
from bevflow.detections import Boxes
from bevflow.evaluation.detector import RotationAwareDetector, iou_matrix
from bevflow.sim.bodies import BodyShape, Posture, pose_bodies
from bevflow.sim.render import FisheyeRenderer, Room
from bevflow.sim.render_textures import Appearance, RenderStyle

FloatArray = NDArray[np.float64]
FITS = ("pipeline", "enclosing", "rendered")
MATCH_IOU = 0.3
FIELD_OF_VIEW_DEG = 190.0
LOW_CEILINGS_M = (3.0, 5.0)  # where the rim tiles serve by default


@dataclass(frozen=True)
class PlacementFrame:
    """One rendered frame, its camera and where its boxed people stand (row-aligned with ``boxes``)."""

    image: NDArray[np.uint8]
    camera: FisheyeCamera
    height_m: float
    boxes: FloatArray  # (N, 4) the people's rendered boxes
    feet: FloatArray  # (N, 2) where they stand, metres

    @property
    def focal_px(self) -> float:
        return float(self.camera.K[0, 0])

    @property
    def centre(self) -> tuple[float, float]:
        return float(self.camera.K[0, 2]), float(self.camera.K[1, 2])


def render_frame(rng: np.random.Generator, zoom: float, heights: tuple[float, float] = LOW_CEILINGS_M,
                 seated: float = 0.3) -> PlacementFrame:  # fmt: skip
    """A random frame of a level ceiling camera (module docstring); ``seated``: the share of
    people seated, the rest walking and standing 4 : 3."""
    height = float(rng.uniform(*heights))
    focal = scaled_focal(height) * zoom
    size = int(math.ceil(2 * focal * math.radians(FIELD_OF_VIEW_DEG / 2)))
    camera = FisheyeCamera.looking_down((0.0, 0.0, height), (size, size), FIELD_OF_VIEW_DEG)
    n = int(rng.integers(3, 16))
    feet = rng.uniform(-1.2 * height, 1.2 * height, (n, 2))
    posture = rng.choice(
        [Posture.WALKING, Posture.STANDING, Posture.SITTING], n, p=[(1 - seated) * 4 / 7, (1 - seated) * 3 / 7, seated]
    )
    speed = np.where(posture == Posture.WALKING, 1.2, 0.0)
    bodies = pose_bodies(
        BodyShape.sample(rng, n), feet, rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 2 * np.pi, n), speed, posture
    )
    room = Room((-3.0 * height, -3.0 * height, 3.0 * height, 3.0 * height))
    out = FisheyeRenderer(camera, room).render(bodies, np.arange(n), Appearance.sample(rng, n), RenderStyle.sample(rng), rng,
                                              min_pixels=int(20 * zoom * zoom))  # fmt: skip
    return PlacementFrame(out.image, camera, height, out.boxes.xyxy, feet[out.rows])


def render_frames(count: int, zoom: float, seed: int = 0, heights: tuple[float, float] = LOW_CEILINGS_M,
                  seated: float = 0.3) -> Iterator[PlacementFrame]:  # fmt: skip
    """``count`` frames of ``render_frame``, frame k from the random stream (``seed``, k)."""
    for k in range(count):
        yield render_frame(np.random.default_rng([seed, k]), zoom, heights, seated)


def feet_errors(detector: RotationAwareDetector, frames: Iterable[PlacementFrame]) -> dict[str, FloatArray]:
    """Each fit's distances (metres) from the people's feet, for the same matched people in
    every fit."""
    errors: dict[str, list[FloatArray]] = {name: [] for name in FITS}
    for frame in frames:
        boxes, rotated = detector.detect_boxes(frame.image, frame.height_m, frame.focal_px, frame.centre)
        if not len(boxes) or not len(frame.boxes):
            continue
        overlap = iou_matrix(rotated_to_xyxy(rotated), frame.boxes)
        found, people = linear_sum_assignment(-overlap)
        matched = overlap[found, people] >= MATCH_IOU
        found, people = found[matched], people[matched]
        fits = {
            "pipeline": boxes.xyxy[found],
            "enclosing": rotated_to_xyxy(rotated[found]),
            "rendered": frame.boxes[people],
        }
        placed = {name: fit_cylinders(frame.camera, Boxes(xyxy)).xy for name, xyxy in fits.items()}
        placeable = np.all([np.isfinite(xy).all(axis=1) for xy in placed.values()], axis=0)
        for name, xy in placed.items():
            errors[name].append(np.linalg.norm(xy[placeable] - frame.feet[people][placeable], axis=1))
    return {name: np.concatenate(e) if e else np.zeros(0) for name, e in errors.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="feet placement of the rim tiles' boxes on rendered low-ceiling frames"
    )
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument(
        "--zoom", type=float, nargs="+", default=[1.0, 3.0], help="frame size as times the detector's scale"
    )
    parser.add_argument(
        "--seated", type=float, nargs="+", default=[0.0, 1.0], help="shares of people seated, one run each"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args(argv)
    from bevflow.detect.tiles import load_rim_tiles  # onnxruntime loads only here

    detector = load_rim_tiles(threads=args.threads)
    print("zoom  seated  fit        people  median m  mean m  p90 m")
    for zoom in args.zoom:
        for seated in args.seated:
            frames = render_frames(args.frames, zoom, args.seed, seated=seated)
            for name, e in feet_errors(detector, frames).items():
                print(
                    f"{zoom:<5g} {seated:<7g} {name:<10} {len(e):>6}  {np.median(e):8.3f}  {e.mean():6.3f}  {np.percentile(e, 90):5.3f}"
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
