from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import cv2
import pytest

from bevflow.datasets.mot import read_detections, read_truth
from bevflow.datasets.wildtrack import ANNOTATED_AREA, WildtrackDataset
from bevflow.evaluation.replay import HEADLINE, replay_tracking
from bevflow.evaluation.wildtrack_tracking import WILDTRACK_TRACKER, evaluate_tracking
from bevflow.site import load_site
from tests.bevflow.evaluation.test_wildtrack_tracking import PERFECT, walkers

WILDTRACK_FPS = 2.0  # annotated frames 0, 5, 10, ... are 0.5 s apart: recording frames 0, 1, 2, ...


def write_recording(dataset: WildtrackDataset, folder: Path) -> tuple[Path, Path, Path]:
    """``dataset`` in the replay's layout: a site file of its cameras, DIR/<camera>.txt with every
    annotated box (confidence 1, as the noise model gives them) and the floor truth, its annotated
    frames numbered 0, 1, 2, ..."""
    cameras = []
    for name, cam in zip(dataset.camera_ids, dataset.cameras, strict=True):
        K = cam.K
        cameras.append({
            "id": name, "model": "pinhole", "image_size": list(cam.image_size),
            "intrinsics": {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]},
            "distortion": cam.dist.tolist(),
            "extrinsics": {"rvec": cv2.Rodrigues(cam.R)[0].ravel().tolist(), "tvec": cam.t.tolist()},
        })
    site = folder / "site.json"
    site.write_text(json.dumps({"site": "wildtrack", "cameras": cameras}))
    detections = folder / "detections"
    detections.mkdir()
    rows: dict[str, list[str]] = {name: [] for name in dataset.camera_ids}
    truth = []
    for k, frame in enumerate(dataset.frames):
        for name, view in zip(dataset.camera_ids, frame.views, strict=True):
            rows[name] += [f"{k},-1,{x0!r},{y0!r},{x1 - x0!r},{y1 - y0!r},1.0,-1,-1,-1" for x0, y0, x1, y1 in view.boxes.xyxy.tolist()]
        truth += [f"{k},{i},{x!r},{y!r}" for i, (x, y) in zip(frame.person_ids.tolist(), frame.feet_xy.tolist(), strict=True)]
    for name, lines in rows.items():
        (detections / f"{name}.txt").write_text("\n".join(lines) + "\n")
    (folder / "truth.txt").write_text("\n".join(truth) + "\n")
    return site, detections, folder / "truth.txt"


def replay(folder: Path, **options: object):  # noqa: ANN201
    site_path, detections, truth = folder / "site.json", folder / "detections", folder / "truth.txt"
    site = load_site(site_path)
    recording = read_detections(detections, {c.id: c.image_size for c in site.cameras})
    return replay_tracking(site, recording, read_truth(truth), WILDTRACK_FPS, **options)


@pytest.mark.parametrize("dataset", [walkers(0.7), walkers(0.3, hidden=None), walkers(1.0, ghost=None)])
def test_a_wildtrack_recording_replayed_scores_as_the_wildtrack_evaluation(dataset, tmp_path: Path) -> None:
    write_recording(dataset, tmp_path)
    expected = evaluate_tracking(dataset, WILDTRACK_TRACKER, noise=PERFECT, clip_to_image=True)
    got = replay(tmp_path, area=ANNOTATED_AREA, tracker=WILDTRACK_TRACKER)
    assert got.scores.as_dict() == pytest.approx(expected.scores.as_dict())
    assert got.settled.as_dict() == pytest.approx(expected.settled.as_dict())
    assert got.detection.as_dict() == pytest.approx(expected.detection.scores.as_dict())
    assert got.scores.frames == len(dataset.frames) and got.tracker == WILDTRACK_TRACKER


def test_the_site_tracker_settings_follow_the_frame_rate_by_default(tmp_path: Path) -> None:
    write_recording(walkers(0.7), tmp_path)
    result = replay(tmp_path)
    assert result.tracker.activate_hits == 3 and result.fps == WILDTRACK_FPS  # the site's defaults
    d = result.as_dict()
    assert set(HEADLINE) <= d.keys() and d["HOTA"] == result.hota.HOTA and d["detection_MODA"] == result.detection.MODA
    assert {"HOTA", "LocA", "MOTA"} <= d["settled"].keys() and d["tracked"]["IDSW"] == d["IDSW"]


def test_weak_boxes_are_left_out_and_frames_without_boxes_are_scored(tmp_path: Path) -> None:
    write_recording(walkers(0.7, hidden=None, ghost=None), tmp_path)
    everything = replay(tmp_path, tracker=WILDTRACK_TRACKER)
    camera = tmp_path / "detections" / "CVLab1.txt"
    camera.write_text(camera.read_text().replace(",1.0,-1", ",0.2,-1"))  # one camera's boxes all weak
    one_camera = replay(tmp_path, tracker=WILDTRACK_TRACKER, min_confidence=0.5)
    assert everything.detection.tp == one_camera.detection.tp == 3 * 8  # the other camera sees everyone
    assert one_camera.detection.APE > everything.detection.APE  # but alone places them less well
    assert replay(tmp_path, tracker=WILDTRACK_TRACKER, min_confidence=0.2).detection == everything.detection
    assert replay(tmp_path, tracker=WILDTRACK_TRACKER).detection == one_camera.detection  # the command's 0.5
    # nobody seen in frames 0 and 1: still scored, as misses
    for name in ("CVLab1", "CVLab2"):
        path = tmp_path / "detections" / f"{name}.txt"
        path.write_text("".join(line + "\n" for line in path.read_text().splitlines() if not line.startswith(("0,", "1,"))))
    late = replay(tmp_path, tracker=WILDTRACK_TRACKER)
    assert late.frame_numbers == tuple(range(8)) and late.scores.frames == 8
    assert (late.detection.tp, late.detection.fn) == (3 * 6, 3 * 2) and late.scores.fn >= 3 * 2


def test_hypotheses_are_scored_online_and_once_final(tmp_path: Path) -> None:
    """With several hypotheses the settled output is built from the updates the tracker made
    final (``HypothesisTracker.final``): every frame once. On clean boxes nothing is in doubt, so
    both outputs score as the plain tracker's do."""
    write_recording(walkers(0.7), tmp_path)
    plain = replay(tmp_path, area=ANNOTATED_AREA)
    held = replay(tmp_path, area=ANNOTATED_AREA, tracker=replace(plain.tracker, hypotheses=10))
    assert held.tracker.hypotheses == 10 and held.settled.frames == held.scores.frames == 8
    assert held.scores.as_dict() == pytest.approx(plain.scores.as_dict())
    assert held.settled.as_dict() == pytest.approx(plain.settled.as_dict())
