"""COCO-style person annotations for overhead fisheye frames, axis-aligned or rotated.

COCO files may hold axis-aligned ``bbox`` [x, y, w, h] or the rotated [cx, cy, w, h, degrees]
used by public overhead fisheye sets (CEPDOF, WEPDTOF); only the person category is read. A
rotated box counts as its enclosing axis-aligned rectangle wherever axis-aligned boxes are
compared (the detector's boxes are axis-aligned, the paper's D). Images may carry
``camera_height_m`` and ``focal_px`` for height-adaptive scaling. A folder of frames nobody
annotated (``unannotated_images``) is read as images whose people are not known.

A person annotation with ``iscrowd`` 1 is a crowd region, as in COCO: one box over people not
boxed one by one. It is not a person to find; scoring ignores detections that lie in it
(``bevflow.evaluation.detector``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, Field, ValidationError

FloatArray = NDArray[np.float64]
Finite = Annotated[float, Field(allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]


@dataclass(frozen=True, eq=False)
class CocoImage:
    """One annotated image: its file and person boxes as rotated rectangles (cx, cy, w, h, deg);
    axis-aligned annotations have angle 0."""

    path: Path
    rotated: FloatArray  # (N, 5)
    camera_height_m: float | None = None
    focal_px: float | None = None
    oriented: bool = False  # whether the file gave angles ([cx, cy, w, h, deg] boxes)
    annotated: bool = True  # False: nobody annotated the frame (``rotated`` is empty: not known)
    crowd: FloatArray = field(default_factory=lambda: np.zeros((0, 5)))  # (M, 5) crowd regions (``iscrowd`` 1)

    @property
    def xyxy(self) -> FloatArray:
        return rotated_to_xyxy(self.rotated)

    @property
    def crowd_xyxy(self) -> FloatArray:
        """The crowd regions as the upright boxes enclosing them: a region, not a body."""
        return rotated_to_xyxy(self.crowd)


class CocoError(ValueError):
    """A COCO file that cannot be read; the message says why."""


class _Image(BaseModel):
    id: int | str
    file_name: str = Field(min_length=1)
    camera_height_m: Positive | None = None
    focal_px: Positive | None = None


class _Annotation(BaseModel):
    id: int | str | None = None
    image_id: int | str
    category_id: int | str | None = None
    bbox: list[Finite] = Field(min_length=4, max_length=5)
    iscrowd: Annotated[int, Field(ge=0, le=1)] = 0


class _Category(BaseModel):
    id: int | str
    name: str = ""


class _CocoFile(BaseModel):
    """The part of a COCO file read here; other keys are ignored."""

    images: list[_Image]
    annotations: list[_Annotation]
    categories: list[_Category] = []


def _parse(annotations: Path) -> _CocoFile:
    try:
        doc = json.loads(Path(annotations).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CocoError(f"cannot read {annotations}: {exc}") from None
    if not isinstance(doc, dict) or "images" not in doc or "annotations" not in doc:
        raise CocoError(f"{annotations} is not a COCO file (needs 'images' and 'annotations')")
    try:
        return _CocoFile.model_validate(doc)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in first["loc"]).lstrip(".")
        more = f" (and {exc.error_count() - 1} more)" if exc.error_count() > 1 else ""
        message = "should be a JSON object" if first["type"] == "model_type" else first["msg"]
        raise CocoError(f"{annotations}: {where}: {message}{more}") from None


def read_coco(annotations: Path, images_dir: Path | None = None) -> list[CocoImage]:
    """Person boxes per image from a COCO JSON file. ``bbox`` of 4 numbers is [x, y, w, h]; of 5,
    the rotated [cx, cy, w, h, degrees]. Images without annotations are kept (no people).
    Optional per-image keys ``camera_height_m`` and ``focal_px`` enable height-adaptive scaling.
    Annotations with ``iscrowd`` 1 are the image's crowd regions, not people (module docstring)."""
    doc = _parse(annotations)
    cats = doc.categories
    person = {c.id for c in cats if c.name.lower() == "person"} or ({c.id for c in cats} if len(cats) == 1 else None)
    folder = Path(images_dir) if images_dir is not None else Path(annotations).parent
    boxes: dict[int | str, list[list[float]]] = {im.id: [] for im in doc.images}
    crowds: dict[int | str, list[list[float]]] = {im.id: [] for im in doc.images}
    oriented = False
    for ann in doc.annotations:
        if person is not None and ann.category_id not in person:
            continue
        b = ann.bbox
        if len(b) == 4:
            b = [b[0] + b[2] / 2, b[1] + b[3] / 2, b[2], b[3], 0.0]
        else:
            oriented = True
        if ann.image_id not in boxes:
            raise CocoError(f"{annotations}: annotation {ann.id} refers to unknown image {ann.image_id!r}")
        (crowds if ann.iscrowd else boxes)[ann.image_id].append(b)
    # A file of rotated boxes is oriented as a whole, so an image whose people all happen to lie
    # at 0° is scored as rotated like the rest.
    return [
        CocoImage(folder / im.file_name, np.array(boxes[im.id], dtype=np.float64).reshape(-1, 5),
                  im.camera_height_m, im.focal_px, oriented, crowd=np.array(crowds[im.id], dtype=np.float64).reshape(-1, 5))
        for im in doc.images
    ]  # fmt: skip


IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")


def unannotated_images(folder: Path) -> list[CocoImage]:
    """Every image file of ``folder`` (by its suffix, any case), in name order, as frames nobody
    annotated; ``CocoError`` for a folder without one."""
    folder = Path(folder)
    if not folder.is_dir():
        raise CocoError(f"{folder} is not a folder")
    paths = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    if not paths:
        raise CocoError(f"{folder} holds no image ({', '.join(IMAGE_SUFFIXES)})")
    return [CocoImage(p, np.zeros((0, 5)), annotated=False) for p in paths]


def rotated_to_xyxy(rotated: FloatArray) -> FloatArray:
    """(N, 5) rotated rectangles (cx, cy, w, h, degrees) → (N, 4) enclosing axis-aligned boxes."""
    r = np.asarray(rotated, dtype=np.float64).reshape(-1, 5)
    a = np.radians(r[:, 4])
    hw = (np.abs(np.cos(a)) * r[:, 2] + np.abs(np.sin(a)) * r[:, 3]) / 2
    hh = (np.abs(np.sin(a)) * r[:, 2] + np.abs(np.cos(a)) * r[:, 3]) / 2
    return np.stack([r[:, 0] - hw, r[:, 1] - hh, r[:, 0] + hw, r[:, 1] + hh], 1)



def write_coco(path: Path, images: list[dict[str, Any]], boxes: list[FloatArray]) -> None:
    """Write axis-aligned person boxes (one (N, 4) xyxy array per image) as COCO JSON. ``images``
    are COCO image entries (``file_name``, ``width``, ``height``, optional extras); ids are
    assigned in order."""
    out_images: list[dict[str, Any]] = []
    annotations: list[dict[str, Any]] = []
    for i, (im, xyxy) in enumerate(zip(images, boxes, strict=True), start=1):
        out_images.append({"id": i, **im})
        for x0, y0, x1, y1 in np.asarray(xyxy, dtype=np.float64).reshape(-1, 4):
            annotations.append({"id": len(annotations) + 1, "image_id": i, "category_id": 1,
                                "bbox": [round(x0, 2), round(y0, 2), round(x1 - x0, 2), round(y1 - y0, 2)],
                                "area": round((x1 - x0) * (y1 - y0), 2), "iscrowd": 0})  # fmt: skip
    doc = {"images": out_images, "annotations": annotations, "categories": [{"id": 1, "name": "person"}]}
    Path(path).write_text(json.dumps(doc))
