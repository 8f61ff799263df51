"""``bevflow train-detector``: render training data, train, export and evaluate the person detector.

Training needs the optional ``train`` extra (torch); rendering and evaluation do not.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

from bevflow_services.runtime import UserError

if TYPE_CHECKING:
    from bevflow.training.dataset import SceneMix

EPILOG = """\
steps, each resumable (run the same command again to continue):
  bevflow train-detector render --out data/train --count 4000            rendered training crops (.npz shards)
  bevflow train-detector render-eval --out data/eval --count 100          held-out whole frames + COCO annotations
  bevflow train-detector train --data data/train --out runs/a --steps 3000
  bevflow train-detector train --coco my.json --images frames/ --out runs/b   your own annotated frames (COCO,
                                                                         bbox [x,y,w,h] or rotated [cx,cy,w,h,deg])
  bevflow train-detector train --coco my.json --init shared/bevflow/data/models/bevflow-person-centernet.onnx --out runs/c --lr 0.0005
                                                                         fine-tune the shipped model on your frames
  bevflow train-detector export --checkpoint runs/a/checkpoint.pt --out model.onnx
  bevflow evaluate --detector --model model.onnx --images data/eval --annotations data/eval/annotations.json
  bevflow train-detector quantize --model model.onnx --frames data/cal/annotations.json --out model-int8.onnx
                                                                         an INT8 copy, calibrated on other held-out frames
  bevflow train-detector set-threshold --model model.onnx --threshold 0.5
                                                                         the score it reports people from, kept in the file
                                                                         (evaluate --detector prints the best-F1 one)
  bevflow train-detector calibrate-scores --model tiles.onnx --annotations data/cal/annotations.json
                                                                         a rim-tile model's scores put on the general
                                                                         model's scale, kept in the file

Rendered crops are drawn at the detector's input scale (a person at the image centre ~20 px).
COCO images are scaled from their 'camera_height_m' and 'focal_px' keys when present, else by --scale.
Exit status: 0 on success, 2 for a usage or input error (message on stderr)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "train-detector",
        help="render data for, train, and export the overhead fisheye person detector",
        description="Build the person detector: render synthetic ceiling fisheye frames, train the small "
        "CenterNet-style network (needs torch: pip install 'bevflow[train]'), and export it to ONNX.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="step", metavar="STEP", required=True)
    render = sub.add_parser("render", help="render training crops into .npz shards")
    render.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder for the shards (resumes if it has some)")
    render.add_argument("--count", type=int, default=4000, metavar="N", help="number of samples (default 4000)")
    render.add_argument("--seed", type=int, default=1, metavar="N", help="random seed (default 1)")
    _heights_option(render, "e.g. 3 5 to fine-tune for low ceilings")
    _scene_options(render)
    render.add_argument("--zoom", type=float, default=1.0, metavar="Z",
                        help="render at Z x the detector's scale (default 1: a person at the image centre is 20 px across); "
                        "train with the same --zoom")  # fmt: skip
    render.set_defaults(func=_render)
    evalset = sub.add_parser("render-eval", help="render held-out whole frames with COCO annotations")
    evalset.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder for the PNG frames and annotations.json")
    evalset.add_argument("--count", type=int, default=100, metavar="N", help="number of frames (default 100)")
    evalset.add_argument("--seed", type=int, default=1000, metavar="N", help="random seed, unlike the training seed (default 1000)")
    evalset.add_argument("--frame-px", type=int, metavar="PX",
                         help="render each frame PX pixels across, as a camera delivers it (e.g. 2048), instead of "
                         "1-1.4 x the detector's scale (a few hundred pixels); the same scenes")  # fmt: skip
    _heights_option(evalset, "e.g. 3 5 for the cameras the rim tiles serve")
    _scene_options(evalset)
    evalset.set_defaults(func=_render_eval)
    train = sub.add_parser("train", help="train (or continue training) the detector")
    train.add_argument("--data", type=Path, metavar="DIR", help="rendered shards (from 'render')")
    train.add_argument("--coco", type=Path, metavar="FILE", help="your own annotated frames, COCO JSON")
    train.add_argument("--images", type=Path, metavar="DIR", help="folder of the COCO images (default: next to the JSON)")
    train.add_argument("--coco-fraction", type=float, default=0.5, metavar="F", help="share of each batch from --coco when both are given (default 0.5)")
    train.add_argument("--scale", type=float, default=1.0, metavar="F", help="resize factor for COCO images without camera_height_m/focal_px (default 1)")
    train.add_argument("--out", type=Path, required=True, metavar="DIR", help="folder for checkpoint.pt (training resumes from it)")
    train.add_argument("--init", type=Path, metavar="FILE",
                       help="start a new run from this exported .onnx model (e.g. the shipped one, to fine-tune it on your frames); default: random weights")  # fmt: skip
    train.add_argument("--steps", type=int, default=3000, metavar="N", help="total optimiser steps (default 3000)")
    train.add_argument("--batch", type=int, default=16, metavar="N", help="batch size (default 16)")
    train.add_argument("--crop", type=int, default=160, metavar="PX", help="training crop size, a multiple of 32 (default 160)")
    train.add_argument("--lr", type=float, default=2e-3, metavar="F", help="peak learning rate (default 0.002)")
    train.add_argument("--threads", type=int, default=1, metavar="N", help="CPU threads (default 1; more is slower on a busy machine)")
    train.add_argument("--seed", type=int, default=0, metavar="N", help="random seed (default 0)")
    train.add_argument("--zoom", type=float, default=1.0, metavar="Z",
                       help="the scale the shards were rendered at (render --zoom); COCO frames are resized to it, "
                       "and the exported model runs at it (default 1)")  # fmt: skip
    train.set_defaults(func=_train)
    export = sub.add_parser("export", help="write a checkpoint as one ONNX file (weights inside)")
    export.add_argument("--checkpoint", type=Path, required=True, metavar="FILE", help="checkpoint.pt from 'train'")
    export.add_argument("--out", type=Path, required=True, metavar="FILE", help="the .onnx file to write")
    export.set_defaults(func=_export)
    quantize = sub.add_parser("quantize", help="write an INT8 copy of a model, calibrated on frames (needs onnx)")
    quantize.add_argument("--model", type=Path, required=True, metavar="FILE", help="the .onnx model to quantise")
    quantize.add_argument("--frames", type=Path, required=True, metavar="FILE",
                          help="COCO JSON of calibration frames (e.g. from render-eval with its own seed)")
    quantize.add_argument("--count", type=int, default=32, metavar="N", help="frames to calibrate on, the first N (default 32)")
    quantize.add_argument("--out", type=Path, required=True, metavar="FILE", help="the INT8 .onnx file to write")
    quantize.set_defaults(func=_quantize)
    threshold = sub.add_parser("set-threshold", help="keep the score a model reports people from in its file (needs onnx)")
    threshold.add_argument("--model", type=Path, required=True, metavar="FILE", help="the .onnx model, changed in place")
    threshold.add_argument("--threshold", type=float, required=True, metavar="T",
                           help="0 to 1: the detector reports people scoring at least this unless told otherwise "
                           "(e.g. the best-F1 score evaluate --detector prints on frames of the model's cameras)")  # fmt: skip
    threshold.set_defaults(func=_set_threshold)
    calibrate = sub.add_parser("calibrate-scores", help="put a rim-tile model's scores on the general model's scale, "
                               "kept in its file (needs onnx)")  # fmt: skip
    calibrate.add_argument("--model", type=Path, required=True, metavar="FILE", help="the rim tiles' .onnx model, changed in place")
    calibrate.add_argument("--annotations", type=Path, required=True, metavar="FILE",
                           help="COCO JSON of held-out frames of mixed heights with their cameras' height and focal "
                           "length (render-eval with a seed of its own)")  # fmt: skip
    calibrate.add_argument("--images", type=Path, metavar="DIR", help="the frames' folder (default: beside the annotations)")
    calibrate.add_argument("--threads", type=int, default=2, metavar="N", help="detector threads (default 2)")
    calibrate.set_defaults(func=_calibrate_scores)


def _heights_option(parser: argparse.ArgumentParser, example: str) -> None:
    parser.add_argument("--heights", type=float, nargs=2, default=[3.0, 10.0], metavar=("LOW", "HIGH"),
                        help=f"camera mounting heights to draw from, metres (default 3 10; {example})")


def _heights(args: argparse.Namespace) -> tuple[float, float]:
    low, high = args.heights
    if not 2.0 <= low < high <= 20.0:
        raise UserError(f"--heights needs 2 <= LOW < HIGH <= 20 metres, got {low:g} {high:g}")
    return low, high


def _scene_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--groups", type=float, default=0.0, metavar="F",
                        help="share of the people standing in tight groups, queues and huddles 0.47-0.65 m apart, 0..1 (default 0)")
    parser.add_argument("--shifted-tiles", type=float, default=0.0, metavar="F",
                        help="share of the tiled floors whose grid is shifted off the camera, 0..1 (default 0: "
                        "two grout lines cross under it)")  # fmt: skip
    parser.add_argument("--squared", type=float, default=0.0, metavar="F",
                        help="share of the cameras mounted level and square to the room, 0..1 (default 0)")


def _mix(args: argparse.Namespace) -> SceneMix:
    from bevflow.training.dataset import SceneMix

    shares = {"--groups": args.groups, "--shifted-tiles": args.shifted_tiles, "--squared": args.squared}
    for name, value in shares.items():
        if not 0.0 <= value <= 1.0:
            raise UserError(f"{name} is a share, 0 to 1, got {value:g}")
    return SceneMix(*shares.values())


def _zoom(value: float) -> float:
    if not 0.5 <= value <= 2.0:
        raise UserError(f"--zoom is a multiple of the detector's scale, 0.5 to 2, got {value:g}")
    return value


def _count(value: int, name: str) -> int:
    if value <= 0:
        raise UserError(f"{name} must be positive, got {value}")
    return value


def _render(args: argparse.Namespace) -> int:
    from bevflow.training.dataset import render_dataset

    written = render_dataset(args.out, _count(args.count, "--count"), seed=args.seed, log=print, heights=_heights(args),
                             mix=_mix(args), zoom=_zoom(args.zoom))
    print(f"{written} new shards in {args.out}")
    return 0


def _render_eval(args: argparse.Namespace) -> int:
    from bevflow.training.dataset import render_evaluation_set

    if args.frame_px is not None and not 64 <= args.frame_px <= 8192:
        raise UserError(f"--frame-px must be 64 to 8192 pixels, got {args.frame_px}")
    path = render_evaluation_set(args.out, _count(args.count, "--count"), seed=args.seed, mix=_mix(args), heights=_heights(args),
                                 frame_px=args.frame_px)  # fmt: skip
    print(f"wrote {args.count} frames and {path}")
    return 0


def _train(args: argparse.Namespace) -> int:
    from bevflow.detect.coco import CocoError, read_coco
    from bevflow.training import train as train_mod  # torch: without the 'train' extra, `bevflow` names it

    if args.data is None and args.coco is None:
        raise UserError("give --data DIR (rendered shards), --coco FILE (your frames), or both")
    if args.crop % 32:
        raise UserError(f"--crop must be a multiple of 32, got {args.crop}")
    if args.data is not None and not any(args.data.glob("*.npz")):
        raise UserError(f"--data {args.data} holds no .npz shards (make them with 'bevflow train-detector render')")
    if args.init is not None and not args.init.is_file():
        raise UserError(f"--init {args.init}: no such model file")
    try:
        coco = read_coco(args.coco, args.images) if args.coco is not None else None
    except CocoError as exc:
        raise UserError(str(exc)) from None
    config = train_mod.TrainConfig(steps=_count(args.steps, "--steps"), batch=_count(args.batch, "--batch"), crop=args.crop,
                                   lr=args.lr, threads=_count(args.threads, "--threads"), seed=args.seed,
                                   zoom=_zoom(args.zoom))  # fmt: skip
    try:
        path = train_mod.train(args.data, args.out, config, log=lambda m: print(m, flush=True), coco=coco,
                               coco_fraction=args.coco_fraction, coco_scale=args.scale, init=args.init)  # fmt: skip
    except FileNotFoundError as exc:
        raise UserError(str(exc)) from None
    print(f"checkpoint: {path}")
    return 0


def _export(args: argparse.Namespace) -> int:
    from bevflow.training.export import export_onnx, load_checkpoint  # torch and onnx: the 'train' extra

    if not args.checkpoint.is_file():
        raise UserError(f"--checkpoint {args.checkpoint} does not exist")
    model, zoom = load_checkpoint(args.checkpoint)
    out = export_onnx(model, args.out, zoom=zoom)
    print(json.dumps({"model": str(out), "bytes": out.stat().st_size, "zoom": zoom}))
    return 0


def _quantize(args: argparse.Namespace) -> int:
    from bevflow.detect.coco import CocoError, read_coco
    from bevflow.training.quantize import quantize_detector  # onnx: the 'train' extra

    if not args.model.is_file():
        raise UserError(f"--model {args.model}: no such model file")
    try:
        frames = read_coco(args.frames)[: _count(args.count, "--count")]
    except CocoError as exc:
        raise UserError(str(exc)) from None
    if not frames:
        raise UserError(f"--frames {args.frames} has no frames to calibrate on")
    out = quantize_detector(args.model, frames, args.out)
    print(json.dumps({"model": str(out), "bytes": out.stat().st_size, "frames": len(frames)}))
    return 0


def _set_threshold(args: argparse.Namespace) -> int:
    from bevflow.training.metadata import set_score_threshold

    if not args.model.is_file():
        raise UserError(f"--model {args.model}: no such model file")
    if not (math.isfinite(args.threshold) and 0.0 < args.threshold < 1.0):
        raise UserError(f"--threshold must lie between 0 and 1, got {args.threshold:g}")
    try:
        set_score_threshold(args.model, args.threshold)
    except Exception as exc:  # onnx raises its own types for a file that is not a model
        raise UserError(f"cannot write the threshold into {args.model}: {exc}") from None
    print(f"{args.model}: reports people scoring at least {args.threshold:g}")
    return 0


def _calibrate_scores(args: argparse.Namespace) -> int:
    from bevflow.detect.runtime import DetectorError
    from bevflow.training.metadata import set_score_map
    from bevflow.training.score_calibration import calibrate_tile_scores

    for path, what in ((args.model, "model file"), (args.annotations, "annotation file")):
        if not path.is_file():
            raise UserError(f"no such {what}: {path}")
    if args.threads < 1:
        raise UserError(f"--threads must be >= 1, got {args.threads}")
    try:
        result = calibrate_tile_scores(args.model, args.annotations, args.images, args.threads)
    except (ValueError, FileNotFoundError, DetectorError) as exc:
        raise UserError(f"cannot calibrate {args.model}: {exc}") from None
    try:
        set_score_map(args.model, result.score_map)
    except Exception as exc:  # onnx raises its own types for a file that is not a model
        raise UserError(f"cannot write the score map into {args.model}: {exc}") from None
    print(json.dumps({"model": str(args.model), **result.as_dict()}))
    return 0


# `bevflow evaluate --detector --images DIR --annotations FILE` lives in its own module; these
# names stay importable from here for ``bevflow_services.cli.evaluate``.
from bevflow_services.cli.detector_evaluation import add_detector_arguments, run_detector_evaluation  # noqa: E402

__all__ = ["add_detector_arguments", "register", "run_detector_evaluation"]
