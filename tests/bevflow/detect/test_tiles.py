"""The rim-tile detector: tiles turned upright about the image centre, boxes mapped back at their
radial angle, cut boxes dropped and duplicates merged. A stand-in tile detector finds upright
bright blobs, as a detector trained on photographs finds upright people."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from bevflow.detect.coco import rotated_to_xyxy
from bevflow.detect.rotated import outline_xyxy, rotated_corners, rotated_iou_matrix
from bevflow.detect.tiles import (
    RIM_TILES,
    TILE_MODEL,
    RimTileDetector,
    TileLayout,
    is_rim_tiles,
    prefiltered,
    rim_tiles_model,
    rotated_nms,
)
from bevflow.detections import Boxes

RADIUS = 200.0
CENTRE = (219.5, 219.5)
FOCAL = RADIUS / math.radians(95)  # the detector takes the circle as f × the half view of 190°


ROOT = Path(__file__).resolve().parents[3]


class UprightBlobs:
    """Finds bright blobs taller than wide in a 128 × 128 tile."""

    fixed_hw = (128, 128)

    def __init__(self) -> None:
        self.calls: list[int] = []  # appended to, which is atomic: workers may call at once

    @property
    def tiles(self) -> int:
        return len(self.calls)

    def detect_scaled(self, tile: np.ndarray, scale: float = 1.0) -> Boxes:
        self.calls.append(1)
        count, _, stats, _ = cv2.connectedComponentsWithStats((tile.max(axis=2) > 100).astype(np.uint8))
        rows = [(x, y, x + w, y + h) for x, y, w, h, area in stats[1:count] if h > 1.3 * w and area > 4]
        return Boxes(np.array(rows, dtype=float).reshape(-1, 4), np.full(len(rows), 0.9))


def _frame(people: list[list[float]]) -> np.ndarray:
    frame = np.zeros((440, 440, 3), np.uint8)
    for corners in rotated_corners(np.array(people)):
        cv2.fillPoly(frame, [np.round(corners).astype(np.int32)], (200, 200, 200))
    return frame


def _radial_person(degrees: float, rho: float, w: float = 20.0, h: float = 60.0) -> list[float]:
    a = math.radians(degrees)
    return [CENTRE[0] - rho * math.sin(a), CENTRE[1] + rho * math.cos(a), w, h, degrees]


@pytest.mark.parametrize("degrees", [0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0, 20.0, 200.0, 290.0])
def test_a_person_lying_along_the_radius_is_found_once_with_its_angle(degrees: float) -> None:
    person = _radial_person(degrees, 110.0)
    tiles = UprightBlobs()
    rotated, conf = RimTileDetector(tiles).detect_rotated(_frame([person]), 3.0, FOCAL, CENTRE)
    assert tiles.tiles == 8
    assert len(rotated) == 1 and conf.tolist() == [0.9]
    # Between two tiles' angles the tile's upright box encloses the person turned by up to 22.5°;
    # the box comes back turned to the person's radial angle, its sides as the tile saw them.
    assert abs((rotated[0, 4] - degrees + 90) % 180 - 90) < 1.0
    assert rotated_iou_matrix(rotated, np.array([person]))[0, 0] > (0.8 if degrees % 45 == 0 else 0.4)


def test_people_all_round_are_each_found_and_their_outlines_are_returned_for_the_pipeline() -> None:
    people = [_radial_person(d, r) for d, r in [(10.0, 90.0), (100.0, 130.0), (190.0, 70.0), (280.0, 150.0)]]
    detector = RimTileDetector(UprightBlobs())
    rotated, conf = detector.detect_rotated(_frame(people), 3.0, FOCAL, CENTRE)
    assert (rotated_iou_matrix(rotated, np.array(people)).max(axis=0) > 0.4).all() and len(rotated) == 4
    boxes = detector.detect(_frame(people), 3.0, FOCAL, CENTRE)
    assert np.allclose(boxes.xyxy, outline_xyxy(rotated)) and np.array_equal(boxes.confidence, conf)


class CentreBoxes:
    """Stands in for the centre model: one upright box 30 × 45 px, 25 px right of and below the
    middle of what it is given (the centre of the frame), where the radial angle is 45°."""

    def detect(self, image_bgr: np.ndarray, camera_height_m: float, focal_px: float) -> Boxes:
        x, y = image_bgr.shape[1] / 2 + 25, image_bgr.shape[0] / 2 + 25
        return Boxes([[x - 15, y - 22.5, x + 15, y + 22.5]], [0.8])


def test_the_centre_model_keeps_its_own_box_and_tile_people_get_their_outline() -> None:
    person = _radial_person(45.0, 120.0)  # 45° off upright: its outline is well inside its enclosing box
    detector = RimTileDetector(UprightBlobs(), centre=CentreBoxes())  # type: ignore[arg-type]
    boxes, rotated = detector.detect_boxes(_frame([person]), 3.0, FOCAL, CENTRE)
    assert len(boxes) == len(rotated) == 2
    tile, centre = np.argsort(-np.hypot(rotated[:, 0] - CENTRE[0], rotated[:, 1] - CENTRE[1]))
    w, h = boxes.xyxy[centre, 2:] - boxes.xyxy[centre, :2]
    assert (w, h) == pytest.approx((30, 45))  # as the model gave it, not turned radially and back
    assert np.allclose(boxes.xyxy[tile], outline_xyxy(rotated[tile : tile + 1])[0])
    assert _area(boxes.xyxy[tile]) < 0.8 * _area(rotated_to_xyxy(rotated[tile : tile + 1])[0])


def _area(xyxy: np.ndarray) -> float:
    return float((xyxy[2] - xyxy[0]) * (xyxy[3] - xyxy[1]))


def test_a_sideways_blob_is_not_upright_in_any_tile() -> None:
    lying = _radial_person(0.0, 110.0, w=60.0, h=20.0)  # across the radius
    rotated, _ = RimTileDetector(UprightBlobs()).detect_rotated(_frame([lying]), 3.0, FOCAL, CENTRE)
    assert len(rotated) == 0


def test_layout_and_tile_detector_checks() -> None:
    assert TileLayout() == TileLayout(tiles=8, side_share=0.8, start_share=0.1, nms_iou=0.4)

    class Dynamic:
        fixed_hw = None

    with pytest.raises(ValueError, match="fixed square input"):
        RimTileDetector(Dynamic())


@pytest.mark.parametrize(
    ("boxes", "scores", "kept"),
    [
        ([[0, 0, 10, 20, 0], [1, 0, 10, 20, 0]], [0.5, 0.9], [1]),  # IoU 0.82: the better one stays
        ([[0, 0, 10, 20, 0], [0, 0, 10, 20, 90]], [0.9, 0.8], [0, 1]),  # a cross: IoU 1/3, both stay
        ([[0, 0, 10, 20, 0], [50, 0, 10, 20, 0], [0, 1, 10, 20, 180]], [0.7, 0.6, 0.8], [2, 1]),  # a half turn is the same box
    ],
)
def test_rotated_nms(boxes: list, scores: list, kept: list) -> None:
    assert rotated_nms(np.array(boxes, float), np.array(scores), 0.4).tolist() == kept


def test_the_shipped_tile_model_is_named() -> None:
    assert RIM_TILES == "rim-tiles" and TILE_MODEL.name == "fastestdet-tiles.onnx" and TILE_MODEL.is_file()
    for model in ("fastestdet-tiles", "fastestdet-coco", "yolox-nano-coco"):  # each ships under its own licence
        assert (TILE_MODEL.parent / f"LICENSE-{model}.txt").is_file() and f"{model}.onnx" in (ROOT / "NOTICE").read_text()


@pytest.mark.parametrize(
    ("name", "rim_tiles", "tile_model"),
    [
        ("rim-tiles", True, None),  # the shipped TILE_MODEL
        ("rim-tiles:yolox-nano-coco", True, "yolox-nano-coco"),
        ("rim-tiles:models/mine.onnx", True, "models/mine.onnx"),
        ("rim-tiles: yolox-nano-coco ", True, "yolox-nano-coco"),
        ("rim-tilesx", False, ValueError),
        ("bevflow-person-centernet", False, ValueError),
        (None, False, ValueError),
        ("rim-tiles:", True, ValueError),  # names no tile model
        ("rim-tiles: ", True, ValueError),
    ],
)
def test_a_model_name_asks_for_rim_tiles_and_names_their_model(name: str | None, rim_tiles: bool, tile_model: str | type | None) -> None:
    assert is_rim_tiles(name) is rim_tiles
    if tile_model is ValueError:
        with pytest.raises(ValueError, match="names no tile model|does not name the rim tiles"):
            rim_tiles_model(str(name))
    else:
        assert rim_tiles_model(str(name)) == tile_model


@pytest.mark.parametrize(("model", "name"), [(TILE_MODEL, "rim-tiles"), (TILE_MODEL.with_name("yolox-nano-coco.onnx"), "rim-tiles:yolox-nano-coco")])
def test_rim_tiles_say_how_a_site_file_names_them(model: Path, name: str) -> None:
    tiles = UprightBlobs()
    tiles.model_path = model  # type: ignore[attr-defined]
    assert RimTileDetector(tiles).name == name  # type: ignore[arg-type]


@pytest.mark.parametrize("workers", [2, 3, 8, 9])
def test_tiles_and_centre_shared_among_workers_find_what_one_worker_finds(workers: int) -> None:
    people = [_radial_person(d, r) for d, r in [(10.0, 90.0), (100.0, 130.0), (190.0, 70.0), (280.0, 150.0), (330.0, 120.0)]]
    one, shared = UprightBlobs(), UprightBlobs()
    expected = RimTileDetector(one, centre=CentreBoxes()).detect_rotated(_frame(people), 3.0, FOCAL, CENTRE)  # type: ignore[arg-type]
    found = RimTileDetector(shared, centre=CentreBoxes(), workers=workers).detect_rotated(_frame(people), 3.0, FOCAL, CENTRE)  # type: ignore[arg-type]
    assert shared.tiles == one.tiles == 8
    assert np.array_equal(found[0], expected[0]) and np.array_equal(found[1], expected[1]) and len(found[0]) == 6


def test_workers_must_be_at_least_one() -> None:
    with pytest.raises(ValueError, match="workers must be >= 1"):
        RimTileDetector(UprightBlobs(), workers=0)


class CentreModel:
    """Stands in for the centre model: its own scale, and what it was given."""

    def __init__(self, scale: float) -> None:
        self.scale = scale
        self.given: list[tuple[int, float]] = []

    def scale_for(self, camera_height_m: float, focal_px: float) -> float:
        return self.scale

    def detect(self, image_bgr: np.ndarray, camera_height_m: float, focal_px: float) -> Boxes:
        self.given.append((image_bgr.shape[1], focal_px))
        return Boxes.empty()


@pytest.mark.parametrize(
    ("centre_scale", "shrunk_by"),
    [
        (0.1, 0.5),  # the centre model shrinks further: it takes the frame halved, as the tiles do
        (0.9, 1.0),  # it would need more than the shrunk frame holds: the frame as it came
    ],
)
def test_the_centre_model_gets_the_shrunk_frame_only_where_it_shrinks_further(centre_scale: float, shrunk_by: float) -> None:
    frame = cv2.resize(_frame([]), (880, 880))  # a circle of 400 px: the 128 px tiles shrink it by 0.4, halved first
    centre = CentreModel(centre_scale)
    RimTileDetector(UprightBlobs(), centre=centre).detect_rotated(frame, 3.0, 2 * FOCAL, (439.5, 439.5))  # type: ignore[arg-type]
    [(width, focal)] = centre.given
    assert focal == pytest.approx(2 * FOCAL * shrunk_by) and width == pytest.approx(2 * 0.55 * 2 * RADIUS * shrunk_by, abs=3)


@pytest.mark.parametrize(
    ("k", "halvings", "smoothed"),
    [
        (1.0, 0, False),  # nothing to shrink: the frame as it came
        (0.8, 0, True),  # all of the shrink left to the warp: smoothed for it
        (0.5, 1, False),  # exactly halved: nothing left to the warp
        (0.3, 1, True),  # halved once, 0.6 left to the warp
        (0.2, 2, True),  # halved twice, 0.8 left
    ],
)
def test_a_frame_is_halved_as_far_as_it_goes_and_smoothed_where_the_warp_shrinks_the_rest(k: float, halvings: int, smoothed: bool) -> None:
    width = 2**halvings  # stripes this wide are one pixel wide once halved: what a shrinking warp would alias
    stripes = np.zeros((64, 64, 3), np.uint8)
    stripes[:, (np.arange(64) // width) % 2 == 1] = 255
    out = prefiltered(stripes, k)
    assert out.shape == (64 >> halvings, 64 >> halvings, 3) and out.dtype == np.uint8
    spread = int(out[:, 1:-1].max()) - int(out[:, 1:-1].min())
    assert spread == 255 if not smoothed else 100 < spread < 200  # σ 0.5 px keeps 0.79 of a pixel, spreads 0.21
