"""``bevflow evaluate --detector --images DIR --annotations FILE``: score the person detector on
annotated frames (AP50, AP50_rotated, precision, recall, F1, ms per frame), optionally drawing
what it found (``--draw DIR``). Without ``--annotations`` nothing is scored: the detector runs on
every image of the folder as it runs live (each model's own reporting threshold) and each frame's
count of people is printed, and drawn with ``--draw``: what an installer checks on a new camera's
first frames.

Frames without calibration (no ``camera_height_m`` / ``focal_px`` in the COCO file, no
``--camera-height`` / ``--focal``, no ``--scale``) are fed at the scale their image circle
suggests for a camera on a 3 m ceiling (``bevflow.detect.circle``); what was assumed is printed.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bevflow.detect.tiles import RIM_TILES, RimTileDetector, is_rim_tiles, load_rim_tiles

from bevflow_services.runtime import UserError

if TYPE_CHECKING:  # the detector's runtime loads when a model does
    from bevflow.detect.runtime import Detector, DetectorBank

SCORE_FLOOR = 0.05  # scoring keeps every box down to this confidence: AP needs the whole curve


def add_detector_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``bevflow evaluate`` that score the person detector on annotated frames."""
    group = parser.add_argument_group("detector evaluation (--detector --images DIR --annotations FILE)")
    group.add_argument("--detector", action="store_true", help="run the real person detector on images instead of using annotated boxes")
    group.add_argument("--model", type=Path, metavar="MODEL",
                       help="the ONNX detector (a file or a shipped model's name, e.g. bevflow-person-centernet-int8), or 'rim-tiles': rim tiles turned upright through a detector trained on "
                       "photographs ('rim-tiles:MODEL' runs MODEL on them, as --tile-model does) (default: what a site gets, by each frame's camera height: rim-tiles under 5 m, "
                       "the shipped general model from 5 m)")  # fmt: skip
    group.add_argument("--tile-model", type=Path, metavar="MODEL",
                       help="with rim-tiles: the ONNX model run on the tiles, a file or a shipped model's name (default: the shipped FastestDet, "
                       "fastestdet-tiles; fastestdet-coco is its COCO weights as published, yolox-nano-coco more accurate and slower)")  # fmt: skip
    group.add_argument("--annotations", type=Path, metavar="FILE",
                       help="COCO JSON of the --images: bbox [x,y,w,h] or rotated [cx,cy,w,h,deg] (iscrowd 1: a crowd region, where "
                       "detections count for nothing, as in COCO); without it nothing is "
                       "scored: each image's people are counted (and drawn with --draw) as the live detector reports them")  # fmt: skip
    group.add_argument("--threads", type=int, default=2, metavar="N", help="ONNX Runtime threads (default 2)")
    group.add_argument("--camera-height", type=float, metavar="M", help="camera height for images without 'camera_height_m' (with --focal)")
    group.add_argument("--focal", type=float, metavar="PX", help="focal length in px for images without 'focal_px' (with --camera-height)")
    group.add_argument("--scale", type=float, metavar="F",
                       help="resize factor for images without calibration (default: found from the image circle "
                       "for a 190-degree lens 3 m above the floor, printed)")  # fmt: skip
    group.add_argument("--draw", type=Path, metavar="DIR", help="write each frame with the truth (green) and the detections (yellow: right, red: wrong) drawn")
    group.add_argument("--turns", type=int, default=1, metavar="N",
                       help="also score the frames as a camera turned about its axis would see them, at N turns k x 360/N "
                       "degrees (k = 0 .. N-1), and print each score's mean, min and max: how much the figures owe to the "
                       "directions people happen to lie in; needs rotated truth boxes (default 1: the frames as they are)")  # fmt: skip


def _check(args: argparse.Namespace) -> None:
    if not args.detector:
        raise UserError("--images is for running the person detector: add --detector (and --annotations FILE to score it)")
    if args.annotations is None and args.turns > 1:
        raise UserError("--turns scores turned frames against their truth: it needs --annotations FILE")
    if not args.images.is_dir():
        raise UserError(f"--images {args.images} is not a folder")
    if (args.camera_height is None) != (args.focal is None):
        raise UserError("give --camera-height and --focal together")
    if args.scale is not None and not (math.isfinite(args.scale) and args.scale > 0):
        raise UserError(f"--scale must be a number > 0, got {args.scale}")
    if args.threads <= 0:
        raise UserError(f"--threads must be positive, got {args.threads}")
    if args.tile_model is not None and str(args.model) != RIM_TILES:
        raise UserError("--tile-model goes with --model rim-tiles" + (" (or --model rim-tiles:MODEL alone)" if is_rim_tiles(args.model) else ""))
    if args.turns < 1:
        raise UserError(f"--turns must be a number of turns >= 1, got {args.turns}")
    if is_rim_tiles(args.model) and args.scale is not None:
        raise UserError("--model rim-tiles sizes its tiles from the focal length: give --camera-height and --focal, or neither, not --scale")


def _detector(args: argparse.Namespace, score_threshold: float | None) -> Detector | RimTileDetector | DetectorBank:
    """The detector ``--model`` (and ``--tile-model``) name, reporting boxes down to ``score_threshold``
    (None: each model's own, as live)."""
    from bevflow.detect.runtime import DEFAULT_RANGES, Detector, DetectorBank

    from bevflow_services.detector.models import resolve_model, tile_model_file

    if is_rim_tiles(args.model):
        tiles = resolve_model(args.tile_model) if args.tile_model is not None else tile_model_file(str(args.model))
        return load_rim_tiles(threads=args.threads, tile_model=tiles, score_threshold=score_threshold)
    if args.model is None and args.scale is None:  # each frame gets the model of its (assumed) height
        return DetectorBank(DEFAULT_RANGES, threads=args.threads, score_threshold=score_threshold)
    model = resolve_model(args.model) if args.model is not None else None
    return Detector(model, threads=args.threads, score_threshold=score_threshold)


def run_detector_evaluation(args: argparse.Namespace) -> int:
    from bevflow.detect.coco import read_coco
    from bevflow.detect.runtime import DetectorBank
    from bevflow.evaluation.detector import detect_turned_frames, score_frames
    from bevflow.evaluation.drawing import write_drawings
    from bevflow.evaluation.turned import TurnedScores, turn_angles

    _check(args)
    if args.annotations is None:
        return _run_unannotated(args)
    with _user_errors():
        if args.turns > 1 and not all(e.oriented for e in read_coco(args.annotations, args.images)):
            raise UserError(f"--turns needs rotated truth boxes ([cx, cy, w, h, degrees]); {args.annotations} has axis-aligned ones")
        detector = _detector(args, SCORE_FLOOR)  # every detection scored: AP needs the whole precision-recall curve
        degrees = turn_angles(args.turns)  # the first is none: the frames as they are
        per_turn = detect_turned_frames(detector, args.annotations, degrees, args.images, args.camera_height, args.focal,
                                        args.scale, log=print)  # fmt: skip
        results, ms = per_turn[0]
        scores = score_frames(results, ms)
        drawn = write_drawings(results, args.draw, scores.threshold) if args.draw is not None else []
        turned = [scores.as_dict()] + [score_frames(*turn).as_dict() for turn in per_turn[1:]]
        spread = TurnedScores.of(degrees, turned) if args.turns > 1 else None
    print(f"{scores.images} images, {scores.annotations} people, {scores.detections} detections, "
          f"{scores.ms_per_frame:.1f} ms per frame")  # fmt: skip
    print(f"AP50 {scores.AP50:.3f}  AP50_rotated {scores.AP50_rotated:.3f}  precision {scores.precision:.3f}  "
          f"recall {scores.recall:.3f}  F1 {scores.F1:.3f}  (score >= {scores.threshold:.3f})")  # fmt: skip
    if drawn:
        print(f"drew {len(drawn)} frames into {args.draw}")
    if spread is not None:
        print(f"{len(spread.degrees)} turns ({', '.join(f'{d:g}' for d in spread.degrees)} degrees): "
              + "  ".join(f"{k} {s.mean:.3f} ({s.low:.3f}-{s.high:.3f})" for k, s in spread.scores.items()))  # fmt: skip
    if isinstance(detector, DetectorBank):
        print(f"models by camera height: {detector.describe()}")
    if args.json is not None:
        _write_json(args.json, scores.as_dict() | ({} if spread is None else {"turned": spread.as_dict()}))
    return 0


def _run_unannotated(args: argparse.Namespace) -> int:
    """Every image of ``--images`` through the detector as it runs live: each frame's people
    counted, printed, drawn (``--draw``) and written (``--json``); nothing scored."""
    from bevflow.evaluation.detector import detect_turned_frames
    from bevflow.evaluation.drawing import write_drawings

    with _user_errors():
        [(results, ms)] = detect_turned_frames(_detector(args, None), None, [0.0], args.images,
                                              args.camera_height, args.focal, args.scale, log=print)  # fmt: skip
        drawn = write_drawings(results, args.draw, 0.0) if args.draw is not None else []  # all the detector reported
    people = {r.entry.path.name: len(r.confidence) for r in results}
    for name, count in people.items():
        print(f"{name}: {count} {'person' if count == 1 else 'people'}")
    print(f"{len(results)} images, {sum(people.values())} people as the live detector reports them (each model's own "
          f"score threshold), {ms:.1f} ms per frame; nothing scored: no --annotations")  # fmt: skip
    if drawn:
        print(f"drew {len(drawn)} frames into {args.draw}")
    if args.json is not None:
        _write_json(args.json, {"images": len(results), "ms_per_frame": ms, "people": people})
    return 0


@contextmanager
def _user_errors() -> Iterator[None]:
    """Frames, annotations or models that cannot be read, and drawings that cannot be written, as
    one line for the user."""
    from bevflow.detect.coco import CocoError
    from bevflow.detect.runtime import DetectorError

    try:
        yield
    except (DetectorError, CocoError, FileNotFoundError) as exc:
        raise UserError(str(exc)) from None
    except OSError as exc:
        raise UserError(f"cannot write the drawings: {exc}") from None


def _write_json(path: Path, doc: dict[str, Any]) -> None:
    try:
        path.write_text(json.dumps(doc, indent=2) + "\n")
    except OSError as exc:
        raise UserError(f"cannot write {path}: {exc.strerror or exc}") from None
