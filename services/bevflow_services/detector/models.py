"""Which detector model each camera uses: models are plugins named in the site file.

A camera's ``detector`` field names its model: the path of an ONNX file (relative paths are read
from the site file's folder) or the name of a model shipped with bevflow (``bevflow-person-
centernet``, the file name without ``.onnx``). A camera without one gets the model of its
mounting height from the site's ``detectors`` list of height ranges (the paper uses one model for
3–6 m and one for 6–10 m), e.g.

    detectors:
      - {min_height_m: 3, max_height_m: 6, model: models/low.onnx}
      - {min_height_m: 6, max_height_m: 10, model: models/high.onnx}

Without that list a camera under 5 m gets the rim tiles and one from 5 m the general model,
trained on renders from 3 to 10 m: its INT8 copy where the detector runs on a CPU with 8-bit
dot-product instructions, about twice as fast there (``bevflow.detect.runtime.ranges_for_host``).
Cameras that name the same file share one loaded model.

``detector: rim-tiles`` selects the rotation-aware detector for real frames of low ceilings
(``bevflow.detect.tiles``: rim tiles turned upright through a detector trained on photographs);
it finds far more people on real frames than the render-trained model, at many times its cost.
``rim-tiles:MODEL`` runs another model on the tiles, named as any model is (e.g.
``rim-tiles:yolox-nano-coco``, more accurate on real frames at about twice the time a frame).
Cameras asking for the same tile model share one rim-tile detector.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from bevflow.detect.providers import DEFAULT_PROVIDERS
from bevflow.detect.runtime import (
    DEFAULT_MODEL,
    Detector,
    DetectorBank,
    DetectorError,
    DetectorOptions,
    HeightRange,
    ranges_for_host,
)
from bevflow.detect.tiles import TILE_MODEL, RimTileDetector, is_rim_tiles, rim_tiles, rim_tiles_model
from bevflow.site import Site

SHIPPED_MODELS = DEFAULT_MODEL.parent
LABEL_MAX = 64  # characters of a metric label (bevflow.schemas.SeriesLabels)


def shipped_model_names() -> list[str]:
    return sorted(p.stem for p in SHIPPED_MODELS.glob("*.onnx"))


def resolve_model(name: str | Path, site_dir: Path | None = None) -> Path:
    """The ONNX file a site file's ``detector`` value names; ``DetectorError`` when none exists."""
    text = str(name)
    candidates = [Path(text).expanduser()]
    if site_dir is not None and not Path(text).is_absolute():
        candidates.insert(0, site_dir / text)
    candidates.append(SHIPPED_MODELS / (text if text.endswith(".onnx") else f"{text}.onnx"))
    for path in candidates:
        if path.is_file():
            return path
    shipped = ", ".join(shipped_model_names()) or "none"
    raise DetectorError(f"detector model {text!r} is neither an ONNX file nor a shipped model (shipped: {shipped})")


class CameraModels:
    """One ``Detector`` per camera of ``site`` (those in ``cameras``, default all), loaded when
    this is built so a bad model name fails at start-up, not on the first frame. ``default``
    overrides the height ranges for cameras that name no model; ``ranges`` (default: the site's
    ``detectors``, else the shipped ranges as this host runs them best,
    ``bevflow.detect.runtime.ranges_for_host``) choose by height."""

    def __init__(
        self,
        site: Site,
        cameras: Sequence[str] | None = None,
        *,
        site_dir: Path | None = None,
        default: str | Path | None = None,
        ranges: Sequence[HeightRange] | None = None,
        threads: int = 2,
        score_threshold: float | None = None,
        providers: Sequence[str] = DEFAULT_PROVIDERS,
        load: type[Detector] = Detector,
    ) -> None:
        options: DetectorOptions = {"score_threshold": score_threshold, "providers": providers}
        by_path: dict[tuple[Path, int], Detector] = {}
        tiles: dict[Path, RimTileDetector] = {}  # one rim-tile detector per tile model, for every camera asking for it

        def model(name: str | Path, n: int = threads) -> Detector:
            path = resolve_model(name, site_dir).resolve()
            if (path, n) not in by_path:
                by_path[path, n] = load(path, n, **options)
            return by_path[path, n]

        def named(name: str | Path) -> Detector | RimTileDetector:
            if is_rim_tiles(name):
                tile_model = tile_model_file(str(name), site_dir)
                if tile_model not in tiles:
                    tiles[tile_model] = rim_tiles(model, threads, tile_model)
                return tiles[tile_model]
            return model(name)

        if ranges is None:
            ranges = [HeightRange(r.min_height_m, r.max_height_m, r.model) for r in site.detectors or []] or ranges_for_host(providers)
        checked = DetectorBank(ranges).ranges  # sorted, refused if they overlap; loads nothing

        def for_height(height_m: float) -> Detector | RimTileDetector:
            for r in checked:
                if r.min_m <= height_m < r.max_m:
                    return named(r.model if r.model is not None else DEFAULT_MODEL)
            spans = ", ".join(f"[{r.min_m:g}, {r.max_m:g})" for r in checked)
            raise DetectorError(f"no detector model covers a camera {height_m:.2f} m high (ranges: {spans})")

        self.detectors: dict[str, Detector | RimTileDetector] = {}
        for config in site.cameras:
            if cameras is not None and config.id not in cameras:
                continue
            name = config.detector or default
            self.detectors[config.id] = named(name) if name is not None else for_height(config.height_m)

    def __getitem__(self, camera: str) -> Detector | RimTileDetector:
        return self.detectors[camera]

    def providers(self) -> list[str]:
        """The execution providers the loaded models run on (the first of each), for the start-up log."""
        return sorted({p for p in map(_provider, self.detectors.values()) if p is not None})

    def runs_on(self) -> dict[str, tuple[str, str]]:
        """Each camera's model name and the execution provider it runs on, for ``/api/health``
        and ``/metrics``."""
        models = self.models()
        return {c: (models[c][:LABEL_MAX], (_provider(d) or "unknown")[:LABEL_MAX]) for c, d in self.detectors.items()}

    def models(self) -> dict[str, str]:
        """The model file of each camera, for the start-up log."""
        return {c: d.name if isinstance(d, RimTileDetector) else d.model_path.name for c, d in self.detectors.items()}


def tile_model_file(name: str, site_dir: Path | None = None) -> Path:
    """The ONNX file a ``rim-tiles`` or ``rim-tiles:MODEL`` name runs on its tiles (MODEL found
    as ``resolve_model`` finds any); ``DetectorError`` where MODEL is missing or names no model."""
    try:
        tile_model = rim_tiles_model(name)
    except ValueError as e:
        raise DetectorError(str(e)) from None
    return TILE_MODEL if tile_model is None else resolve_model(tile_model, site_dir).resolve()


def _provider(detector: Detector | RimTileDetector) -> str | None:
    """The execution provider a camera's model runs on (the tile model's, for rim tiles); None
    for a stand-in that does not say."""
    session = detector.tile_detector if isinstance(detector, RimTileDetector) else detector
    providers = getattr(session, "providers", None)
    return str(providers[0]) if providers else None
