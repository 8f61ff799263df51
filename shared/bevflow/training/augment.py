"""The paper's augmentations (rotation, flip, CLAHE) plus photometric jitter, on an image and its
id buffer, and the exact boxes recovered from the buffer afterwards.

A ceiling fisheye is symmetric under rotation about its principal point, and a fully
convolutional detector does not know where in the frame a crop came from, so rotating a crop by
any angle about its own centre gives another image the camera could have taken. Rotating the id
buffer (``owner``, see ``bevflow.training.dataset``) with nearest-neighbour sampling keeps every
pixel's person, so the boxes after rotation are the exact bounding boxes of the rotated
silhouettes, not the inflated boxes of rotated rectangles.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from bevflow.training.dataset import IGNORE

FloatArray = NDArray[np.float64]
Image = NDArray[np.uint8]
Owner = NDArray[np.int16]


def rotate(image: Image, owner: Owner, angle_deg: float, center: tuple[float, float] | None = None) -> tuple[Image, Owner]:
    """Rotate both about ``center`` (default: the image centre) by ``angle_deg`` (counter-clockwise
    as displayed); uncovered corners become black / background."""
    h, w = owner.shape
    c = center if center is not None else ((w - 1) / 2.0, (h - 1) / 2.0)
    m = cv2.getRotationMatrix2D(c, angle_deg, 1.0)
    img = cv2.warpAffine(image, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    own = cv2.warpAffine(owner.astype(np.float32), m, (w, h), flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=-1)
    return np.asarray(img, dtype=np.uint8), own.astype(np.int16)


def flip(image: Image, owner: Owner, horizontal: bool = True) -> tuple[Image, Owner]:
    axis = 1 if horizontal else 0
    return np.ascontiguousarray(np.flip(image, axis)), np.ascontiguousarray(np.flip(owner, axis))


def clahe(image: Image, clip_limit: float = 2.0, tiles: int = 8) -> Image:
    """Contrast-limited adaptive histogram equalisation of the lightness (LAB L channel)."""
    lab = cv2.cvtColor(image, cv2.COLOR_BGR2LAB)
    lab[..., 0] = cv2.createCLAHE(clipLimit=clip_limit, tileGridSize=(tiles, tiles)).apply(np.ascontiguousarray(lab[..., 0]))
    return np.asarray(cv2.cvtColor(lab, cv2.COLOR_LAB2BGR), dtype=np.uint8)


def jitter_colors(rng: np.random.Generator, image: Image) -> Image:
    """Brightness, contrast and per-channel gain changes, and sometimes grey-scale (many ceiling
    cameras switch to monochrome in low light)."""
    img = image.astype(np.float32)
    img = (img - 128.0) * rng.uniform(0.7, 1.3) + 128.0 + rng.uniform(-30, 30)
    img *= rng.uniform(0.85, 1.15, 3).astype(np.float32)
    out = np.clip(img, 0, 255).astype(np.uint8)
    if rng.random() < 0.1:
        out = np.asarray(cv2.cvtColor(cv2.cvtColor(out, cv2.COLOR_BGR2GRAY), cv2.COLOR_GRAY2BGR), dtype=np.uint8)
    return out


def augment_sample(rng: np.random.Generator, image: Image, owner: Owner, crop: int) -> tuple[Image, Owner]:
    """A random rotation, flip, CLAHE and colour jitter, then a random ``crop`` × ``crop`` window."""
    if rng.random() < 0.9:
        image, owner = rotate(image, owner, rng.uniform(0.0, 360.0))
    if rng.random() < 0.5:
        image, owner = flip(image, owner)
    if rng.random() < 0.3:
        image = clahe(image, clip_limit=rng.uniform(1.0, 3.0))
    if rng.random() < 0.8:
        image = jitter_colors(rng, image)
    h, w = owner.shape
    y0 = int(rng.integers(0, h - crop + 1))
    x0 = int(rng.integers(0, w - crop + 1))
    return image[y0 : y0 + crop, x0 : x0 + crop], owner[y0 : y0 + crop, x0 : x0 + crop]


def boxes_from_owner(
    owner: Owner, reference_pixels: NDArray[np.int64] | None = None, min_pixels: int = 15, min_fraction: float = 0.3
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Boxes (N, 4) of the people in the id buffer (pixel-centre coordinates) and whether each is
    to be ignored: people marked ``IGNORE``, and people the crop cut down to fewer than
    ``min_pixels`` or under ``min_fraction`` of their ``reference_pixels`` (their pixel count
    before cropping)."""
    labels = np.where(owner >= 0, owner.astype(np.int64) + 1, 0)
    top = int(labels.max()) if labels.size else 0
    slices = ndimage.find_objects(labels, max_label=top) if top else []
    counts = np.bincount(labels.ravel(), minlength=top + 1)
    boxes, ignore = [], []
    for k, sl in enumerate(slices):
        if sl is None:
            continue
        boxes.append([sl[1].start - 0.5, sl[0].start - 0.5, sl[1].stop - 0.5, sl[0].stop - 0.5])
        n = counts[k + 1]
        ref = reference_pixels[k] if reference_pixels is not None and k < len(reference_pixels) else n
        ignore.append(n < min_pixels or n < min_fraction * ref)
    hidden = ndimage.find_objects((owner == IGNORE).astype(np.int32))
    if hidden and hidden[0] is not None:
        lab, count = ndimage.label(owner == IGNORE)
        for sl in ndimage.find_objects(lab, max_label=count):
            if sl is not None:
                boxes.append([sl[1].start - 0.5, sl[0].start - 0.5, sl[1].stop - 0.5, sl[0].stop - 0.5])
                ignore.append(True)
    return np.array(boxes, dtype=np.float64).reshape(-1, 4), np.array(ignore, dtype=bool)


def rotate_rotated_boxes(rotated: FloatArray, angle_deg: float, center: tuple[float, float]) -> FloatArray:
    """Rotated rectangles (N, 5: cx, cy, w, h, deg) after rotating the image as ``rotate`` does."""
    r = np.asarray(rotated, dtype=np.float64).reshape(-1, 5).copy()
    m = cv2.getRotationMatrix2D(center, angle_deg, 1.0)
    r[:, :2] = r[:, :2] @ m[:, :2].T + m[:, 2]
    r[:, 4] -= angle_deg  # image y points down: a counter-clockwise turn lowers the box angle
    return r
