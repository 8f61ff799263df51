from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from bevflow.camera import FisheyeCamera
from bevflow.detect.confidence import ScoreMap
from bevflow.detect.cpu import int8_dot_product
from bevflow.detect.runtime import (
    DEFAULT_MODEL,
    DEFAULT_RANGES,
    INT8_MODEL,
    SCORE_THRESHOLD,
    Detector,
    DetectorBank,
    DetectorError,
    HeightRange,
    ranges_for_host,
)
from bevflow.detect.scaling import scale_factor, scaled_focal


class FakeCenterNet:
    """An ONNX-Runtime-like session that 'detects' one box centred on the input's brightest pixel,
    20 x 30 input pixels, and records what it was given."""

    def __init__(self, fixed_hw: tuple[int, int] | None = None, metadata: dict[str, str] | None = None) -> None:
        shape = [1, 3, *(fixed_hw or ("h", "w"))] if fixed_hw else ["batch", 3, "h", "w"]
        self.inputs = [SimpleNamespace(name="image", shape=shape)]
        self.metadata = metadata or {}
        self.seen: list[np.ndarray] = []

    def get_modelmeta(self):  # noqa: ANN201
        return SimpleNamespace(custom_metadata_map=self.metadata)

    def get_inputs(self):  # noqa: ANN201
        return self.inputs

    def get_outputs(self):  # noqa: ANN201
        return [SimpleNamespace(shape=["b", 1, "h", "w"])] * 3

    def run(self, _names, feeds):  # noqa: ANN001, ANN201
        x = feeds["image"]
        self.seen.append(x)
        b, _, h, w = x.shape
        heat = np.zeros((b, 1, h // 4, w // 4), np.float32)
        size = np.zeros((b, 2, h // 4, w // 4), np.float32)
        offset = np.zeros((b, 2, h // 4, w // 4), np.float32)
        for k in range(b):
            y, xx = np.unravel_index(x[k].sum(0).argmax(), (h, w))
            cy, cx = (y + 0.5) / 4, (xx + 0.5) / 4
            i, j = int(cy), int(cx)
            heat[k, 0, i, j] = 0.9
            size[k, :, i, j] = (20.0, 30.0)
            offset[k, :, i, j] = (cx - j, cy - i)
        return [heat, size, offset]


def _frame(w: int, h: int, bright: tuple[int, int]) -> np.ndarray:
    img = np.zeros((h, w, 3), np.uint8)
    img[bright[1], bright[0]] = 255
    return img


@pytest.mark.parametrize(
    ("height", "focal", "bright", "zoom"),
    [(3.3, 300.0, (400, 300), None), (8.1, 500.0, (123, 456), None), (5.5, 164.0, (50, 60), None),
     (3.3, 300.0, (400, 300), "1.2"), (8.1, 500.0, (123, 456), "0.8")],
)  # fmt: skip
def test_boxes_come_back_in_frame_pixels(height: float, focal: float, bright: tuple[int, int], zoom: str | None) -> None:
    """A model's ``bevflow.zoom`` metadata scales its input; boxes still map back to the frame."""
    fake = FakeCenterNet(metadata={"bevflow.zoom": zoom} if zoom else None)
    det = Detector(session=fake, score_threshold=0.5)
    boxes = det.detect(_frame(800, 600, bright), height, focal)
    s = scale_factor(height, focal) * float(zoom or 1)
    assert det.scale_for(height, focal) == pytest.approx(s)
    h, w = fake.seen[0].shape[2:]
    assert h % 32 == 0 and w % 32 == 0
    assert (w, h) == (-(-round(800 * s) // 32) * 32, -(-round(600 * s) // 32) * 32)
    (x0, y0, x1, y1), = boxes.xyxy
    # The centre maps back near the bright pixel (within one input pixel), the size by 1/s.
    assert abs((x0 + x1) / 2 - bright[0]) <= 1.0 / s + 0.5
    assert abs((y0 + y1) / 2 - bright[1]) <= 1.0 / s + 0.5
    assert (x1 - x0) == pytest.approx(20.0 / s, rel=0.02)
    assert (y1 - y0) == pytest.approx(30.0 / s, rel=0.02)


@pytest.mark.parametrize(("zoom", "message"), [("big", "'big' is not a number"), ("9", "9 is outside 0.25-4")])
def test_a_bad_zoom_in_the_model_file_is_a_clear_error(zoom: str, message: str) -> None:
    with pytest.raises(DetectorError, match=f"model metadata bevflow.zoom={message}"):
        Detector(session=FakeCenterNet(metadata={"bevflow.zoom": zoom}))


@pytest.mark.parametrize(
    ("metadata", "given", "used"),
    [(None, None, 0.4),  # no threshold in the file: SCORE_THRESHOLD
     ({"bevflow.score_threshold": "0.56"}, None, 0.56),  # the file's own
     ({"bevflow.score_threshold": "0.56"}, 0.05, 0.05),  # the caller's wins (an evaluation's floor, --score-threshold)
     ({"bevflow.zoom": "1.5"}, None, 0.4)],
)
def test_a_model_reports_from_its_own_threshold_unless_told(metadata: dict[str, str] | None, given: float | None, used: float) -> None:
    assert Detector(session=FakeCenterNet(metadata=metadata), score_threshold=given).score_threshold == used
    assert SCORE_THRESHOLD == 0.4


@pytest.mark.parametrize(("value", "message"), [("high", "'high' is not a number"), ("1.5", "1.5 is outside 0-1")])
def test_a_bad_threshold_in_the_model_file_is_a_clear_error(value: str, message: str) -> None:
    with pytest.raises(DetectorError, match=f"model metadata bevflow.score_threshold={message}"):
        Detector(session=FakeCenterNet(metadata={"bevflow.score_threshold": value}))


@pytest.mark.parametrize(
    ("metadata", "given_map", "threshold", "reported"),
    [(None, None, 0.4, 0.9),  # no map: the network's own score
     ({"bevflow.score_map": "0.5 -0.5"}, None, 0.4, 0.645),  # the file's map: σ(0.5 · logit(0.9) − 0.5)
     ({"bevflow.score_map": "0.5 -0.5"}, ScoreMap(), 0.4, 0.9),  # the caller's map wins (fitting one reads raw scores)
     ({"bevflow.score_map": "0.5 -0.5"}, None, 0.7, None)],  # the threshold is on the mapped scale: 0.645 < 0.7
)
def test_scores_are_reported_on_the_scale_the_model_file_maps_them_to(
    metadata: dict[str, str] | None, given_map: ScoreMap | None, threshold: float, reported: float | None
) -> None:
    detector = Detector(session=FakeCenterNet(metadata=metadata), score_threshold=threshold, score_map=given_map)
    boxes = detector.detect(_frame(64, 64, (30, 30)), 3.3, 300.0)
    assert boxes.confidence.tolist() == ([] if reported is None else [pytest.approx(reported, abs=1e-3)])


def test_a_bad_score_map_in_the_model_file_is_a_clear_error() -> None:
    with pytest.raises(DetectorError, match="model metadata bevflow.score_map: a score map is two numbers"):
        Detector(session=FakeCenterNet(metadata={"bevflow.score_map": "steep"}))


def test_the_shipped_tile_model_keeps_its_own_threshold_and_the_general_model_none() -> None:
    from bevflow.detect.tiles import TILE_MODEL

    tiles, general = Detector(TILE_MODEL, threads=1), Detector(DEFAULT_MODEL, threads=1)
    assert 0.3 < tiles.score_threshold < 0.5  # the best-F1 score on renders 3-5 m up (model card), on the general model's scale
    assert 0.5 < tiles.score_map.raw(tiles.score_threshold) < 0.6  # FastestDet's own score there
    assert general.score_threshold == SCORE_THRESHOLD and general.score_map.is_identity


def test_fixed_size_models_get_a_letterbox() -> None:
    fake = FakeCenterNet(fixed_hw=(320, 320))
    det = Detector(session=fake, score_threshold=0.5, model_format="centernet")
    frame = np.zeros((320, 640, 3), np.uint8)
    frame[198:202, 318:322] = 255  # a block: it stays brighter than the grey bars after the resize
    boxes = det.detect(frame, 3.3, 300.0)
    x = fake.seen[0]
    assert x.shape == (1, 3, 320, 320)
    assert x[0, :, 0, 0].tolist() == [114.0] * 3  # the grey bars above and below
    (x0, y0, x1, y1), = boxes.xyxy
    assert abs((x0 + x1) / 2 - 320) <= 2.5 and abs((y0 + y1) / 2 - 200) <= 2.5


def test_batch_matches_one_by_one() -> None:
    det = Detector(session=FakeCenterNet(), score_threshold=0.5)
    frames = [_frame(400, 400, (100, 200)), _frame(400, 400, (300, 50)), _frame(200, 300, (20, 30))]
    heights, focals = [3.3, 3.3, 6.0], [200.0, 200.0, 150.0]
    batch = det.detect_batch(frames, heights, focals)
    for f, h, fo, b in zip(frames, heights, focals, batch, strict=True):
        np.testing.assert_allclose(b.xyxy, det.detect(f, h, fo).xyxy)


def test_unknown_format_and_missing_model_are_clear_errors(tmp_path) -> None:  # noqa: ANN001
    with pytest.raises(DetectorError, match="unknown detector format"):
        Detector(session=FakeCenterNet(), model_format="ssd")
    with pytest.raises(DetectorError, match="does not exist"):
        Detector(tmp_path / "missing.onnx")


def test_bank_picks_the_model_by_height() -> None:
    bank = DetectorBank([HeightRange(6.0, 10.0, "high.onnx"), HeightRange(3.0, 6.0, "low.onnx")])
    assert [r.model for r in bank.ranges] == ["low.onnx", "high.onnx"]
    with pytest.raises(ValueError, match="no detector model covers"):
        bank.for_height(12.0)
    with pytest.raises(ValueError, match="overlap"):
        DetectorBank([HeightRange(3.0, 6.5), HeightRange(6.0, 10.0)])


@pytest.mark.skipif(not DEFAULT_MODEL.is_file(), reason="the shipped model is not in this checkout")
@pytest.mark.parametrize("height", [3.3, 6.0])
def test_shipped_model_finds_a_rendered_person(height: float) -> None:
    from bevflow.sim.bodies import BodyShape, pose_bodies
    from bevflow.sim.render import FisheyeRenderer, Room

    f = scaled_focal(height) * 1.2  # a frame a little larger than the detector's input
    size = int(math.ceil(2 * f * math.radians(92.5)))
    cam = FisheyeCamera.looking_down((0.0, 0.0, height), (size, size), 185.0)
    bodies = pose_bodies(BodyShape.standard(2), np.array([[1.0, 0.5], [-1.5, -1.0]]), np.zeros(2), np.zeros(2), np.zeros(2), np.ones(2, int))
    out = FisheyeRenderer(cam, Room((-8.0, -8.0, 8.0, 8.0))).render(bodies, np.array([1, 2]))
    found = Detector(threads=1).detect(out.image, height, cam.K[0, 0])
    for truth in out.boxes.xyxy:
        cx, cy = (truth[0] + truth[2]) / 2, (truth[1] + truth[3]) / 2
        centres = (found.xyxy[:, :2] + found.xyxy[:, 2:]) / 2
        assert np.hypot(*(centres - (cx, cy)).T).min() < 0.3 * max(truth[2] - truth[0], truth[3] - truth[1]) + 2


@pytest.mark.parametrize(
    ("providers", "int8_fast", "general"),
    [
        (["cpu"], True, INT8_MODEL),  # a CPU with 8-bit dot products: the INT8 copy, twice as fast there
        (["cpu"], False, None),  # without them it is slower: the float model
        (["cuda", "cpu"], True, None),  # an accelerator runs the float model
        (["CPU "], True, INT8_MODEL),
    ],
)
def test_the_host_gets_the_int8_general_model_only_on_a_cpu_that_pays(providers: list[str], int8_fast: bool,
                                                                       general: object) -> None:
    ranges = ranges_for_host(providers, int8_fast)
    assert [(r.min_m, r.max_m) for r in ranges] == [(r.min_m, r.max_m) for r in DEFAULT_RANGES]
    assert ranges[0] == DEFAULT_RANGES[0]  # the rim tiles under 5 m either way
    assert ranges[1].model == general


@pytest.mark.parametrize(
    ("cpuinfo", "expected"),
    [
        ("processor\t: 0\nflags\t\t: fpu avx2 avx512f avx512_vnni\n", True),
        ("flags\t\t: fpu avx2 avx_vnni\n", True),
        ("flags\t\t: fpu avx2 amx_tile amx_int8\n", True),
        ("flags\t\t: fpu sse4_2 avx2 fma\n", False),  # AVX2 alone: INT8 measured slower
        ("Features\t: fp asimd evtstrm asimddp\n", True),
        ("Features\t: fp asimd evtstrm\n", False),
        ("model name\t: avx512_vnni in a name is not a flag\n", False),
        ("", False),
    ],
)
def test_8_bit_dot_products_are_read_from_the_cpu_flags(cpuinfo: str, expected: bool) -> None:
    assert int8_dot_product(cpuinfo) is expected
