"""``bevflow evaluate --detections DIR``: recorded detector output replayed through the live
pipeline (``bevflow.evaluation.replay``) and scored against world truth.

Prints and writes (``--json OUT``) ``MODA``, ``MOTA``, ``IDF1``, ``HOTA``, ``DetA``, ``AssA``,
``IDSW``, ``precision``, ``recall``, ``APE``, ``frames`` of the online tracks as top-level keys,
then ``detection_MODA`` (each frame's fused cylinders before tracking), every score of the
online, settled and fused output under ``tracked``, ``settled`` and ``detection``, and where the
online tracks lose identities under ``identities`` (``bevflow.evaluation.identities``). With
``--perturb N``, also each headline score's mean, min and max over N perturbed copies of the
recording (``bevflow.evaluation.perturbed``) under ``perturbed``. With ``--ideal-noise M``, also
the tracker alone on the truth moved by M metres (``bevflow.evaluation.ideal``) under ``ideal``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from bevflow.datasets.mot import MIN_CONFIDENCE, RecordingError, read_detections, read_truth
from bevflow.datasets.wildtrack import FloorArea
from bevflow.evaluation.camera_errors import CameraError
from bevflow.evaluation.ideal import ideal_tracking
from bevflow.evaluation.identities import FLICKER_FRAMES, SHORT_FRAMES, IdentityBreakdown
from bevflow.evaluation.perturbed import BoxPerturbation, PerturbedReplays, perturbed_replays
from bevflow.evaluation.replay import SCORED, Everywhere, ReplayEvaluation, replay_tracking
from bevflow.evaluation.spread import Spread
from bevflow.site import Site, SiteError, Thresholds, load_site_or_builtin
from bevflow.tracking.tracker import TrackTable

from bevflow_services.runtime import UserError

EXAMPLE = """\
  bevflow evaluate --detections DIR --site site.yaml --truth truth.txt --fps 4 --area 1.5,0,6.2,3.41
      (DIR/<camera id>.txt: MOTChallenge rows frame,id,left,top,width,height,confidence,... per camera;
       truth.txt: frame,id,x,y in metres; frame f was taken at f / fps seconds)"""


def add_replay_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("replay of recorded detections (--detections DIR)")
    group.add_argument("--site", metavar="SITE", help="the site file of the cameras that recorded --detections")
    group.add_argument("--truth", type=Path, metavar="FILE", help="world truth, one line frame,id,x,y (metres on the floor)")
    group.add_argument("--fps", type=float, metavar="F", help="frames per second of the recording: frame f was taken at f / F seconds")
    group.add_argument("--area", metavar="XMIN,YMIN,XMAX,YMAX",
                       help="the floor rectangle (metres) the truth covers; tracks outside it that match nobody are "
                       "neither right nor wrong (default: the site's floor, else everywhere; write one starting with '-' "
                       "as --area=-3,-9,9,27)")
    group.add_argument("--min-confidence", type=float, default=MIN_CONFIDENCE, metavar="C",
                       help=f"use boxes of confidence C or more (default {MIN_CONFIDENCE:g}, the usual operating point of "
                       "a COCO person detector such as Faster R-CNN)")
    group.add_argument("--hypotheses", type=int, metavar="N",
                       help="hold N ways of matching tracks to people open for two seconds before deciding, instead of "
                       "the site's track_hypotheses (1: decide at every update)")
    mode = group.add_mutually_exclusive_group()
    mode.add_argument("--track-views", action="store_true",
                      help="let each track take its views from every camera, and fuse only the views left over (the "
                      "site's track_views true), instead of the site's own choice (by default: views where every "
                      "camera is a side view, else fused first)")
    mode.add_argument("--fuse-first", action="store_true",
                      help="fuse every view first and track the fused people (the site's track_views false), instead "
                      "of the site's own choice")
    group.add_argument("--tracks-out", type=Path, metavar="FILE", help="write the online tracks as frame,id,x,y lines")
    perturbation = BoxPerturbation()
    group.add_argument("--perturb", type=int, default=0, metavar="N",
                       help="also replay N perturbed copies of the recording (seeds 0..N-1) and print each score's mean, min "
                       "and max: how far a figure would move on another recording of the same scene (default 0: none)")
    group.add_argument("--perturb-drop", type=float, default=perturbation.drop, metavar="P",
                       help=f"in each copy, drop each box with probability P (default {perturbation.drop:g})")
    group.add_argument("--perturb-jitter", type=float, default=perturbation.jitter_px, metavar="PX",
                       help=f"in each copy, move each box edge by a normal error of PX pixels (default {perturbation.jitter_px:g})")
    group.add_argument("--ideal-noise", type=float, metavar="M",
                       help="also track the truth itself, each position moved by a normal error of M metres, with no "
                       "detector or fusion: what the tracker alone loses on this scene (over the --perturb N seeds, else one)")


def run_replay(args: argparse.Namespace) -> tuple[ReplayEvaluation, dict[str, Any]]:
    """Check the options, replay (and the ``--perturb`` copies and ``--ideal-noise`` runs), print
    the scores and write ``--tracks-out``; returns the replay and the JSON of the extra runs
    (``perturbed``, ``ideal``), which the caller writes to ``--json``."""
    for option in ("site", "truth", "fps"):
        if getattr(args, option) is None:
            raise UserError(f"--detections needs --{option} (see bevflow evaluate --help)")
    if not (math.isfinite(args.fps) and args.fps > 0):
        raise UserError(f"--fps must be a number of frames per second > 0, got {args.fps}")
    if not (math.isfinite(args.min_confidence) and args.min_confidence >= 0):
        raise UserError(f"--min-confidence must be a number >= 0, got {args.min_confidence}")
    perturbation = _perturbation(args)
    if args.ideal_noise is not None and not (math.isfinite(args.ideal_noise) and args.ideal_noise >= 0):
        raise UserError(f"--ideal-noise must be a number of metres >= 0, got {args.ideal_noise}")
    try:
        site = load_site_or_builtin(args.site)
    except SiteError as exc:
        raise UserError(str(exc)) from None
    if args.hypotheses is not None:
        site = with_hypotheses(site, args.hypotheses)
    if args.track_views or args.fuse_first:
        site = site.model_copy(update={"thresholds": site.thresholds.model_copy(update={"track_views": args.track_views})})
    area = parse_area(args.area, site)
    try:
        recording = read_detections(args.detections, {c.id: c.image_size for c in site.cameras})
        truth = read_truth(args.truth)
    except RecordingError as exc:
        raise UserError(str(exc)) from None
    if not truth.frame_numbers:
        raise UserError(f"{args.truth}: no truth rows, so nothing to score")
    try:
        result = replay_tracking(site, recording, truth, args.fps, area, min_confidence=args.min_confidence)
    except RecordingError as exc:
        raise UserError(str(exc)) from None
    print(format_replay(result, site))
    if args.tracks_out is not None:
        write_tracks(args.tracks_out, result.tracks)
    extra: dict[str, Any] = {}
    if args.perturb:
        spread = perturbed_replays(site, recording, truth, args.fps, args.perturb, perturbation, area, args.min_confidence)
        print(format_spread(spread))
        extra["perturbed"] = spread.as_dict()
    if args.ideal_noise is not None:
        runs = max(1, args.perturb)
        ideal = ideal_tracking(truth, args.fps, args.ideal_noise, result.tracker, runs, area)  # the replay's own settings
        print(format_spread_rows(f"the truth moved by {args.ideal_noise:g} m (σ), tracked alone, {runs} seed(s):", ideal))
        extra["ideal"] = {"noise_m": args.ideal_noise, "runs": runs, **{k: s.as_dict() for k, s in ideal.items()}}
    return result, extra


def with_hypotheses(site: Site, hypotheses: int) -> Site:
    """``site`` with its tracker holding ``hypotheses`` ways of matching open (``--hypotheses``)."""
    try:
        thresholds = Thresholds.model_validate({**site.thresholds.model_dump(), "track_hypotheses": hypotheses})
    except ValidationError as exc:
        raise UserError(f"--hypotheses must be a whole number from 1 to 100, got {hypotheses}") from exc
    return site.model_copy(update={"thresholds": thresholds})


def _perturbation(args: argparse.Namespace) -> BoxPerturbation:
    if args.perturb < 0:
        raise UserError(f"--perturb must be a number of copies >= 0, got {args.perturb}")
    try:
        return BoxPerturbation(drop=args.perturb_drop, jitter_px=args.perturb_jitter)
    except ValueError as exc:
        raise UserError(f"--perturb-drop, --perturb-jitter: {exc}") from None


def parse_area(text: str | None, site: Site) -> FloorArea | Everywhere:
    if text is None:
        if site.floor is None:
            return Everywhere()
        x0, y0, x1, y1 = site.floor
        return FloorArea(x_min=x0, x_max=x1, y_min=y0, y_max=y1)
    try:
        x0, y0, x1, y1 = (float(v) for v in text.split(","))
    except ValueError:
        raise UserError(f"--area must be four numbers XMIN,YMIN,XMAX,YMAX in metres, got {text!r}") from None
    if not (all(map(math.isfinite, (x0, y0, x1, y1))) and x1 > x0 and y1 > y0):
        raise UserError(f"--area needs XMAX > XMIN and YMAX > YMIN, got {text!r}")
    return FloorArea(x_min=x0, x_max=x1, y_min=y0, y_max=y1)


def write_tracks(path: Path, tracks: tuple[tuple[int, TrackTable], ...]) -> None:
    lines = [f"{frame},{i},{x:.4f},{y:.4f}" for frame, table in tracks
             for i, (x, y) in zip(table.id.tolist(), table.xy.tolist(), strict=True)]
    try:
        path.write_text("".join(line + "\n" for line in lines))
    except OSError as exc:
        raise UserError(f"cannot write {path}: {exc.strerror or exc}") from None


def format_replay(r: ReplayEvaluation, site: Site) -> str:
    c = r.tracker
    head = (f"{site.site}: {len(site.cameras)} cameras, frames {r.frame_numbers[0]}..{r.frame_numbers[-1]} at {r.fps:g} fps, "
            f"boxes of confidence >= {r.min_confidence:g}, matched within {r.threshold_m:g} m; tracker: "
            f"{c.activate_hits} hits to confirm, {c.max_misses} misses to drop, gate {c.gate_m:g} m"
            + ("" if c.gate_chi2 is None else f" and chi2 {c.gate_chi2:g} of the prediction")
            + ("" if c.hypotheses == 1 else f", {c.hypotheses} hypotheses over {c.hypothesis_window_s:g} s")
            + (", each camera's views matched to the tracks" if c.track_views else ", views fused before tracking")
            + (" (every camera looks from the side)" if c.track_views and site.thresholds.track_views is None else ""))
    columns = f"{'':<9} {'MODA':>6} {'MOTA':>6} {'IDF1':>6} {'HOTA':>6} {'DetA':>6} {'AssA':>6} {'IDSW':>5} {'prec':>6} {'recall':>6} {'APE m':>6} {'frames':>6}"
    rows = [head, columns]
    for name, s, h in (("online", r.scores, r.hota), ("settled", r.settled, r.settled_hota)):
        rows.append(f"{name:<9} {_num(s.MODA)} {_num(s.MOTA)} {_num(s.IDF1)} {_num(h.HOTA)} {_num(h.DetA)} {_num(h.AssA)} "
                    f"{s.IDSW:>5} {_num(s.precision)} {_num(s.recall)} {_num(s.APE)} {s.frames:>6}")
    d = r.detection
    rows.append(f"{'fused':<9} {_num(d.MODA)} {'':>41} {_num(d.precision)} {_num(d.recall)} {_num(d.APE)} {d.frames:>6}")
    late = "one update late" if c.hypotheses == 1 else f"as decided {c.hypothesis_window_s:g} s later, then one update late"
    rows.append(f"online: the tracks as the live tracker publishes them; settled: {late}; "
                "fused: each frame's fused detections before tracking")
    return "\n".join([*rows, format_identities(r.identities), *format_camera_errors(r.cameras)])


def format_identities(b: IdentityBreakdown) -> str:
    """Where the online tracks lose identities, in one sentence (``bevflow.evaluation.identities``)."""
    def pct(count: int) -> str:
        return f"{100 * b.share(count):.1f} %"

    return (f"identities: of {b.person_frames} person-frames, {pct(b.main)} under each person's main id, {pct(b.unmatched)} "
            f"followed by no track; under another id {pct(b.flicker)} for 1-{FLICKER_FRAMES} frames, {pct(b.short)} for "
            f"{FLICKER_FRAMES + 1}-{SHORT_FRAMES}, {pct(b.long_fresh + b.long_taken)} for longer ({pct(b.long_fresh)} a track "
            f"that followed nobody else before, {pct(b.long_taken)} one that had followed someone else)")


def format_camera_errors(cameras: tuple[CameraError, ...]) -> list[str]:
    """Each camera's views against the truth, a row each (``bevflow.evaluation.camera_errors``)."""
    rows = ["each camera's views against the truth (mean ± spread; bearing + anticlockwise, range + beyond, "
            "lag: the views show people that much later):",
            f"{'camera':<12} {'views':>6} {'bearing mrad':>15} {'range m':>15} {'lag s':>7}"]
    for c in cameras:
        lag = f"{'-':>7}" if c.lag_s is None else f"{c.lag_s:>+7.3f}"
        rows.append(f"{c.camera_id:<12} {c.views:>6} {c.across_mrad:>+7.1f} ± {c.across_spread_mrad:<5.1f} "
                    f"{c.along_m:>+7.3f} ± {c.along_spread_m:<5.3f} {lag}")
    return rows


_SHORT = {"precision": "prec", "APE": "APE m"}  # the column heads of format_replay


def format_spread(p: PerturbedReplays) -> str:
    """Each headline score's mean, min and max over the perturbed copies, one row each."""
    title = (f"{p.runs} perturbed copies (each box dropped with probability {p.perturbation.drop:g}, each edge moved "
             f"{p.perturbation.jitter_px:g} px σ), online tracks:")
    return format_spread_rows(title, p.scores)


def format_spread_rows(title: str, scores: dict[str, Spread]) -> str:
    """``title``, then each headline score's mean, min and max over several runs, one row each."""
    rows = [title, f"{'':<9}" + "".join(f" {_SHORT.get(k, k):>6}" for k in SCORED)]
    for name, field in (("mean", "mean"), ("min", "low"), ("max", "high")):
        values = [getattr(scores[k], field) for k in SCORED]
        rows.append(f"{name:<9}" + "".join(f" {v:>6.1f}" if k == "IDSW" else f" {_num(v)}" for k, v in zip(SCORED, values, strict=True)))
    return "\n".join(rows)


def _num(x: float) -> str:
    return f"{'-':>6}" if math.isnan(x) else f"{x:>6.3f}"
