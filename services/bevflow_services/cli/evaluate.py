"""``bevflow evaluate``: detection accuracy of the projection + fusion pipeline on annotated data.

The dataset's annotated boxes stand in for a detector; ``--jitter``, ``--drop`` and
``--false-positives`` make them as imperfect as a real one (exact definitions in
``bevflow.sim.noise``), and the fused floor positions are scored against ground truth within
0.5 m. JSON output (``--json OUT``): one object per method with the top-level keys ``method``,
``frames``, ``MODA``, ``MODP``, ``precision``, ``recall``, ``F1``, ``APE`` (plus counts and
per-camera details); with ``--method all`` the file holds a list of those objects, one per
method, in the order cylinder, bbox-center, nearest-point. A ratio with nothing to divide by (e.g.
precision when nothing was found) is written as null.

The fused detections are also tracked (``bevflow.evaluation.wildtrack_tracking``: the world
tracker with real frame times, 0.5 s apart on WILDTRACK) and each object gains the tracking scores
``MOTA``, ``MOTP``, ``IDF1``, ``IDP``, ``IDR``, ``IDSW``, ``MT``, ``PT``, ``ML``, ``FRAG``,
``FRAG_ratio`` as top-level keys, ``tracked_MODA`` and the tracked output's detection scores under
``tracked``, and the same for the tracks settled one update late under ``settled``
(``bevflow.tracking.settled``). The top-level ``MODA``, ``precision``, ... stay those of the
per-frame fused detections.

``--suite NAME`` runs a simulated suite instead (``bevflow.evaluation.suite``: tracking scores per
sequence, camera set and method); noise options left out keep the suite's own defaults. With
``--detector`` the suite renders every camera's frames and runs the shipped person detector on
them instead of the noise model (``bevflow.evaluation.rendered``; slow: add ``--frames-scale``).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from bevflow.cylinder import METHODS, projection_method
from bevflow.datasets.wildtrack import WildtrackError, load_wildtrack
from bevflow.evaluation.detection import DetectionEvaluation, evaluate_detection
from bevflow.evaluation.wildtrack_tracking import TrackingEvaluation, evaluate_tracking
from bevflow.sim.noise import DetectorNoise
from bevflow_services.cli.evaluate_replay import EXAMPLE as REPLAY_EXAMPLE
from bevflow_services.cli.evaluate_replay import add_replay_arguments, run_replay
from bevflow_services.cli.train_detector import add_detector_arguments, run_detector_evaluation
from bevflow_services.runtime import UserError

DATASETS = ("wildtrack",)

EPILOG = """\
examples:
  bevflow evaluate --dataset wildtrack --root /data/Wildtrack
  bevflow evaluate --dataset wildtrack --root /data/Wildtrack --jitter 0.02 --drop 0.1 --method all --json results.json
  bevflow evaluate --dataset wildtrack --root /data/Wildtrack --frames 0:50     (the first 50 annotated frames)
  bevflow evaluate --suite paper --json suite.json     (the paper's Tables 2 and 3 on simulated sequences; add --frames-scale 0.03 for a quick run)
  bevflow evaluate --suite paper --detector --frames-scale 0.05     (the same on rendered frames through the shipped detector)
""" + REPLAY_EXAMPLE + """

--frames takes a Python slice over the annotated frames sorted by frame number, not frame numbers:
  0:50 = the first 50, 150: = from the 151st to the end, ::2 = every other one,
  --frames=-10: = the last 10 (write a slice that starts with '-' with '=').
Only estimates inside the dataset's annotated area are scored (WILDTRACK: the 12 m x 36 m grid).
The same --seed gives the same noise for a frame whatever --frames selects.
Exit status: 0 on success, 2 for a usage or input error (message on stderr)."""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "evaluate",
        help="measure detection accuracy (MODA, precision, recall, position error) on annotated data",
        description="Run the camera-to-floor projection and multi-camera fusion on an annotated dataset "
        "and report how well the people found on the floor match the ground truth.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--dataset", choices=DATASETS, help="a public dataset read from --root")
    source.add_argument("--suite", metavar="NAME", help="a built-in simulated suite: 'paper' runs every Table 1 sequence, camera set and projection method (--method does not apply) and prints the paper's Tables 2 and 3")
    source.add_argument("--images", type=Path, metavar="DIR", help="with --detector: a folder of frames annotated by --annotations (COCO JSON); reports AP50, precision, recall, F1")
    source.add_argument("--detections", type=Path, metavar="DIR", help="a recording of any detector's boxes, one DIR/<camera id>.txt per camera of --site, replayed through the live pipeline and tracked; reports MOTA, IDF1, HOTA, ... against --truth")
    parser.add_argument("--frames-scale", type=float, metavar="F", help="--suite only: shorten every sequence to F x its frames, e.g. 0.1 for a quick run (default 1)")
    parser.add_argument("--jobs", type=int, metavar="N", help="--suite only: sequences simulated in parallel (default: one per CPU core)")
    parser.add_argument("--root", type=Path, metavar="DIR", help="the dataset folder (for WILDTRACK: the one holding calibrations/ and annotations_positions/)")
    parser.add_argument("--frames", default=":", metavar="A:B", help="which annotated frames, as a Python slice over them in order (default: all)")
    parser.add_argument("--jitter", type=float, metavar="F", help="move each box edge by Gaussian noise of F x the box width/height (default 0; a suite has its own)")
    parser.add_argument("--drop", type=float, metavar="F", help="lose each box with probability F, 0..1 (default 0; a suite has its own)")
    parser.add_argument("--false-positives", type=float, metavar="F", help="add on average F spurious boxes per camera per frame (default 0; a suite has its own)")
    parser.add_argument("--no-truncation", action="store_true", help="do not cut the lower part of boxes hidden behind nearer people")
    parser.add_argument("--clip-to-image", action="store_true", help="clip boxes to the image as a real detector's are (dataset boxes may reach past the border)")
    parser.add_argument("--seed", type=int, default=0, metavar="N", help="random seed of the noise (default 0)")
    parser.add_argument("--method", choices=(*METHODS, "all"), default="cylinder", help="how a box becomes a floor position (default: cylinder)")
    parser.add_argument("--fusion-distance", type=float, default=0.45, metavar="M", help="merge cylinders of different cameras closer than M metres (default 0.45, the paper's)")
    parser.add_argument("--json", type=Path, metavar="OUT", help="also write the results to this JSON file")
    add_detector_arguments(parser)
    add_replay_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.images is not None:
        return run_detector_evaluation(args)
    if args.detections is not None:
        replayed, extra = run_replay(args)
        if args.json is not None:
            _write_json(args.json, replayed.as_dict() | extra)
        return 0
    methods = list(METHODS) if args.method == "all" else [args.method]
    if args.suite is not None:
        return _run_suite(args, methods)
    results = _run_dataset(args, _noise(args, DetectorNoise()), methods)
    print(format_table([r.detection for r in results]))
    print()
    print(format_tracking_table(results))
    if args.json is not None:
        _write_json(args.json, [r.as_dict() for r in results] if args.method == "all" else results[0].as_dict())
    return 0


def _write_json(path: Path, payload: object) -> None:
    try:
        path.write_text(json.dumps(_finite(payload), indent=2, allow_nan=False) + "\n")
    except OSError as exc:
        raise UserError(f"cannot write {path}: {exc.strerror or exc}") from None


def _finite(value: object) -> object:
    """NaN (a ratio with nothing to divide by, e.g. precision with no estimates) becomes null: strict JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    return value


def _noise(args: argparse.Namespace, defaults: DetectorNoise) -> DetectorNoise:
    """The noise the options ask for; options left out keep ``defaults``."""
    if args.seed < 0:
        raise UserError(f"--seed must be 0 or more, got {args.seed}")
    chosen = {"jitter": args.jitter, "drop": args.drop, "false_positives": args.false_positives}
    try:
        return DetectorNoise(
            **{k: getattr(defaults, k) if v is None else v for k, v in chosen.items()},
            truncation=defaults.truncation and not args.no_truncation,
        )
    except ValueError as exc:
        option = next(k for k in ("false_positives", "jitter", "drop") if str(exc).startswith(k))
        raise UserError(str(exc).replace(option, "--" + option.replace("_", "-"), 1)) from None


def parse_frame_slice(text: str) -> slice:
    """'A:B' or 'A:B:C' with optional parts, as in Python; raises UserError otherwise."""
    parts = text.strip().split(":")
    if len(parts) not in (2, 3):
        raise UserError(f"--frames must look like A:B (a slice such as 0:50 or 100:), got {text!r}")
    try:
        start, stop, *step = (int(p) if p.strip() else None for p in parts)
    except ValueError:
        raise UserError(f"--frames must hold whole numbers, like 0:50, got {text!r}") from None
    if step and step[0] == 0:
        raise UserError(f"--frames step cannot be zero, got {text!r}")
    return slice(start, stop, step[0] if step else None)


def _run_dataset(args: argparse.Namespace, noise: DetectorNoise, methods: list[str]) -> list[TrackingEvaluation]:
    if args.root is None:
        raise UserError(f"--dataset {args.dataset} needs --root DIR (the dataset folder)")
    if not (math.isfinite(args.fusion_distance) and args.fusion_distance > 0):
        raise UserError(f"--fusion-distance must be a distance in metres > 0, got {args.fusion_distance}")
    frames = parse_frame_slice(args.frames)
    try:
        dataset = load_wildtrack(args.root)
    except WildtrackError as exc:
        raise UserError(str(exc)) from None
    if not dataset.frames[frames]:
        raise UserError(f"--frames {args.frames} selects none of the {len(dataset.frames)} annotated frames")
    return [
        evaluate_tracking(dataset, detection=evaluate_detection(
            dataset, method=projection_method(m), noise=noise, seed=args.seed, frames=frames, fusion_distance_m=args.fusion_distance,
            clip_to_image=args.clip_to_image))
        for m in methods
    ]


def _run_suite(args: argparse.Namespace, methods: list[str]) -> int:
    """Hand over to the simulated suites (``bevflow.evaluation.suite``), which track as well.
    A suite runs every projection method whatever ``methods`` says (its Table 3 compares them)."""
    from bevflow.evaluation import suite, tables  # here: the other commands start without them
    if args.root is not None or args.frames != ":" or args.fusion_distance != 0.45 or args.clip_to_image:
        raise UserError("--root, --frames, --fusion-distance and --clip-to-image apply to --dataset only")
    scale = 1.0 if args.frames_scale is None else args.frames_scale
    if not (math.isfinite(scale) and scale > 0):
        raise UserError(f"--frames-scale must be a number > 0, got {args.frames_scale}")
    if args.jobs is not None and args.jobs < 1:
        raise UserError(f"--jobs must be 1 or more, got {args.jobs}")
    if args.detector and (args.jitter is not None or args.drop is not None or args.false_positives is not None):
        raise UserError("--suite --detector takes its boxes from the detector: drop --jitter, --drop and --false-positives")
    if args.model is not None and not args.detector:
        raise UserError("--model needs --detector (the suite's boxes come from the noise model otherwise)")
    if args.model is not None and not Path(args.model).is_file():
        raise UserError(f"--model {args.model}: no such file")
    noise = _noise(args, suite.DEFAULT_NOISE)
    try:
        result = suite.run_suite(
            args.suite, frames_scale=scale, noise=noise, seed=args.seed, processes=args.jobs or suite.default_processes(),
            detector=args.detector, model=args.model,
        )
    except ValueError as exc:
        raise UserError(str(exc)) from None
    print(tables.format_suite(result))
    if args.json is not None:
        _write_json(args.json, result.as_dict())
    return 0


def format_table(results: list[DetectionEvaluation]) -> str:
    """The headline numbers, one row per method, then the per-camera counts of the first run."""
    first = results[0]
    n = first.noise
    lines = [
        f"{len(first.frame_numbers)} frames, noise: jitter {n.jitter:g}, drop {n.drop:g}, "
        f"false positives {n.false_positives:g}, truncation {'on' if n.truncation else 'off'}, seed {first.seed}, "
        f"fusion {first.fusion_distance_m:g} m, boxes {'clipped to the image' if first.clip_to_image else 'as annotated'}",
        f"{'method':<14} {'MODA':>6} {'MODP':>6} {'prec':>6} {'recall':>6} {'F1':>6} {'APE m':>6} {'TP':>6} {'FP':>6} {'FN':>6}",
    ]
    for r in results:
        s = r.scores
        lines.append(
            f"{r.method:<14} {_num(s.MODA)} {_num(s.MODP)} {_num(s.precision)} {_num(s.recall)} {_num(s.F1)} {_num(s.APE)} "
            f"{s.tp:>6} {s.fp:>6} {s.fn:>6}"
        )
    for r in results:
        lines += ["", f"per camera ({r.method}; 'alone' = that camera's estimates vs the people it sees):",
                  f"{'camera':<10} {'boxes':>6} {'dets':>6} {'drop':>5} {'trunc':>5} {'FP':>4} {'clip':>5} {'dupl':>5} {'unpl':>5} {'out':>5} "
                  f"{'prec':>6} {'recall':>6} {'APE m':>6}"]
        for c in r.per_camera:
            a = c.alone
            lines.append(
                f"{c.camera_id:<10} {c.boxes:>6} {c.detections:>6} {c.dropped:>5} {c.truncated:>5} {c.false_positives:>4} {c.clipped:>5} "
                f"{c.duplicates:>5} {c.unplaced:>5} {c.outside_area:>5} {_num(a.precision)} {_num(a.recall)} {_num(a.APE)}"
            )
    return "\n".join(lines)


def format_tracking_table(results: list[TrackingEvaluation]) -> str:
    """Two rows per method, the online tracked output's scores and those of the tracks settled one
    update late, next to the per-frame detections' MODA."""
    first = results[0]
    c = first.tracker
    lines = [
        f"tracked ({c.activate_hits} hits to confirm, {c.max_misses} misses to drop, "
        f"frame f at f x {first.seconds_per_frame_number:g} s; 'det MODA' = the per-frame fused detections):",
        f"{'method':<14} {'MOTA':>6} {'IDF1':>6} {'IDSW':>5} {'MT':>4} {'PT':>4} {'ML':>4} {'FRAG':>5} "
        f"{'MODA':>6} {'det MODA':>8} {'prec':>6} {'recall':>6} {'APE m':>6}",
    ]
    for r in results:
        for name, s in ((r.detection.method, r.scores), ("  settled", r.settled)):
            lines.append(
                f"{name:<14} {_num(s.MOTA)} {_num(s.IDF1)} {s.IDSW:>5} {s.MT:>4} {s.PT:>4} {s.ML:>4} {s.FRAG:>5} "
                f"{_num(s.MODA)} {_num(r.detection.scores.MODA):>8} {_num(s.precision)} {_num(s.recall)} {_num(s.APE)}"
            )
    lines.append("settled: the same tracks one update late, a new track's first frame and a missed frame "
                 "bridged by the next one reported (for what is read after the fact; live alerts cannot wait)")
    return "\n".join(lines)


def _num(x: float) -> str:
    return f"{'-':>6}" if math.isnan(x) else f"{x:>6.3f}"
