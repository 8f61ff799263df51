"""The person detector at run time: ONNX Runtime, height-adaptive scaling, decoding, NMS.

``Detector(model_path, threads).detect(image_bgr, camera_height_m, focal_px)`` resizes the frame
so a person at the image centre is about 20 px across (``bevflow.detect.scaling``), runs the
model, decodes its outputs (``bevflow.detect.decoders``) and returns ``Boxes`` in the ORIGINAL
frame's pixels. Models with a dynamic input size get the scaled frame padded to a multiple of 32
at the bottom and right; models with a fixed input size (most YOLO exports) get it letterboxed
(scaled to fit, grey padding). ``detect_batch`` runs several cameras' frames in one call where
their padded sizes match (cameras at the same height), which amortises the per-call overhead.

``DetectorBank`` picks a model by mounting height (the paper uses one for 3–6 m and one for
6–10 m): a list of ``HeightRange(min_m, max_m, model)``.

>>> det = Detector()  # the shipped model, 2 threads  # doctest: +SKIP
>>> boxes = det.detect(frame, camera_height_m=3.3, focal_px=326.0)  # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import functools
import io
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, TypedDict, Unpack

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.detect.confidence import SCORE_MAP_METADATA_KEY, ScoreMap
from bevflow.detect.cpu import int8_dot_product
from bevflow.detect.decoders import FORMATS, decode_centernet, decode_fastestdet, decode_yolov5, decode_yolov8, decode_yolox, guess_format
from bevflow.detect.providers import DEFAULT_PROVIDERS, check_providers, plan_providers
from bevflow.detect.rotated import radial_boxes
from bevflow.detect.scaling import scale_factor
from bevflow.detect.tiles import RIM_TILES, RimTileDetector, is_rim_tiles, load_rim_tiles, rim_tiles_model
from bevflow.detections import SAME_PERSON_IOU, Boxes, nms

_log = logging.getLogger(__name__)
FloatArray = NDArray[np.float64]
DEFAULT_MODEL = Path(__file__).resolve().parent.parent / "data" / "models" / "bevflow-person-centernet.onnx"
PAD_MULTIPLE = 32
SCORE_THRESHOLD = 0.4
"""The lowest confidence of a person a model reports live unless its file names its own
(``SCORE_THRESHOLD_METADATA_KEY``); evaluations score every box down to a lower floor."""
LETTERBOX_GREY = 114


class ModelPort(Protocol):
    """One of a model's inputs or outputs as ONNX Runtime describes it: a dimension is a number
    when fixed, a name or None when dynamic."""

    @property
    def name(self) -> str: ...
    @property
    def shape(self) -> Sequence[int | str | None]: ...


class InferenceSession(Protocol):
    """What the detector uses of an ONNX Runtime session: tests, or a session built with other
    execution providers, can stand in for it."""

    def get_inputs(self) -> Sequence[ModelPort]: ...
    def get_outputs(self) -> Sequence[ModelPort]: ...
    def run(self, output_names: list[str] | None, input_feed: dict[str, NDArray[Any]]) -> list[NDArray[Any]]: ...


class DetectorError(RuntimeError):
    """A model file that cannot be loaded or understood; the message says why."""


@dataclass(frozen=True)
class PreparedInput:
    """A frame made ready for the model: the tensor (1, 3, H, W) float32 and how to map boxes
    in the model's input pixels back to the frame: frame = (model − pad) / scale, with the
    half-pixel shift of pixel-centre coordinates."""

    tensor: NDArray[np.float32]
    scale: float
    pad: tuple[float, float]


ZOOM_METADATA_KEY = "bevflow.zoom"
"""ONNX metadata: the model's input scale as a multiple of ``bevflow.detect.scaling``'s (a model
trained on renders at ``render --zoom 1.2`` sees a person at the image centre 24 px across)."""
SCORE_THRESHOLD_METADATA_KEY = "bevflow.score_threshold"
"""ONNX metadata: the model's own reporting threshold. Scores of different networks mean
different things (FastestDet's are objectness^0.6 · class^0.4, the project's model's heatmap
peaks), so one number does not suit them all. Written by ``bevflow train-detector set-threshold``."""


class Detector:
    """One ONNX person detector. ``model_format`` is one of ``decoders.FORMATS`` or "auto";
    ``rgb`` and ``input_scale`` say what the model expects (defaults: BGR 0–255 for the
    project's model and YOLOX, RGB 0–1 for YOLOv5/v8, BGR 0–1 for FastestDet). ``zoom``: the frame is resized to this
    multiple of the height-adaptive scale, read from the model file (``ZOOM_METADATA_KEY``,
    default 1). Scores are reported on the general model's scale: the file's ``ScoreMap``
    (``bevflow.detect.confidence``) maps the network's own onto it, unless ``score_map`` is given.
    ``score_threshold``: the lowest (mapped) score reported; None takes the model file's own
    (``SCORE_THRESHOLD_METADATA_KEY``), else ``SCORE_THRESHOLD``."""

    def __init__(
        self,
        model_path: str | Path | None = None,
        threads: int = 2,
        score_threshold: float | None = None,
        nms_iou: float = SAME_PERSON_IOU,
        model_format: str = "auto",
        person_class: int = 0,
        rgb: bool | None = None,
        input_scale: float | None = None,
        session: InferenceSession | None = None,
        providers: Sequence[str] = DEFAULT_PROVIDERS,
        score_map: ScoreMap | None = None,
    ) -> None:
        self.model_path = Path(model_path) if model_path is not None else DEFAULT_MODEL
        # ``session``: anything with ONNX Runtime's get_inputs / get_outputs / run (tests, or a
        # session built elsewhere).
        self.session = session if session is not None else _load_session(self.model_path, threads, providers)
        used = getattr(self.session, "get_providers", None)  # test doubles may have none
        self.providers: list[str] = list(used()) if used is not None else []
        inp = self.session.get_inputs()[0]
        self.input_name = inp.name
        h, w = inp.shape[2], inp.shape[3]
        self.fixed_hw = (h, w) if isinstance(h, int) and isinstance(w, int) else None
        shapes = [o.shape for o in self.session.get_outputs()]
        if model_format == "auto":
            model_format = guess_format(shapes, self.fixed_hw or (640, 640))
        if model_format not in FORMATS:
            raise DetectorError(f"unknown detector format {model_format!r}; choose one of: auto, {', '.join(FORMATS)}")
        self.format = model_format
        yolo_like = model_format in ("yolov5", "yolov8")
        self.rgb = yolo_like if rgb is None else rgb
        unit_range = yolo_like or model_format == "fastestdet"  # FastestDet: BGR / 255
        self.input_scale = (1 / 255.0 if unit_range else 1.0) if input_scale is None else input_scale
        self.nms_iou, self.person_class = nms_iou, person_class
        self.zoom = _model_zoom(self.session)
        self.score_threshold = _model_score_threshold(self.session) if score_threshold is None else score_threshold
        self.score_map = _model_score_map(self.session) if score_map is None else score_map

    # --- public API ----------------------------------------------------------------------------
    def detect(self, image_bgr: NDArray[np.uint8], camera_height_m: float, focal_px: float) -> Boxes:
        """Person boxes in ``image_bgr`` (H, W, 3) of a camera ``camera_height_m`` above the floor
        whose focal length is ``focal_px`` (px/rad, K[0, 0] of its calibration)."""
        return self.detect_scaled(image_bgr, self.scale_for(camera_height_m, focal_px))

    def scale_for(self, camera_height_m: float, focal_px: float) -> float:
        """The resize factor from a frame of this camera to the model's input."""
        return scale_factor(camera_height_m, focal_px) * self.zoom

    def detect_scaled(self, image_bgr: NDArray[np.uint8], scale: float = 1.0) -> Boxes:
        """As ``detect``, with the resize factor given directly (1.0: the frame is already at
        the detector's scale, e.g. rendered for it)."""
        prepared = self.prepare(image_bgr, scale)
        outputs = self.session.run(None, {self.input_name: prepared.tensor})
        return self._boxes(outputs, 0, prepared, prepared.tensor.shape[2:])

    def detect_batch(self, images: Sequence[NDArray[np.uint8]], heights_m: Sequence[float], focals_px: Sequence[float]) -> list[Boxes]:
        """``detect`` for several frames; frames whose model inputs have the same size share one
        inference call (only for models with a dynamic batch axis)."""
        return self.detect_batch_scaled(images, [self.scale_for(h, f) for h, f in zip(heights_m, focals_px, strict=True)])

    def detect_batch_scaled(self, images: Sequence[NDArray[np.uint8]], scales: Sequence[float]) -> list[Boxes]:
        """``detect_scaled`` for several images, batched as ``detect_batch`` does."""
        prepared = [self.prepare(im, s) for im, s in zip(images, scales, strict=True)]
        out: list[Boxes | None] = [None] * len(prepared)
        groups: dict[tuple[int, ...], list[int]] = {}
        batched = not isinstance(self.session.get_inputs()[0].shape[0], int)
        for i, p in enumerate(prepared):
            groups.setdefault(p.tensor.shape if batched else (i,), []).append(i)
        for members in groups.values():
            tensor = np.concatenate([prepared[i].tensor for i in members])
            outputs = self.session.run(None, {self.input_name: tensor})
            for k, i in enumerate(members):
                out[i] = self._boxes(outputs, k, prepared[i], tensor.shape[2:])
        return [b if b is not None else Boxes.empty() for b in out]

    def prepare(self, image_bgr: NDArray[np.uint8], scale: float) -> PreparedInput:
        """Resize (and pad or letterbox) a frame into the model's input tensor."""
        image = np.asarray(image_bgr)
        if image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"expected an (H, W, 3) BGR image, got shape {image.shape}")
        h, w = image.shape[:2]
        if self.fixed_hw is not None:  # letterbox: fit inside, keep the aspect ratio
            scale = min(self.fixed_hw[0] / h, self.fixed_hw[1] / w)
            th, tw = self.fixed_hw
        sw, sh = max(int(round(w * scale)), 1), max(int(round(h * scale)), 1)
        if (sw, sh) != (w, h):
            interpolation = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
            image = np.asarray(cv2.resize(image, (sw, sh), interpolation=interpolation), dtype=np.uint8)
        if self.fixed_hw is None:
            th, tw = -(-sh // PAD_MULTIPLE) * PAD_MULTIPLE, -(-sw // PAD_MULTIPLE) * PAD_MULTIPLE
            pad, fill = (0, 0), 0
        else:
            pad, fill = ((tw - sw) // 2, (th - sh) // 2), LETTERBOX_GREY
        if (th, tw) == (sh, sw):  # already the input's size (a rim tile): nothing to pad
            canvas = image
        else:
            canvas = np.full((th, tw, 3), fill, dtype=np.uint8)
            canvas[pad[1] : pad[1] + sh, pad[0] : pad[0] + sw] = image
        if self.rgb:
            canvas = canvas[..., ::-1]
        tensor = np.ascontiguousarray(canvas.transpose(2, 0, 1)[None], dtype=np.float32)
        if self.input_scale != 1.0:
            tensor *= np.float32(self.input_scale)
        # The resize factor actually applied per axis is sw / w; use the mean (they differ < 1 px).
        return PreparedInput(tensor, 0.5 * (sw / w + sh / h), (float(pad[0]), float(pad[1])))

    # --- decoding -------------------------------------------------------------------------------
    def _boxes(self, outputs: list[np.ndarray], k: int, prepared: PreparedInput, input_hw: tuple[int, ...]) -> Boxes:
        one = [o[k : k + 1] for o in outputs]
        thr = self.score_map.raw(self.score_threshold)  # decoders keep raw scores from this up
        if self.format == "centernet":
            xyxy, scores = decode_centernet(one[0], one[1], one[2], thr)
        elif self.format == "yolov5":
            xyxy, scores = decode_yolov5(one[0][0], thr, self.person_class)
        elif self.format == "yolov8":
            xyxy, scores = decode_yolov8(one[0][0], thr, self.person_class)
        elif self.format == "fastestdet":
            xyxy, scores = decode_fastestdet(one[0][0], (int(input_hw[0]), int(input_hw[1])), thr, self.person_class)
        else:
            xyxy, scores = decode_yolox(one[0][0], (int(input_hw[0]), int(input_hw[1])), thr, self.person_class)
        keep = nms(xyxy, scores, self.nms_iou)
        xyxy, scores = xyxy[keep], self.score_map(scores[keep])
        # Model pixels → frame pixels (pixel-centre coordinates: u = (u' + 0.5) / s − 0.5).
        px, py = prepared.pad
        s = prepared.scale
        xyxy = (xyxy - [px, py, px, py] + 0.5) / s - 0.5
        return Boxes(xyxy=xyxy, confidence=scores)


def _load_session(path: Path, threads: int, providers: Sequence[str] = DEFAULT_PROVIDERS) -> InferenceSession:
    import onnxruntime as ort  # imported here so the rest of the core library loads without it

    plan = plan_providers(providers, ort.get_available_providers())
    if plan.unavailable:
        _log.warning("%s: %s", path.name, plan.describe())

    if not path.is_file():
        raise DetectorError(f"detector model {path} does not exist")
    options = ort.SessionOptions()
    options.intra_op_num_threads = max(int(threads), 1)
    options.inter_op_num_threads = 1
    # ONNX Runtime's threads spin-wait for work between operators by default; on a machine whose
    # cores the detector shares (rendering, tracking, other cameras) that burned ~50 % more CPU
    # per frame with 2 threads and made each frame slower, not faster.
    options.add_session_config_entry("session.intra_op.allow_spinning", "0")
    if plan.needs_cuda():
        _preload_cuda_libraries()
    try:
        created = ort.InferenceSession(str(path), options, providers=plan.use)
    except Exception as exc:  # onnxruntime raises its own exception types
        raise DetectorError(f"cannot load detector model {path}: {exc}") from None
    loaded = list(created.get_providers())
    missed = plan.not_loaded(loaded)
    if missed:
        _log.warning("%s: %s offered by this onnxruntime build but did not load (ONNX Runtime's message "
                     "above says why: a driver or library missing?); runs on %s", path.name, ", ".join(missed),
                     ", ".join(loaded))
    session: InferenceSession = created
    return session


@functools.cache
def _preload_cuda_libraries() -> None:
    """Load CUDA and cuDNN from NVIDIA's pip packages (what the gpu extra installs) before a CUDA
    or TensorRT session, as ONNX Runtime asks; on a host with them installed system-wide it finds
    those. Once a process."""
    import onnxruntime as ort

    preload = getattr(ort, "preload_dlls", None)  # in onnxruntime since 1.21
    if preload is not None:
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):  # it prints each library it cannot find
            preload()
        said = [line.strip() for line in printed.getvalue().splitlines() if line.strip()]
        if said:
            _log.warning("loading CUDA's libraries: %s", "; ".join(said))


def _model_zoom(session: InferenceSession) -> float:
    return _metadata_number(session, ZOOM_METADATA_KEY, 1.0, 0.25, 4.0)


def _model_score_threshold(session: InferenceSession) -> float:
    return _metadata_number(session, SCORE_THRESHOLD_METADATA_KEY, SCORE_THRESHOLD, 0.0, 1.0)


def _model_score_map(session: InferenceSession) -> ScoreMap:
    text = _metadata_text(session, SCORE_MAP_METADATA_KEY)
    if text is None:
        return ScoreMap()
    try:
        return ScoreMap.from_text(text)
    except ValueError as exc:
        raise DetectorError(f"model metadata {SCORE_MAP_METADATA_KEY}: {exc}") from None


def _metadata_text(session: InferenceSession, key: str) -> str | None:
    """What the model file keeps under ``key``, None where it keeps nothing."""
    meta = getattr(session, "get_modelmeta", None)  # test doubles may have none
    value = meta().custom_metadata_map.get(key) if meta is not None else None
    return None if value is None else str(value)


def _metadata_number(session: InferenceSession, key: str, default: float, low: float, high: float) -> float:
    """The number the model file keeps under ``key`` (``default`` where it keeps none)."""
    value = _metadata_text(session, key)
    if value is None:
        return default
    try:
        number = float(value)
    except ValueError:
        raise DetectorError(f"model metadata {key}={value!r} is not a number") from None
    if not low <= number <= high:
        raise DetectorError(f"model metadata {key}={number:g} is outside {low:g}-{high:g}")
    return number


@dataclass(frozen=True)
class HeightRange:
    """Cameras mounted from ``min_m`` (inclusive) to ``max_m`` (exclusive) use ``model``."""

    min_m: float
    max_m: float
    model: str | Path | None = None


class DetectorOptions(TypedDict, total=False):
    """``Detector``'s settings other than the model and threads, as ``DetectorBank`` passes them on."""

    score_threshold: float | None
    nms_iou: float
    model_format: str
    person_class: int
    rgb: bool | None
    input_scale: float | None
    providers: Sequence[str]


class DetectorBank:
    """One detector per mounting-height range; ranges must not overlap. Detectors load lazily,
    so a site whose cameras are all in one range loads one model."""

    def __init__(self, ranges: Sequence[HeightRange], threads: int = 2, **options: Unpack[DetectorOptions]) -> None:
        ordered = sorted(ranges, key=lambda r: r.min_m)
        for a, b in zip(ordered, ordered[1:], strict=False):
            if b.min_m < a.max_m:
                raise ValueError(f"detector height ranges overlap: [{a.min_m}, {a.max_m}) and [{b.min_m}, {b.max_m})")
        for r in ordered:
            if not r.min_m < r.max_m:
                raise ValueError(f"detector height range [{r.min_m}, {r.max_m}) is empty")
        self.ranges = ordered
        self.threads, self.options = threads, options
        self._loaded: dict[int, Detector | RimTileDetector] = {}

    def for_height(self, camera_height_m: float) -> Detector | RimTileDetector:
        for i, r in enumerate(self.ranges):
            if r.min_m <= camera_height_m < r.max_m:
                if i not in self._loaded:
                    self._loaded[i] = self._load(r.model)
                return self._loaded[i]
        spans = ", ".join(f"[{r.min_m}, {r.max_m})" for r in self.ranges)
        raise ValueError(f"no detector model covers a camera {camera_height_m} m high (ranges: {spans})")

    def detect(self, image_bgr: NDArray[np.uint8], camera_height_m: float, focal_px: float) -> Boxes:
        return self.for_height(camera_height_m).detect(image_bgr, camera_height_m, focal_px)

    def detect_boxes(self, image_bgr: NDArray[np.uint8], camera_height_m: float, focal_px: float,
                     centre: tuple[float, float]) -> tuple[Boxes, FloatArray]:  # fmt: skip
        """The pipeline's boxes and the same people's rotated boxes (N, 5): the rim-tile
        detector's own angles, other models' boxes turned to their radial angle about ``centre``."""
        detector = self.for_height(camera_height_m)
        if isinstance(detector, Detector):
            boxes = detector.detect(image_bgr, camera_height_m, focal_px)
            return boxes, radial_boxes(boxes.xyxy, centre)
        return detector.detect_boxes(image_bgr, camera_height_m, focal_px, centre)

    def describe(self) -> str:
        """E.g. "under 5 m: rim-tiles; from 5 m: bevflow-person-centernet"."""
        parts = []
        for r in self.ranges:
            span = f"under {r.max_m:g} m" if r.min_m <= 0 else f"from {r.min_m:g} m" if r.max_m >= 100 else f"{r.min_m:g}-{r.max_m:g} m"
            parts.append(f"{span}: {r.model if is_rim_tiles(r.model) else Path(r.model or DEFAULT_MODEL).stem}")
        return "; ".join(parts)

    def _load(self, model: str | Path | None) -> Detector | RimTileDetector:
        if is_rim_tiles(model):
            return load_rim_tiles(self.threads, rim_tiles_model(str(model)), **self.options)
        return Detector(model, self.threads, **self.options)


# As in the paper, one model for low ceilings and one for the rest, both trained on renders: the
# general model (renders from 3 to 10 m) fine-tuned at 1.2 x the scale on renders from 3 to 5 m
# separates people standing close under low ceilings. The split is at 5 m, not the paper's 6 m:
# from 5 to 6 m the low-ceiling model costs 1.4 x the general model's time a frame, and the
# general model meets the suite's targets there (see the model card). The paper suite measures
# this pair.
LOW_CEILING_MODEL = DEFAULT_MODEL.with_name("bevflow-person-centernet-low.onnx")
# The general model quantised to 8 bits (``bevflow.training.quantize``), as accurate on renders.
# On CPUs without 8-bit dot-product instructions it is slower than the original, so it is chosen
# only where the CPU has them (``ranges_for_host``), or where a site file names it
# (``bevflow-person-centernet-int8``).
INT8_MODEL = DEFAULT_MODEL.with_name("bevflow-person-centernet-int8.onnx")
RENDER_TRAINED_RANGES = (HeightRange(0.0, 5.0, LOW_CEILING_MODEL), HeightRange(5.0, 100.0, None))
# What a site gets: under 5 m, where people are large in the frame and lie along its radius, the
# rim tiles through a detector trained on real photographs, which finds people in real frames
# that the render-trained models miss (docs/RESULTS.md, "Real frames"); from 5 m the general
# model. A site file's ``detectors`` can ask for other ranges or models.
DEFAULT_RANGES = (HeightRange(0.0, 5.0, RIM_TILES), HeightRange(5.0, 100.0, None))


def ranges_for_host(providers: Sequence[str] = DEFAULT_PROVIDERS, int8_fast: bool | None = None) -> tuple[HeightRange, ...]:
    """``DEFAULT_RANGES`` as this host runs them best: from 5 m the general model's INT8 copy
    where the detector runs on the CPU alone (``providers``, short names) and the CPU has 8-bit
    dot-product instructions (``int8_fast``; default: ``bevflow.detect.cpu``), which makes it
    about twice as fast there (docs/BENCHMARKS.md) and as accurate on renders (model card)."""
    on_cpu = check_providers(providers) == ["cpu"]
    fast = int8_dot_product() if int8_fast is None else int8_fast
    if on_cpu and fast and INT8_MODEL.is_file():
        return tuple(HeightRange(r.min_m, r.max_m, INT8_MODEL) if r.model is None else r for r in DEFAULT_RANGES)
    return DEFAULT_RANGES
