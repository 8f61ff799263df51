"""Do overlapping cameras agree? The same person seen by two cameras should land on the same spot.

Fusion already decides which cylinders of different cameras are one person; every such pair of
members gives one *offset* sample, camera a's feet minus camera b's (a before b in site order).
Over many people, a pair's samples show its calibration:

- the median offset (a vector, and its length in metres) is the systematic disagreement: one
  camera's floor is shifted or turned against the other's;
- the spread (the median distance of the samples from that median offset) is the noise of the
  position estimates themselves, which no calibration removes.

Fusion only pairs feet closer than its distance (0.45 m by default), so offsets near that limit
are cut off. ``isolated_pairs`` pairs differently, for measuring: only someone alone in the overlap
(no second candidate within the gate), with a wider gate (1 m). In the simulator, two perfectly
calibrated 5.5 m cameras already disagree by about 0.3 m in their overlap, because each camera's
cylinder fits lean toward it; fusion's pairs would report less than that.

>>> from bevflow.camera import FisheyeCamera
>>> from bevflow.detections import Cylinders
>>> from bevflow.fusion import fuse_cylinders
>>> cams = [FisheyeCamera.looking_down((x, 0.0, 3.3), (512, 512)) for x in (0.0, 4.0)]
>>> seen = Cylinders(xy=[[2.0, 0.0], [2.1, 0.0]], camera=[0, 1])
>>> pair_offsets(seen, fuse_cylinders(seen, cams)).offset.tolist()
[[-0.10000000000000009, 0.0]]
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from bevflow.camera import Camera
from bevflow.detections import Cylinders
from bevflow.fusion import Fusion, fuse_cylinders

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class PairSamples:
    """Row-aligned offset samples: cameras ``a`` < ``b`` (indices), ``offset`` (M, 2) = feet of a −
    feet of b, ``position`` (M, 2) their midpoint, ``person`` (M,) the fused row they belong to."""

    a: IntArray
    b: IntArray
    offset: FloatArray
    position: FloatArray
    person: IntArray

    def __len__(self) -> int:
        return len(self.a)

    @classmethod
    def empty(cls) -> PairSamples:
        return cls(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, np.int64))

    @staticmethod
    def merge(parts: Sequence[PairSamples]) -> PairSamples:
        parts = [p for p in parts if len(p)]
        if not parts:
            return PairSamples.empty()
        return PairSamples(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("a", "b", "offset", "position", "person")))


def pair_offsets(cylinders: Cylinders, fusion: Fusion, visible_only: bool = False) -> PairSamples:
    """One sample per pair of cylinders that fusion merged into the same person. With
    ``visible_only``, cylinders rebuilt from the head (lower body occluded) are left out: their
    error is several times that of a whole person and would only add noise."""
    usable = fusion.assignment >= 0
    if visible_only:
        usable &= ~cylinders.occluded
    rows = np.flatnonzero(usable)
    if len(rows) < 2:
        return PairSamples.empty()
    person = fusion.assignment[rows]
    # Every ordered pair of inputs with the same person; fusion never merges two of one camera.
    i, j = np.nonzero((person[:, None] == person[None, :]) & (cylinders.camera[rows][:, None] < cylinders.camera[rows][None, :]))
    first, second = rows[i], rows[j]
    xy = cylinders.xy
    return PairSamples(
        a=cylinders.camera[first].astype(np.int64),
        b=cylinders.camera[second].astype(np.int64),
        offset=xy[first] - xy[second],
        position=(xy[first] + xy[second]) / 2.0,
        person=person[i].astype(np.int64),
    )


def isolated_pairs(cylinders: Cylinders, gate_m: float = 1.0) -> PairSamples:
    """One sample per pair of cylinders of two cameras that are within ``gate_m`` of each other
    with no other cylinder of either camera within ``gate_m`` of them: someone alone in the
    overlap, about whom there is no doubt. Unlike fusion's pairs, these are not cut off at
    fusion's distance, so offsets up to ``gate_m`` are measured without bias."""
    ok = np.isfinite(cylinders.xy).all(axis=1)
    rows = np.flatnonzero(ok)
    if len(rows) < 2:
        return PairSamples.empty()
    xy, camera = cylinders.xy[rows], cylinders.camera[rows]
    near = np.linalg.norm(xy[:, None] - xy[None, :], axis=2) < gate_m
    np.fill_diagonal(near, False)
    # counts[r, c]: neighbours of row r seen by camera c. A clean pair (i of camera a, j of b):
    # each is the other's only neighbour from that camera, and neither has one from its own camera
    # (a second person close by). A third camera seeing the same person is no doubt.
    counts = near.astype(np.int64) @ (camera[:, None] == np.arange(camera.max() + 1)[None, :]).astype(np.int64)
    i, j = np.nonzero(near & (camera[:, None] < camera[None, :]))
    ci, cj = camera[i], camera[j]
    keep = (counts[i, cj] == 1) & (counts[j, ci] == 1) & (counts[i, ci] == 0) & (counts[j, cj] == 0)
    i, j = rows[i[keep]], rows[j[keep]]
    return PairSamples(
        a=cylinders.camera[i].astype(np.int64),
        b=cylinders.camera[j].astype(np.int64),
        offset=cylinders.xy[i] - cylinders.xy[j],
        position=(cylinders.xy[i] + cylinders.xy[j]) / 2.0,
        person=np.arange(len(i), dtype=np.int64),
    )


@dataclass(frozen=True)
class PairConsistency:
    """How well cameras ``camera_a`` and ``camera_b`` agree, from ``samples`` sightings (one person
    seen by both cameras in one frame)."""

    camera_a: str
    camera_b: str
    samples: int
    median_offset: tuple[float, float]
    median_offset_m: float
    spread_m: float
    gate_m: float

    @property
    def near_gate(self) -> bool:
        """The offsets come so close to fusion's gate that larger ones were probably not paired."""
        return self.median_offset_m + self.spread_m > 0.8 * self.gate_m


def summarise_pairs(samples: PairSamples, camera_ids: Sequence[str], gate_m: float) -> list[PairConsistency]:
    """One row per camera pair with samples, in site order."""
    out = []
    pairs = sorted({(int(a), int(b)) for a, b in zip(samples.a, samples.b, strict=True)})
    for a, b in pairs:
        offsets = samples.offset[(samples.a == a) & (samples.b == b)]
        median = np.median(offsets, axis=0)
        spread = float(np.median(np.linalg.norm(offsets - median, axis=1)))
        out.append(
            PairConsistency(
                camera_a=camera_ids[a],
                camera_b=camera_ids[b],
                samples=len(offsets),
                median_offset=(float(median[0]), float(median[1])),
                median_offset_m=float(np.linalg.norm(median)),
                spread_m=spread,
                gate_m=gate_m,
            )
        )
    return out


def check_consistency(
    cameras: Sequence[Camera],
    camera_ids: Sequence[str],
    frames: Iterable[Mapping[int, Cylinders]],
    gate_m: float = 1.0,
    pairing: Literal["isolated", "fusion"] = "isolated",
) -> list[PairConsistency]:
    """Summarise the offsets of every overlapping pair over ``frames`` (each: cylinders by camera
    index). ``pairing`` "isolated" pairs people alone in an overlap within ``gate_m``
    (``isolated_pairs``); "fusion" pairs what ``fuse_cylinders`` with distance ``gate_m`` merges,
    which is what the live pipeline does, offsets cut off at the gate included."""
    collected = []
    for per_camera in frames:
        seen = Cylinders.merge([c.with_camera(i) for i, c in per_camera.items()])
        if len(seen) < 2:
            continue
        if pairing == "fusion":
            collected.append(pair_offsets(seen, fuse_cylinders(seen, cameras, gate_m)))
        else:
            collected.append(isolated_pairs(seen, gate_m))
    return summarise_pairs(PairSamples.merge(collected), camera_ids, gate_m)


def format_consistency(rows: Sequence[PairConsistency], min_samples: int = 1) -> str:
    """A table for the terminal, worst pair first; pairs with fewer than ``min_samples`` samples
    are listed last, as too few to judge. A sample is one person seen by both cameras in one frame."""
    lines = [f"{'camera pair':<28} {'samples':>7} {'median offset m':>16} {'(dx, dy) m':>16} {'spread m':>9}"]
    for r in sorted(rows, key=lambda r: (r.samples < min_samples, -r.median_offset_m)):
        if r.samples < min_samples:
            flag = "  too few samples to judge"
        else:
            flag = "  near the gate: rerun with a wider --gate" if r.near_gate else ""
        dx, dy = r.median_offset
        lines.append(
            f"{r.camera_a + ' / ' + r.camera_b:<28} {r.samples:>7} {r.median_offset_m:>16.3f} "
            f"{f'({dx:+.2f}, {dy:+.2f})':>16} {r.spread_m:>9.3f}{flag}"
        )
    return "\n".join(lines)
