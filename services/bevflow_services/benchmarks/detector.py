"""Detector speed per frame at the scaled input of 3.3, 5.5 and 8.1 m cameras, on 1 and 2 threads.

``Detector.detect`` is timed whole (resize to the height-adaptive scale, inference, decoding, NMS)
with the model that serves each height (``DEFAULT_RANGES``, unless a model is given) on a
rendered frame of each height (``bevflow.detect.benchmark.rendered_frame``: a crowd drawn
at 1.5 x the detector's scale, as a camera's own frame is larger than the model's input). The
rim tiles are timed on that frame enlarged to ``REAL_FRAME_PX`` square, the size of the real
ceiling cameras they serve: their cost grows with the frame they shrink. Without
a model file (none given and none shipped) or without ONNX Runtime, nothing is timed and the
result says why: no number is made up.

``bench_rendering`` times what feeds the detector in the live demo: a simulated camera's frame
rendered at the detector's input scale (``bevflow.sim.render_feed.RenderedCameras``) for a
site's crowd, per camera and frame.

    python -m bevflow_services.benchmarks.detector [--render-only] [--people 50] [--frames 30]
"""

from __future__ import annotations

import functools
import importlib.util
import math
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from bevflow.camera import FisheyeCamera
from bevflow.detect.scaling import scaled_focal

from bevflow_services.benchmarks.timing import percentile, time_calls

if TYPE_CHECKING:  # the detector's module is loaded only when a model is timed
    from bevflow.detect.runtime import Detector
    from bevflow.detect.tiles import RimTileDetector

HEIGHTS_M = (3.3, 5.5, 8.1)
THREADS = (1, 2)
REAL_FRAME_PX = 2048  # a real ceiling fisheye camera's frame side (the real frames in docs/RESULTS.md)


def default_model() -> Path:
    from bevflow.detect.runtime import DEFAULT_MODEL

    return DEFAULT_MODEL


def unavailable_reason(model: Path | None) -> str | None:
    """Why the detector cannot be timed here, or None when it can."""
    if importlib.util.find_spec("onnxruntime") is None:
        return "onnxruntime is not installed"
    path = model if model is not None else default_model()
    if not path.is_file():
        return "no detector model shipped" if model is None else f"detector model {path} does not exist"
    return None


def frame_for(height_m: float) -> tuple[np.ndarray, float]:
    """A frame of a camera ``height_m`` up and its focal length (px/rad): rendered when the
    renderer is available, else a textured stand-in of the same size (inference time depends
    on the input size, not on what is in the picture)."""
    try:
        from bevflow.detect.benchmark import rendered_frame
    except ImportError:
        pass
    else:
        return rendered_frame(height_m)
    f = scaled_focal(height_m) * 1.5
    size = int(math.ceil(2 * f * math.radians(92.5)))
    cam = FisheyeCamera.looking_down((0.0, 0.0, height_m), (size, size), 185.0)
    rng = np.random.default_rng(0)
    return rng.integers(60, 200, (size, size, 3), dtype=np.uint8), float(cam.K[0, 0])


def bench_detector(
    model: Path | None = None,
    heights_m: tuple[float, ...] = HEIGHTS_M,
    threads: tuple[int, ...] = THREADS,
    repeats: int = 30,
    warmup: int = 3,
    make_detector: Callable[[int, float], Detector | RimTileDetector] | None = None,
) -> dict:
    """One row per (height, threads): the model's input size and ms per frame, median and 90th
    percentile of wall-clock time (ONNX Runtime works on threads of its own, so the calling
    thread's CPU time would miss most of it). ``make_detector(threads, height)`` overrides how a
    detector is built (tests pass a stand-in)."""
    if make_detector is None:
        reason = unavailable_reason(model)
        if reason is not None:
            return {"available": False, "reason": reason, "rows": []}
        from bevflow.detect.runtime import DEFAULT_RANGES, Detector, DetectorBank

        def make_detector(n: int, height: float) -> Detector | RimTileDetector:
            return Detector(model, threads=n) if model is not None else DetectorBank(DEFAULT_RANGES, threads=n).for_height(height)

    rows = []
    for height in heights_m:
        rendered = frame_for(height)
        for n in threads:
            detector = make_detector(n, height)
            frame, focal = camera_sized(detector, *rendered)
            for _ in range(warmup):
                detector.detect(frame, height, focal)
            timing = time_calls(functools.partial(detector.detect, frame, height, focal), repeats)
            rows.append({
                "height_m": height,
                "threads": n,
                "frame": f"{frame.shape[1]}x{frame.shape[0]}",
                "input": model_input(detector, frame, height, focal),
                "ms_p50": timing.wall_ms,
                "ms_p90": percentile([s * 1e3 for s in timing.wall_s], 90),
                "boxes": len(timing.result),  # type: ignore[arg-type]
            })
    return {"available": True, "reason": None, "rows": rows}


def bench_int8(height_m: float = 5.5, threads: int = 2, rounds: int = 10, calls: int = 3,
               make_detector: Callable[[Path], Detector] | None = None) -> dict:
    """The general model against its INT8 copy on one camera's frame, timed in alternating rounds
    of ``calls`` calls each so that both see the same machine load: ms per frame (median over
    every call) and ``speedup`` = float32 ms / INT8 ms (above 1: INT8 pays on this CPU).
    ``make_detector(path)`` overrides how a model is loaded (tests pass a stand-in)."""
    from bevflow.detect.runtime import DEFAULT_MODEL, INT8_MODEL, Detector

    if not INT8_MODEL.is_file() or not DEFAULT_MODEL.is_file():
        return {"available": False, "reason": f"no {INT8_MODEL.name} shipped beside {DEFAULT_MODEL.name}"}
    load = make_detector or (lambda path: Detector(path, threads=threads))
    frame, focal = frame_for(height_m)
    ms = alternately({"float32": load(DEFAULT_MODEL), "int8": load(INT8_MODEL)}, frame, height_m, focal, rounds, calls)
    return {"available": True, "height_m": height_m, "threads": threads, "ms_p50": {k: round(v, 2) for k, v in ms.items()},
            "speedup": round(ms["float32"] / ms["int8"], 3) if ms["int8"] > 0 else None}


def alternately(detectors: Mapping[str, Detector | RimTileDetector], frame: np.ndarray, height_m: float, focal: float,
                rounds: int, calls: int) -> dict[str, float]:
    """Each detector's median ms per ``frame``, timed in alternating rounds of ``calls`` calls
    each (after one warm-up call) so that all see the same machine load."""
    times: dict[str, list[float]] = {name: [] for name in detectors}
    for detector in detectors.values():
        detector.detect(frame, height_m, focal)  # warm-up
    for _ in range(rounds):
        for name, detector in detectors.items():
            times[name].extend(time_calls(functools.partial(detector.detect, frame, height_m, focal), calls).wall_s)
    return {name: percentile([t * 1e3 for t in values], 50) for name, values in times.items()}


def bench_workers(height_m: float = 5.5, cores: int = 2, rounds: int = 4, calls: int = 6,
                  make_detector: Callable[[int], Detector] | None = None) -> dict:
    """Frames a second through the general model on one camera's frame, on ``cores`` cores, three
    ways timed in alternating rounds (so that all see the same machine load), each round
    ``calls`` × ``cores`` frames: ``one_at_a_time`` on one session of ``cores`` threads;
    ``workers``, ``cores`` sessions of one thread each working in parallel, as the detector
    service runs them (``--workers``); ``batched``, ``cores`` frames per call on one session of
    ``cores`` threads. ``speedup``: workers against one at a time (above 1: the service's default
    pays on this CPU). ``make_detector(threads)`` overrides how the model is loaded (tests)."""
    if make_detector is None:
        reason = unavailable_reason(None)
        if reason is not None:
            return {"available": False, "reason": reason}
        from bevflow.detect.runtime import DEFAULT_MODEL, Detector

        def make_detector(threads: int) -> Detector:
            return Detector(DEFAULT_MODEL, threads=threads)

    frame, focal = frame_for(height_m)
    shared, single = make_detector(cores), [make_detector(1) for _ in range(cores)]
    scale = shared.scale_for(height_m, focal)

    def one_at_a_time() -> None:
        for _ in range(calls * cores):
            shared.detect(frame, height_m, focal)

    def workers() -> None:
        with ThreadPoolExecutor(cores) as pool:
            list(pool.map(lambda d: [d.detect(frame, height_m, focal) for _ in range(calls)], single))

    def batched() -> None:
        for _ in range(calls):
            shared.detect_batch_scaled([frame] * cores, [scale] * cores)

    ways: dict[str, Callable[[], None]] = {"one_at_a_time": one_at_a_time, "workers": workers, "batched": batched}
    seconds: dict[str, list[float]] = {name: [] for name in ways}
    for way in ways.values():
        way()  # warm-up
    for _ in range(rounds):
        for name, way in ways.items():
            start = time.perf_counter()
            way()
            seconds[name].append(time.perf_counter() - start)
    fps = {name: calls * cores / percentile(values, 50) for name, values in seconds.items()}
    return {"available": True, "height_m": height_m, "cores": cores, "fps": {k: round(v, 1) for k, v in fps.items()},
            "speedup": round(fps["workers"] / fps["one_at_a_time"], 3)}


def camera_sized(detector: Detector | RimTileDetector, frame: np.ndarray, focal: float) -> tuple[np.ndarray, float]:
    """``frame`` and its focal length, enlarged to ``REAL_FRAME_PX`` for the rim tiles when it is
    smaller (module docstring)."""
    from bevflow.detect.tiles import RimTileDetector

    if not isinstance(detector, RimTileDetector) or frame.shape[1] >= REAL_FRAME_PX:
        return frame, focal
    k = REAL_FRAME_PX / frame.shape[1]
    return cv2.resize(frame, None, fx=k, fy=k, interpolation=cv2.INTER_LINEAR), focal * k


def model_input(detector: Detector | RimTileDetector, frame: np.ndarray, height: float, focal: float) -> str:
    """What the model sees of ``frame``: its input size, or the rim tiles' and the centre's."""
    from bevflow.detect.tiles import RimTileDetector

    if isinstance(detector, RimTileDetector):
        return f"{detector.layout.tiles} tiles of {detector.input_px}x{detector.input_px} + centre"
    shape = detector.prepare(frame, detector.scale_for(height, focal)).tensor.shape
    return f"{shape[3]}x{shape[2]}"


def bench_rendering(site_name: str = "demo-hall", people: int = 50, frames: int = 30, warmup: int = 10,
                    cameras: tuple[str, ...] | None = None) -> dict:
    """ms per rendered camera frame (median, 90th percentile, wall clock) for ``people`` walking
    in ``site_name``, timed over ``frames`` scene frames after ``warmup`` (the crowd walks in
    first), with the frame size and the number of people each camera showed."""
    from bevflow.sim.feed import scene_for_site
    from bevflow.sim.render_feed import RenderedCameras
    from bevflow.sim.render_textures import Appearance
    from bevflow.sim.scene import Scene
    from bevflow.site import load_site_or_builtin

    site = load_site_or_builtin(site_name)
    preset = scene_for_site(site, people=people).with_scene(frames=warmup + frames)
    chosen = list(cameras) if cameras else site.camera_ids
    renderers = RenderedCameras(site, preset.scene, chosen)
    times: dict[str, list[float]] = {c: [] for c in chosen}
    shown: dict[str, list[int]] = {c: [] for c in chosen}
    pose_s: list[float] = []
    for frame in Scene(preset.scene).run():
        if frame.index < warmup:
            continue
        start = time.perf_counter()
        bodies = frame.primitives()
        appearance = Appearance.for_identities(frame.identity)
        pose_s.append(time.perf_counter() - start)
        for camera in chosen:
            start = time.perf_counter()
            out = renderers.render(camera, frame, bodies, appearance)
            times[camera].append(time.perf_counter() - start)
            shown[camera].append(len(out.boxes))
    rows = [{"camera": c, "frame": "{}x{}".format(*renderers.frame_size(c)), "people_shown": round(float(np.mean(shown[c])), 1),
             "ms_p50": round(percentile([t * 1e3 for t in times[c]], 50), 2),
             "ms_p90": round(percentile([t * 1e3 for t in times[c]], 90), 2)} for c in chosen]
    return {"site": site_name, "people": people, "frames": frames,
            "pose_ms_p50": round(percentile([t * 1e3 for t in pose_s], 50), 2), "rows": rows}


def lookup(result: dict, height_m: float, threads: int) -> float | None:
    """ms per frame of one row of ``bench_detector``'s result, None if it was not measured."""
    for row in result["rows"]:
        if math.isclose(row["height_m"], height_m) and row["threads"] == threads:
            return float(row["ms_p50"])
    return None


if __name__ == "__main__":
    import argparse
    import json

    parser = argparse.ArgumentParser(description="Rendering and detector speed per camera frame.")
    parser.add_argument("--render-only", action="store_true", help="time the rendering only")
    parser.add_argument("--site", default="demo-hall")
    parser.add_argument("--people", type=int, default=50)
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=30, help="detector calls per height and thread count")
    cli = parser.parse_args()
    print(json.dumps(bench_rendering(cli.site, cli.people, cli.frames), indent=1), flush=True)
    if not cli.render_only:
        print(json.dumps(bench_detector(repeats=cli.repeats), indent=1))
