from __future__ import annotations

from pathlib import Path

import pytest

from bevflow.detect.runtime import (
    DEFAULT_MODEL,
    DEFAULT_RANGES,
    INT8_MODEL,
    LOW_CEILING_MODEL,
    RENDER_TRAINED_RANGES,
    Detector,
    DetectorBank,
    DetectorError,
    HeightRange,
)
from bevflow.detect.tiles import TILE_MODEL, RimTileDetector
from bevflow.site import SiteError, parse_site

from bevflow_services.detector.models import CameraModels, resolve_model, shipped_model_names

SITE = """
site: hall
cameras:
  - {id: low, image_size: [800, 800], intrinsics: {fx: 250, fy: 250, cx: 399.5, cy: 399.5}, pose: {position: [0, 0, 3.5]}}
  - {id: high, image_size: [800, 800], intrinsics: {fx: 250, fy: 250, cx: 399.5, cy: 399.5}, pose: {position: [5, 0, 8.0]}}
  - {id: own, image_size: [800, 800], intrinsics: {fx: 250, fy: 250, cx: 399.5, cy: 399.5}, pose: {position: [9, 0, 4.0]}, detector: %s}
"""


class FakeDetector:
    """Stands in for ``Detector``: remembers what it was built with."""

    fixed_hw = (352, 352)  # as the rim-tile model has

    def __init__(self, path: Path, threads: int, **options: object) -> None:
        self.model_path, self.threads, self.options = Path(path), threads, options


@pytest.mark.parametrize("model", [DEFAULT_MODEL, INT8_MODEL])
def test_a_shipped_model_is_found_by_name(model: Path) -> None:
    assert model.stem in shipped_model_names()
    assert resolve_model(model.stem) == model
    assert resolve_model(model.name) == model


@pytest.mark.parametrize("relative", [True, False])
def test_a_model_file_is_found_by_path_or_next_to_the_site_file(tmp_path: Path, relative: bool) -> None:
    model = tmp_path / "models" / "mine.onnx"
    model.parent.mkdir()
    model.write_bytes(b"onnx")
    name = "models/mine.onnx" if relative else str(model)
    assert resolve_model(name, site_dir=tmp_path) == model


def test_an_unknown_model_names_the_shipped_ones(tmp_path: Path) -> None:
    with pytest.raises(DetectorError, match=f"'nope'.*shipped: .*{DEFAULT_MODEL.stem}"):
        resolve_model("nope", site_dir=tmp_path)


def test_cameras_get_their_own_model_or_the_one_for_their_height(tmp_path: Path) -> None:
    own = tmp_path / "own.onnx"
    own.write_bytes(b"onnx")
    site = parse_site(SITE % "own.onnx")
    models = CameraModels(site, site_dir=tmp_path, threads=3, score_threshold=0.6, providers=["cuda", "cpu"],
                          load=FakeDetector)
    assert models["own"].model_path == own.resolve()
    assert models["own"].threads == 3
    assert models["own"].options == {"score_threshold": 0.6, "providers": ["cuda", "cpu"]}
    # Cameras naming no model: the height ranges (by default rim tiles under 5 m, the general
    # model above).
    low = models["low"]
    assert isinstance(low, RimTileDetector) and low.tile_detector.model_path == TILE_MODEL
    assert models["high"].model_path == DEFAULT_MODEL
    assert models.models() == {"low": "rim-tiles", "high": DEFAULT_MODEL.name, "own": "own.onnx"}


def test_cameras_naming_the_same_file_share_one_loaded_model(tmp_path: Path) -> None:
    model = tmp_path / "m.onnx"
    model.write_bytes(b"onnx")
    site = parse_site(SITE % "m.onnx")
    models = CameraModels(site, site_dir=tmp_path, default=str(model), load=FakeDetector)
    assert models["low"] is models["high"] is models["own"]


def test_only_the_served_cameras_load_and_a_bad_name_fails_at_start_up(tmp_path: Path) -> None:
    site = parse_site(SITE % "missing-model")
    models = CameraModels(site, ["low"], site_dir=tmp_path, load=FakeDetector)
    assert list(models.detectors) == ["low"]
    with pytest.raises(DetectorError, match="missing-model"):
        CameraModels(site, site_dir=tmp_path, load=FakeDetector)


def test_height_ranges_choose_the_model_of_cameras_that_name_none(tmp_path: Path) -> None:
    low, high = tmp_path / "low.onnx", tmp_path / "high.onnx"
    low.write_bytes(b"onnx")
    high.write_bytes(b"onnx")
    site = parse_site(SITE % "null")
    ranges = [HeightRange(6.0, 10.0, high), HeightRange(3.0, 6.0, low)]
    models = CameraModels(site, ranges=ranges, load=FakeDetector)
    assert models.models() == {"low": "low.onnx", "high": "high.onnx", "own": "low.onnx"}
    with pytest.raises(DetectorError, match="no detector model covers a camera 8.00 m high"):
        CameraModels(site, ranges=[HeightRange(3.0, 6.0, low)], load=FakeDetector)


def test_the_site_files_height_table_chooses_by_height(tmp_path: Path) -> None:
    for name in ("low.onnx", "high.onnx"):
        (tmp_path / name).write_bytes(b"onnx")
    text = (SITE % "null") + """
detectors:
  - {min_height_m: 3, max_height_m: 6, model: low.onnx}
  - {min_height_m: 6, max_height_m: 10, model: high.onnx}
"""
    models = CameraModels(parse_site(text), site_dir=tmp_path, load=FakeDetector)
    assert models.models() == {"low": "low.onnx", "high": "high.onnx", "own": "low.onnx"}


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ("[{min_height_m: 3, max_height_m: 7, model: a}, {min_height_m: 6, max_height_m: 10, model: b}]", "overlap"),
        ("[{min_height_m: 6, max_height_m: 6, model: a}]", "must be below"),
        ("[{max_height_m: 6}]", "model"),
    ],
)
def test_bad_height_tables_are_refused_when_the_site_is_read(table: str, message: str) -> None:
    from bevflow.site import SiteError

    with pytest.raises(SiteError, match=message):
        parse_site((SITE % "null") + f"detectors: {table}\n")


@pytest.mark.parametrize(("height_m", "tiles"), [(3.3, True), (4.99, True), (5.0, False), (8.1, False)])
def test_by_default_low_ceilings_get_rim_tiles_and_the_rest_the_general_model(height_m: float, tiles: bool) -> None:
    assert TILE_MODEL.is_file() and DEFAULT_MODEL.is_file()
    detector = DetectorBank(DEFAULT_RANGES, threads=1).for_height(height_m)
    if tiles:
        assert isinstance(detector, RimTileDetector) and detector.tile_detector.model_path == TILE_MODEL
    else:
        assert isinstance(detector, Detector) and detector.model_path == DEFAULT_MODEL


@pytest.mark.parametrize(("height_m", "model"), [(3.3, LOW_CEILING_MODEL), (4.99, LOW_CEILING_MODEL), (5.0, DEFAULT_MODEL)])
def test_the_render_trained_pair_splits_at_five_metres(height_m: float, model: Path) -> None:
    detector = DetectorBank(RENDER_TRAINED_RANGES, threads=1).for_height(height_m)
    assert isinstance(detector, Detector) and detector.model_path == model


class FakeTileDetector(FakeDetector):
    fixed_hw = (416, 416)
    providers = ["OpenVINOExecutionProvider", "CPUExecutionProvider"]


def test_rim_tiles_names_the_rotation_aware_detector_shared_by_the_cameras_asking_for_it(tmp_path: Path) -> None:
    from bevflow.detect.tiles import TILE_MODEL, RimTileDetector

    site = parse_site(SITE % "rim-tiles")
    models = CameraModels(site, site_dir=tmp_path, default="rim-tiles", load=FakeTileDetector)
    assert isinstance(models["own"], RimTileDetector) and models["own"] is models["low"]
    assert models["own"].tile_detector.model_path == TILE_MODEL
    assert models["own"].centre.model_path == DEFAULT_MODEL.resolve()
    assert models.models()["own"] == "rim-tiles"
    assert models.runs_on()["own"] == ("rim-tiles", "OpenVINOExecutionProvider")  # the provider actually used


def test_rim_tiles_with_another_tile_model_are_a_detector_of_their_own(tmp_path: Path) -> None:
    site = parse_site((SITE % "rim-tiles:yolox-nano-coco") + "detectors: [{min_height_m: 0, max_height_m: 100, model: rim-tiles}]\n")
    models = CameraModels(site, site_dir=tmp_path, load=FakeTileDetector)
    assert isinstance(models["own"], RimTileDetector) and models["low"] is models["high"] is not models["own"]
    assert models["own"].tile_detector.model_path == TILE_MODEL.with_name("yolox-nano-coco.onnx")
    assert models["own"].centre is models["low"].centre  # one general model under both
    assert models.models() == {"low": "rim-tiles", "high": "rim-tiles", "own": "rim-tiles:yolox-nano-coco"}


@pytest.mark.parametrize(
    ("name", "message"),
    [("rim-tiles:nope", "detector model 'nope' is neither an ONNX file nor a shipped model"),
     ("'rim-tiles:'", "'rim-tiles:' names no tile model: write rim-tiles:MODEL")],
)
def test_rim_tiles_with_no_such_tile_model_fail_at_start(tmp_path: Path, name: str, message: str) -> None:
    with pytest.raises(DetectorError, match=message):
        CameraModels(parse_site(SITE % name), site_dir=tmp_path, load=FakeTileDetector)


@pytest.mark.parametrize(
    ("line", "expected"),
    [("", ["cpu"]), ("detector_providers: [OpenVINO, cpu]\n", ["openvino", "cpu"]),
     ("detector_providers: [tensorrt, cuda, cpu]\n", ["tensorrt", "cuda", "cpu"])],
)
def test_the_site_file_names_the_providers(line: str, expected: list[str]) -> None:
    assert parse_site(line + SITE % "null").detector_providers == expected


@pytest.mark.parametrize("line", ["detector_providers: [gpu]\n", "detector_providers: []\n"])
def test_an_unknown_provider_is_refused_when_the_site_is_read(line: str) -> None:
    with pytest.raises(SiteError, match="detector_providers.*choose from tensorrt, cuda, openvino, cpu"):
        parse_site(line + SITE % "null")


@pytest.mark.parametrize(
    ("table", "low", "high"),
    [("[{min_height_m: 0, max_height_m: 5, model: bevflow-person-centernet-low.onnx}, "
      "{min_height_m: 5, max_height_m: 100, model: bevflow-person-centernet.onnx}]", LOW_CEILING_MODEL.name, DEFAULT_MODEL.name),
     ("[{min_height_m: 0, max_height_m: 100, model: rim-tiles}]", "rim-tiles", "rim-tiles")],
)
def test_a_site_height_table_names_the_render_trained_pair_or_rim_tiles(table: str, low: str, high: str) -> None:
    """What docs/INSTALL.md ("Which detector model") shows a site file doing."""
    site = parse_site((SITE % "null") + f"detectors: {table}\n")
    models = CameraModels(site, load=FakeDetector).models()
    assert (models["low"], models["high"]) == (low, high)


@pytest.mark.parametrize(("providers", "int8_fast", "high"), [(["cpu"], True, INT8_MODEL), (["cpu"], False, DEFAULT_MODEL),
                                                              (["openvino", "cpu"], True, DEFAULT_MODEL)])
def test_a_site_without_a_height_table_gets_the_int8_general_model_where_the_cpu_makes_it_pay(
        monkeypatch: pytest.MonkeyPatch, providers: list[str], int8_fast: bool, high: Path) -> None:
    from bevflow.detect import runtime

    monkeypatch.setattr(runtime, "int8_dot_product", lambda: int8_fast)
    models = CameraModels(parse_site(SITE % "rim-tiles"), providers=providers, load=FakeDetector)  # type: ignore[arg-type]
    assert models["high"].model_path == high
    assert models.models()["high"] == high.name  # as the start-up line and /api/health say
