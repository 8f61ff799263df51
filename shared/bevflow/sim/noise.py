"""A detector-noise model: perfect boxes in, the boxes an imperfect detector would give out.

Used on dataset annotations (WILDTRACK) and on the simulator's exact boxes, so runs with the
same settings compare across datasets and versions. The definition is exact; changing it
changes every published number, so keep it.

For one view of one frame, with input boxes b_i = (x0, y0, x1, y1), i = 0..N−1:

1. **Truncation** (``truncation=True``). A detector sees only the visible part of a person.
   Each box is replaced by its visible extent: given by the caller (``visible=``, e.g. the
   simulator's occlusion) or else inferred by :func:`side_view_visible_boxes`, the rule for
   side-view cameras (the floor below the image, so feet are the bottom edge and a person whose
   box bottom is lower stands nearer the camera). Box j *occludes* box i when
   ``y1_j > y1_i`` (j's feet are nearer), ``y0_j < y1_i`` (j reaches i's feet) and j covers at
   least ``OCCLUDER_COVER`` (half) of i's width. Box i's bottom edge is then cut back to the
   highest top edge ``y0_j`` among its occluders, but never above ``y0_i + MIN_VISIBLE · h_i``
   (a head and shoulders always stay visible).
2. **Jitter** (``jitter=F``). Each edge moves by independent Gaussian noise: x0 and x1 with
   σ = F · w, y0 and y1 with σ = F · h, where w, h are the size of the (truncated) box. If two
   edges cross they are swapped back into order.
3. **Drop** (``drop=F``). Each box is removed independently with probability F.
4. **False positives** (``false_positives=F``). K ~ Poisson(F) spurious boxes are added. Each
   takes the width and height of an input box chosen uniformly (the view's real boxes after
   truncation), or ``DEFAULT_FALSE_POSITIVE_SIZE`` times the image height when the view has
   none, and a top-left corner uniform over the positions that keep it inside the image.
   Their confidence is 1.

Random numbers: one generator per (seed, frame, view), made by :func:`view_rng`, so evaluating a
slice of the frames draws exactly the noise of the full run for those frames. Every draw is made
whatever the settings, in this order: normals (N, 4) for jitter, uniforms (N,) for drop, the
Poisson count K, then uniforms (K, 3) for the false positives (template, x, y). Changing one
setting therefore leaves the other effects' random numbers unchanged.

>>> boxes = Boxes(xyxy=np.array([[100.0, 100.0, 140.0, 200.0]]))
>>> out = apply_detector_noise(boxes, DetectorNoise(drop=1.0), view_rng(0, 0, 0), image_size=(640, 480))
>>> len(out.boxes), out.source.tolist()
(0, [])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bevflow.detections import Boxes

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

OCCLUDER_COVER = 0.5
MIN_VISIBLE = 0.3
DEFAULT_FALSE_POSITIVE_SIZE = (0.1, 0.25)  # (width, height) as fractions of the image height


@dataclass(frozen=True)
class DetectorNoise:
    """Noise settings; see the module docstring for their exact meaning. All zero and
    ``truncation=False`` is a perfect detector."""

    jitter: float = 0.0
    drop: float = 0.0
    false_positives: float = 0.0
    truncation: bool = True

    def __post_init__(self) -> None:
        if not (np.isfinite(self.jitter) and self.jitter >= 0.0):
            raise ValueError(f"jitter must be a fraction of the box size >= 0, got {self.jitter}")
        if not 0.0 <= self.drop <= 1.0:
            raise ValueError(f"drop must be a probability in [0, 1], got {self.drop}")
        if not (np.isfinite(self.false_positives) and self.false_positives >= 0.0):
            raise ValueError(f"false_positives must be a mean count >= 0, got {self.false_positives}")


@dataclass(frozen=True)
class NoisyBoxes:
    """The detector's output for one view. ``source[k]`` is the input box that output k came
    from, −1 for a false positive; ``truncated[k]`` says its bottom was cut by an occluder."""

    boxes: Boxes
    source: IntArray
    truncated: NDArray[np.bool_]


def view_rng(seed: int, frame: int, view: int) -> np.random.Generator:
    """The generator for one view of one frame, independent of every other (seed, frame, view)."""
    if min(seed, frame, view) < 0:
        raise ValueError(f"seed, frame and view must be >= 0, got {seed}, {frame}, {view}")
    return np.random.default_rng([seed, frame, view])


def side_view_visible_boxes(boxes: Boxes) -> FloatArray:
    """The visible extent (N, 4) of each box under the side-view occlusion rule of step 1."""
    xyxy = boxes.xyxy.copy()
    if len(xyxy) < 2:
        return xyxy
    x0, y0, x1, y1 = (xyxy[:, k] for k in range(4))
    overlap = np.clip(np.minimum(x1[:, None], x1[None, :]) - np.maximum(x0[:, None], x0[None, :]), 0.0, None)
    width = np.maximum(x1 - x0, 1e-9)
    # occludes[i, j]: box j hides the lower part of box i
    occludes = (y1[None, :] > y1[:, None]) & (y0[None, :] < y1[:, None]) & (overlap >= OCCLUDER_COVER * width[:, None])
    cut = np.where(occludes, y0[None, :], np.inf).min(axis=1)
    floor = y0 + MIN_VISIBLE * (y1 - y0)
    xyxy[:, 3] = np.where(np.isfinite(cut), np.maximum(np.minimum(cut, y1), floor), y1)
    return xyxy


def apply_detector_noise(
    boxes: Boxes,
    noise: DetectorNoise,
    rng: np.random.Generator,
    image_size: tuple[int, int],
    visible: FloatArray | None = None,
) -> NoisyBoxes:
    """Apply ``noise`` to one view's boxes (see the module docstring for the definition).

    ``image_size`` (w, h) bounds the false positives. ``visible`` (N, 4), optional, is each box's
    visible extent from the caller's own occlusion model; without it truncation uses
    :func:`side_view_visible_boxes`."""
    n = len(boxes)
    xyxy = boxes.xyxy.copy()
    if noise.truncation:
        seen = side_view_visible_boxes(boxes) if visible is None else np.asarray(visible, dtype=np.float64).reshape(n, 4)
        truncated = np.any(np.abs(seen - xyxy) > 1e-9, axis=1)
        xyxy = seen.copy()
    else:
        truncated = np.zeros(n, dtype=bool)
    templates = xyxy.copy()

    normals = rng.standard_normal((n, 4))
    keep = rng.random(n) >= noise.drop
    n_false = int(rng.poisson(noise.false_positives))
    placement = rng.random((n_false, 3))

    size = np.stack([xyxy[:, 2] - xyxy[:, 0], xyxy[:, 3] - xyxy[:, 1]], axis=1)  # (w, h)
    xyxy += noise.jitter * normals * np.concatenate([size, size], axis=1)  # (w, h, w, h)
    xyxy[:, [0, 2]] = np.sort(xyxy[:, [0, 2]], axis=1)
    xyxy[:, [1, 3]] = np.sort(xyxy[:, [1, 3]], axis=1)

    false_xyxy = _false_positive_boxes(templates, placement, image_size)
    out = Boxes(
        xyxy=np.concatenate([xyxy[keep], false_xyxy]),
        confidence=np.concatenate([boxes.confidence[keep], np.ones(n_false)]),
    )
    source = np.concatenate([np.flatnonzero(keep), np.full(n_false, -1)]).astype(np.int64)
    return NoisyBoxes(boxes=out, source=source, truncated=np.concatenate([truncated[keep], np.zeros(n_false, dtype=bool)]))


def _false_positive_boxes(templates: FloatArray, placement: FloatArray, image_size: tuple[int, int]) -> FloatArray:
    w_img, h_img = float(image_size[0]), float(image_size[1])
    k = len(placement)
    if len(templates):
        pick = np.minimum((placement[:, 0] * len(templates)).astype(np.int64), len(templates) - 1)
        wh = templates[pick, 2:] - templates[pick, :2]
    else:
        wh = np.tile(np.array(DEFAULT_FALSE_POSITIVE_SIZE) * h_img, (k, 1))
    wh = np.minimum(wh, [w_img, h_img])
    x0 = placement[:, 1] * (w_img - wh[:, 0])
    y0 = placement[:, 2] * (h_img - wh[:, 1])
    return np.stack([x0, y0, x0 + wh[:, 0], y0 + wh[:, 1]], axis=1).reshape(-1, 4)
