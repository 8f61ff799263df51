"""``bevflow evaluate --detector --images DIR --annotations FILE``: score the person detector on
annotated frames (AP50, AP50_rotated, precision, recall, F1, ms per frame), optionally drawing
what it found (``--draw DIR``).

Frames without calibration (no ``camera_height_m`` / ``focal_px`` in the COCO file, no
``--camera-height`` / ``--focal``, no ``--scale``) are fed at the scale their image circle
suggests for a camera on a 3 m ceiling (``bevflow.detect.circle``); what was assumed is printed.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from bevflow.detect.tiles import RIM_TILES, RimTileDetector, load_rim_tiles

from bevflow_services.runtime import UserError


def add_detector_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``bevflow evaluate`` that score the person detector on annotated frames."""
    group = parser.add_argument_group("detector evaluation (--detector --images DIR --annotations FILE)")
    group.add_argument("--detector", action="store_true", help="run the real person detector on images instead of using annotated boxes")
    group.add_argument("--model", type=Path, metavar="MODEL",
                       help="the ONNX detector (a file or a shipped model's name, e.g. bevflow-person-centernet-int8), or 'rim-tiles': rim tiles turned upright through a detector trained on "
                       "photographs (default: what a site gets, by each frame's camera height: rim-tiles under 5 m, "
                       "the shipped general model from 5 m)")  # fmt: skip
    group.add_argument("--tile-model", type=Path, metavar="MODEL",
                       help="with rim-tiles: the ONNX model run on the tiles, a file or a shipped model's name (default: the shipped FastestDet, "
                       "fastestdet-tiles; fastestdet-coco is its COCO weights as published, yolox-nano-coco more accurate and slower)")  # fmt: skip
    group.add_argument("--annotations", type=Path, metavar="FILE", help="COCO JSON of the --images: bbox [x,y,w,h] or rotated [cx,cy,w,h,deg]")
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
        raise UserError("--images is for scoring the person detector: add --detector (and --annotations FILE)")
    if args.annotations is None:
        raise UserError("--detector --images DIR needs --annotations FILE (COCO JSON)")
    if not args.images.is_dir():
        raise UserError(f"--images {args.images} is not a folder")
    if (args.camera_height is None) != (args.focal is None):
        raise UserError("give --camera-height and --focal together")
    if args.scale is not None and not (math.isfinite(args.scale) and args.scale > 0):
        raise UserError(f"--scale must be a number > 0, got {args.scale}")
    if args.threads <= 0:
        raise UserError(f"--threads must be positive, got {args.threads}")
    if args.tile_model is not None and str(args.model) != RIM_TILES:
        raise UserError("--tile-model goes with --model rim-tiles")
    if args.turns < 1:
        raise UserError(f"--turns must be a number of turns >= 1, got {args.turns}")
    if str(args.model) == RIM_TILES and args.scale is not None:
        raise UserError("--model rim-tiles sizes its tiles from the focal length: give --camera-height and --focal, or neither, not --scale")


def run_detector_evaluation(args: argparse.Namespace) -> int:
    from bevflow.detect.coco import CocoError, read_coco
    from bevflow.detect.runtime import DEFAULT_RANGES, Detector, DetectorBank, DetectorError
    from bevflow.evaluation.detector import detect_turned_frames, score_frames
    from bevflow.evaluation.drawing import write_drawings
    from bevflow.evaluation.turned import TurnedScores, turn_angles

    from bevflow_services.detector.models import resolve_model

    _check(args)
    try:
        if args.turns > 1 and not all(e.oriented for e in read_coco(args.annotations, args.images)):
            raise UserError(f"--turns needs rotated truth boxes ([cx, cy, w, h, degrees]); {args.annotations} has axis-aligned ones")
        # Score every detection: AP needs the whole precision-recall curve.
        detector: Detector | RimTileDetector | DetectorBank
        if str(args.model) == RIM_TILES:
            tiles = resolve_model(args.tile_model) if args.tile_model is not None else None
            detector = load_rim_tiles(threads=args.threads, tile_model=tiles, score_threshold=0.05)
        elif args.model is None and args.scale is None:  # each frame gets the model of its (assumed) height
            detector = DetectorBank(DEFAULT_RANGES, threads=args.threads, score_threshold=0.05)
        else:
            model = resolve_model(args.model) if args.model is not None else None
            detector = Detector(model, threads=args.threads, score_threshold=0.05)
        degrees = turn_angles(args.turns)  # the first is none: the frames as they are
        per_turn = detect_turned_frames(detector, args.annotations, degrees, args.images, args.camera_height, args.focal,
                                        args.scale, log=print)  # fmt: skip
        results, ms = per_turn[0]
        scores = score_frames(results, ms)
        drawn = write_drawings(results, args.draw, scores.threshold) if args.draw is not None else []
        turned = [scores.as_dict()] + [score_frames(*turn).as_dict() for turn in per_turn[1:]]
        spread = TurnedScores.of(degrees, turned) if args.turns > 1 else None
    except (DetectorError, CocoError, FileNotFoundError) as exc:
        raise UserError(str(exc)) from None
    except OSError as exc:
        raise UserError(f"cannot write the drawings: {exc}") from None
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
        try:
            args.json.write_text(json.dumps(scores.as_dict() | ({} if spread is None else {"turned": spread.as_dict()}), indent=2) + "\n")
        except OSError as exc:
            raise UserError(f"cannot write {args.json}: {exc.strerror or exc}") from None
    return 0

