"""The cylinder fit: batched against the exhaustive reference, speed and agreement, and the feet
error of each projection method.

Boxes are the bounding rectangles of human-shaped point clouds (legs, torso, arms, head; 1.55 to
1.9 m tall, random heading) standing at random within a camera's monitored radius. For each
number of boxes per frame, ``bench_speed`` times the batched fit (median wall-clock and median
thread CPU time over ``repeats`` calls, after a first cold call that fills the camera's lookup
table, timed apart) and the reference (median over ``reference_repeats``), and reports the largest
disagreement between the two in metres. ``bench_accuracy`` gives the mean feet error of each
method and weighting on clean model (cuboid) boxes, silhouette boxes, silhouettes with 3 % box
noise, and silhouettes whose lower 30 % is hidden.

    python -m bevflow_services.benchmarks.cylinder [--camera fisheye-5.5] [--boxes 10 50 200] [--accuracy] [--json OUT]
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import time
from dataclasses import replace

import numpy as np

from bevflow.camera import Camera, FisheyeCamera, PinholeCamera, rotation_from_ypr
from bevflow.cylinder import (
    CylinderGrid,
    ProjectionMethod,
    box_anchor,
    clear_lookup_cache,
    fit_cylinders,
    fit_cylinders_reference,
)
from bevflow.detections import Boxes

from bevflow_services.benchmarks.timing import time_calls

MONITORED_RADIUS_M = {"fisheye-3.3": 3.5, "fisheye-5.5": 8.0, "fisheye-8.1": 10.0}  # the paper's Table 1


def make_camera(name: str) -> Camera:
    if name == "pinhole":  # WILDTRACK-like: 2.5 m up, 20° below level
        R = rotation_from_ypr(0.0, 70.0, 0.0)
        K = np.array([[1700.0, 0.0, 960.0], [0.0, 1700.0, 540.0], [0.0, 0.0, 1.0]])
        return PinholeCamera(K=K, dist=np.zeros(5), R=R, t=-R @ np.array([0.0, 0.0, 2.5]), image_size=(1920, 1080))
    height = float(name.split("-")[1])
    return FisheyeCamera.looking_down(position=(0.0, 0.0, height), image_size=(1024, 1024), fov_deg=185.0)


def body_points() -> np.ndarray:
    ring = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    parts = [(-0.1, 0.07, 0.07, 0.0, 0.85), (0.1, 0.07, 0.07, 0.0, 0.85), (0.0, 0.2, 0.12, 0.85, 1.45),
             (-0.25, 0.05, 0.05, 0.8, 1.42), (0.25, 0.05, 0.05, 0.8, 1.42)]
    points = []
    for cx, ax, ay, z0, z1 in parts:
        t, z = np.meshgrid(ring, np.linspace(z0, z1, 5))
        points.append(np.stack([cx + ax * np.cos(t), ay * np.sin(t), z], axis=-1).reshape(-1, 3))
    t, e = np.meshgrid(ring, np.linspace(-np.pi / 2, np.pi / 2, 7))
    head = [0.1 * np.cos(e) * np.cos(t), 0.1 * np.cos(e) * np.sin(t), 1.64 + 0.11 * np.sin(e)]
    points.append(np.stack(head, axis=-1).reshape(-1, 3))
    return np.concatenate(points) / np.array([1.0, 1.0, 1.75])  # unit height


def clip(camera: Camera, rects: np.ndarray) -> np.ndarray:
    w, h = camera.image_size
    return np.clip(rects, 0.0, [w - 1, h - 1, w - 1, h - 1])


def silhouette_boxes(camera: Camera, feet: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    body, rects = body_points(), []
    for x, y in feet:
        a = rng.uniform(0.0, math.pi)
        turn = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
        uv = camera.project((body * [1.0, 1.0, rng.uniform(1.55, 1.9)]) @ turn.T + [x, y, 0.0])
        uv = uv[np.isfinite(uv).all(axis=1)]
        rects.append([*uv.min(axis=0), *uv.max(axis=0)])
    return clip(camera, np.array(rects))


def cuboid_boxes(camera: Camera, feet: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    square = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    rects = []
    for x, y in feet:
        r, h = rng.uniform(0.25, 0.4), rng.uniform(1.5, 1.9)
        bottom = np.c_[[x, y] + r * square, np.zeros(4)]
        corners = np.concatenate([bottom, np.c_[[x, y] + 0.6 * r * square, np.full(4, h)]])
        uv = camera.project(corners)
        rects.append([*uv.min(axis=0), *uv.max(axis=0)])
    return clip(camera, np.array(rects))


def hide_lower_part(camera: Camera, rects: np.ndarray, fraction: float) -> np.ndarray:
    """Cut the side of each box nearest the nadir, as an obstacle in front of the legs would."""
    out = rects.copy()
    direction = (rects[:, :2] + rects[:, 2:]) / 2.0 - camera.nadir_pixel()
    for row, (dx, dy) in zip(out, direction, strict=True):
        axis = 0 if abs(dx) > abs(dy) else 1
        cut = fraction * (row[axis + 2] - row[axis])
        if (dx if axis == 0 else dy) > 0:
            row[axis] += cut
        else:
            row[axis + 2] -= cut
    return out


def random_feet(camera_name: str, camera: Camera, n: int, rng: np.random.Generator) -> np.ndarray:
    if camera_name == "pinhole":
        depth = rng.uniform(4.0, 20.0, n)
        return np.stack([depth * rng.uniform(-0.4, 0.4, n), depth], axis=1)
    radius = MONITORED_RADIUS_M[camera_name] * np.sqrt(rng.uniform(0.0, 1.0, n))  # uniform over the disc
    azimuth = rng.uniform(0.0, 2.0 * math.pi, n)
    return camera.center[:2] + np.stack([radius * np.cos(azimuth), radius * np.sin(azimuth)], axis=1)


def bench_speed(camera_name: str, sizes: list[int], repeats: int, reference_repeats: int, seed: int = 0,
                reference_max_boxes: int | None = None) -> list[dict]:
    """One row per number of boxes per frame: ms per box of both fits, the cold first call, and
    their largest disagreement. ``reference_max_boxes`` runs the reference on only the first that
    many boxes of a frame (its time per box does not depend on how many there are: it is a plain
    loop), to shorten quick runs; agreement is then checked on those boxes."""
    camera = make_camera(camera_name)
    rng = np.random.default_rng(seed)
    rows = []
    for n in sizes:
        boxes = Boxes(xyxy=silhouette_boxes(camera, random_feet(camera_name, camera, n, rng), rng))
        clear_lookup_cache()
        start = time.perf_counter()
        fast = fit_cylinders(camera, boxes)
        cold_ms = (time.perf_counter() - start) * 1e3
        batched = time_calls(functools.partial(fit_cylinders, camera, boxes), repeats)
        checked = min(n, reference_max_boxes or n)
        subset = boxes[:checked]
        reference = time_calls(functools.partial(fit_cylinders_reference, camera, subset), reference_repeats)
        slow, fast = reference.result, fast[:checked]
        both = np.isfinite(fast.xy).all(axis=1) & np.isfinite(slow.xy).all(axis=1)
        rows.append({
            "boxes": n,
            "batched_ms_per_box": batched.wall_ms / n,
            "batched_cpu_ms_per_box": batched.cpu_ms / n,
            "batched_cold_ms": cold_ms,
            "reference_boxes": checked,
            "reference_ms_per_box": reference.wall_ms / checked,
            "reference_cpu_ms_per_box": reference.cpu_ms / checked,
            "speedup": (reference.cpu_ms / checked) / (batched.cpu_ms / n),
            "max_disagreement_m": float(np.abs(fast.xy[both] - slow.xy[both]).max(initial=0.0)),
            "nan_mismatches": int((np.isnan(fast.xy[:, 0]) != np.isnan(slow.xy[:, 0])).sum()),
        })
    return rows


def format_speed(rows: list[dict]) -> list[str]:
    return [
        f"{r['boxes']:4d} boxes  batched {r['batched_ms_per_box']:.4f} ms/box (CPU {r['batched_cpu_ms_per_box']:.4f}; "
        f"cold first call {r['batched_cold_ms']:.0f} ms)  reference {r['reference_ms_per_box']:.2f} ms/box"
        + (f" (on {r['reference_boxes']})" if r["reference_boxes"] != r["boxes"] else "") + "  "
        f"x{r['speedup']:.0f}  max disagreement {r['max_disagreement_m']:.2e} m  NaN mismatches {r['nan_mismatches']}"
        for r in rows
    ]


ESTIMATORS: dict[str, tuple[ProjectionMethod, CylinderGrid]] = {
    "bbox-center": ("bbox-center", CylinderGrid()),
    "nearest-point": ("nearest-point", CylinderGrid()),
    "cylinder, paper weights (IoU)": ("cylinder", CylinderGrid(weight_power=1.0)),
    "cylinder, IoU^2": ("cylinder", CylinderGrid(weight_power=2.0)),
    "cylinder, IoU^4 (default)": ("cylinder", CylinderGrid()),
    "cylinder, IoU^8": ("cylinder", CylinderGrid(weight_power=8.0)),
    "cylinder, top 10": ("cylinder", CylinderGrid(weight_power=1.0, top_k=10)),
    "cylinder, best only": ("cylinder", CylinderGrid(top_k=1)),
    "cylinder, IoU^4, no occlusion test": ("cylinder", CylinderGrid(occlusion_ratio=math.inf)),
}


def bench_accuracy(camera_name: str, people: int, seed: int) -> dict:
    camera = make_camera(camera_name)
    rng = np.random.default_rng(seed)
    feet = random_feet(camera_name, camera, people, rng)
    silhouettes = silhouette_boxes(camera, feet, rng)
    size = np.concatenate([silhouettes[:, 2:] - silhouettes[:, :2]] * 2, axis=1)
    away = np.linalg.norm(feet - camera.center[:2], axis=1) > 1.0  # a hidden lower body needs a body axis
    sets = {
        "model": (cuboid_boxes(camera, feet, rng), feet),
        "silhouette": (silhouettes, feet),
        "silhouette+3%": (clip(camera, silhouettes + rng.normal(0.0, 0.03, silhouettes.shape) * size), feet),
        "lower 30% hidden": (hide_lower_part(camera, silhouettes[away], 0.3), feet[away]),
    }
    print(f"mean feet error (m), {camera_name}, {people} people" + "".join(f" | {name:>16s}" for name in sets))
    table: dict[str, dict[str, float]] = {}
    for label, (method, grid) in ESTIMATORS.items():
        table[label] = {}
        for name, (rects, truth) in sets.items():
            fit = fit_cylinders(camera, Boxes(xyxy=rects), method, grid)
            table[label][name] = float(np.nanmean(np.linalg.norm(fit.xy - truth, axis=1)))
            if method == "cylinder" and grid == CylinderGrid():
                table[label][name + " flagged occluded"] = float(fit.occluded.mean())
        print(f"{label:38s}" + "".join(f" | {table[label][name]:16.3f}" for name in sets))
    flagged = table["cylinder, IoU^4 (default)"]
    shares = ", ".join(f"{name} {flagged[name + ' flagged occluded']:.2f}" for name in sets)
    print(f"  share flagged occluded by the default: {shares}")
    anchor_ground = camera.pixels_to_plane(box_anchor(camera, Boxes(xyxy=silhouettes)))[:, :2]
    clamp = np.clip(camera.nadir_pixel(), silhouettes[:, :2], silhouettes[:, 2:])
    clamp_ground = camera.pixels_to_plane(clamp)[:, :2]
    table["anchor"] = {
        "axis exit (box_anchor)": float(np.nanmean(np.linalg.norm(anchor_ground - feet, axis=1))),
        "nearest-point clamp": float(np.nanmean(np.linalg.norm(clamp_ground - feet, axis=1))),
    }
    print("  silhouette anchors on the floor: " + ", ".join(f"{k} {v:.3f} m" for k, v in table["anchor"].items()))
    return table


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--camera", default="fisheye-5.5", choices=[*MONITORED_RADIUS_M, "pinhole"])
    parser.add_argument("--boxes", type=int, nargs="+", default=[10, 50, 200], help="boxes per frame")
    parser.add_argument("--repeats", type=int, default=50, help="timed calls of the batched fit")
    parser.add_argument("--reference-repeats", type=int, default=3, help="timed calls of the reference")
    parser.add_argument("--accuracy", action="store_true", help="also measure feet errors of every method")
    parser.add_argument("--people", type=int, default=400, help="people for --accuracy")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", metavar="OUT", help="write the numbers to this JSON file")
    args = parser.parse_args(argv)

    print(f"camera {args.camera}; grid {replace(CylinderGrid())}")
    speed = bench_speed(args.camera, args.boxes, args.repeats, args.reference_repeats, args.seed)
    for line in format_speed(speed):
        print(line)
    report: dict = {"camera": args.camera, "speed": speed}
    if args.accuracy:
        report["accuracy"] = bench_accuracy(args.camera, args.people, args.seed)
    if args.json:
        with open(args.json, "w") as out:
            json.dump(report, out, indent=2)


if __name__ == "__main__":
    main()
