"""Recorded detector output and world truth in MOTChallenge-style text files.

Layout read::

    DIR/<camera id>.txt    one per camera of the site: frame,id,left,top,width,height,confidence,...
    TRUTH                  frame,id,x,y    (each annotated person's floor position, metres)

A detection row is one person box of one camera in one frame, in pixels; its id is −1 (nobody
knows whose it is) and is not read, and columns past the confidence (MOTChallenge's world x, y, z)
are ignored. Frame numbers are shared by every camera and the truth: frame f of one camera and
frame f of another were taken at the same instant. Boxes are clipped to the camera's image, as a
detector's are (MOTChallenge files may hold boxes reaching past the border), and a box left with
no area is dropped. Of two boxes of one camera and frame that overlap as one person's would, the
less confident is left out when the boxes are read back (``CameraRecording.boxes``,
``bevflow.detections.Boxes.distinct``), as bevflow's own detector suppresses them.

Every problem in a file is a ``RecordingError`` naming the file and the line; a camera of the
site with no file is one naming the camera. A replay steps through every frame number from the
first to the last, so frames that leave more than ``LONGEST_EMPTY_S`` without a single row
(``check_no_long_gap``) are one too: a frame number typed wrong, which would otherwise have a
replay step through years of empty frames.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from bevflow.detections import Boxes

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

MIN_CONFIDENCE = 0.5
"""Boxes below this confidence are left out unless asked for: the usual operating point of a
COCO person detector such as Faster R-CNN, whose boxes below it are mostly not people."""

LONGEST_EMPTY_S = 3600.0
"""The longest stretch without a single row that a replay steps through: an hour of a recording
in which no camera has a box and nobody is annotated is a frame number typed wrong."""


class RecordingError(ValueError):
    """A detections folder or truth file that cannot be read; the message names file and line."""


@dataclass(frozen=True)
class CameraRecording:
    """One camera's boxes, by frame number (frames without boxes are absent)."""

    camera_id: str
    by_frame: dict[int, Boxes]

    def boxes(self, frame: int, min_confidence: float = 0.0) -> Boxes:
        """The boxes of ``frame`` whose confidence reaches ``min_confidence``, in file order, less
        each one overlapping a more confident one as one person's boxes would (``Boxes.distinct``)."""
        boxes = self.by_frame.get(frame) or Boxes.empty()
        boxes = boxes if min_confidence <= 0 else boxes[boxes.confidence >= min_confidence]
        return boxes.distinct()


@dataclass(frozen=True)
class DetectionRecording:
    """Every camera's boxes, in the site's camera order."""

    cameras: tuple[CameraRecording, ...]

    @property
    def camera_ids(self) -> tuple[str, ...]:
        return tuple(c.camera_id for c in self.cameras)

    @property
    def frame_numbers(self) -> tuple[int, ...]:
        """Every frame number that has a box in some camera, sorted."""
        return tuple(sorted({f for c in self.cameras for f in c.by_frame}))

    def frames_by_file(self, last: int | None = None) -> dict[str, set[int]]:
        """Each camera's file name (``<camera id>.txt``) and the frame numbers it has boxes in (up
        to ``last``), as ``check_no_long_gap`` takes them."""
        return {file_name(c.camera_id): {f for f in c.by_frame if last is None or f <= last} for c in self.cameras}


@dataclass(frozen=True)
class WorldTruth:
    """Annotated people on the floor, by frame number: ``(ids (N,), xy (N, 2))``."""

    by_frame: dict[int, tuple[IntArray, FloatArray]]

    @property
    def frame_numbers(self) -> tuple[int, ...]:
        return tuple(sorted(self.by_frame))

    def at(self, frame: int) -> tuple[IntArray, FloatArray]:
        """The people of ``frame``; nobody where the file has no row."""
        return self.by_frame.get(frame) or (np.zeros(0, np.int64), np.zeros((0, 2)))


def file_name(camera_id: str) -> str:
    """The file of a camera's boxes in a detections folder."""
    return f"{camera_id}.txt"


def read_detections(folder: Path | str, cameras: dict[str, tuple[int, int]]) -> DetectionRecording:
    """``folder/<camera id>.txt`` for every camera of ``cameras`` (id -> image size (w, h), in the
    site's order)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise RecordingError(f"{folder}: no such folder (expected one <camera id>.txt per camera)")
    out = []
    for camera_id, image_size in cameras.items():
        path = folder / file_name(camera_id)
        if not path.is_file():
            raise RecordingError(f"{path}: no detections file for camera {camera_id!r} "
                                 f"(expected one <camera id>.txt per camera: {', '.join(cameras)})")
        out.append(CameraRecording(camera_id, read_detection_file(path, image_size)))
    return DetectionRecording(tuple(out))


def read_detection_file(path: Path, image_size: tuple[int, int]) -> dict[int, Boxes]:
    """One camera's rows ``frame,id,left,top,width,height,confidence,...``, by frame, clipped to
    the image (w, h)."""
    rows: dict[int, list[list[float]]] = {}
    for where, fields in _rows(path, 7):
        frame = _frame(fields[0], where)
        left, top, width, height, confidence = (_number(f, where) for f in fields[2:7])
        if width <= 0 or height <= 0:
            raise RecordingError(f"{where}: a box needs width and height above 0, got {width:g} x {height:g}")
        rows.setdefault(frame, []).append([left, top, left + width, top + height, confidence])
    w, h = image_size
    out = {}
    for frame, values in rows.items():
        table = np.asarray(values, dtype=np.float64)
        xyxy = table[:, :4].copy()
        xyxy[:, [0, 2]] = xyxy[:, [0, 2]].clip(0.0, w)
        xyxy[:, [1, 3]] = xyxy[:, [1, 3]].clip(0.0, h)
        keep = (xyxy[:, 2] > xyxy[:, 0]) & (xyxy[:, 3] > xyxy[:, 1])  # off the image: nothing seen
        if keep.any():
            out[frame] = Boxes(xyxy=xyxy[keep], confidence=table[keep, 4])
    return out


def read_truth(path: Path | str) -> WorldTruth:
    """Rows ``frame,id,x,y``; a person may appear once per frame."""
    path = Path(path)
    if not path.is_file():
        raise RecordingError(f"{path}: no such file (expected world truth rows frame,id,x,y)")
    people: dict[int, dict[int, tuple[float, float]]] = {}
    for where, fields in _rows(path, 4):
        frame = _frame(fields[0], where)
        person = _whole(fields[1], where, "person id")
        x, y = _number(fields[2], where), _number(fields[3], where)
        if person in people.setdefault(frame, {}):
            raise RecordingError(f"{where}: person {person} appears twice in frame {frame}")
        people[frame][person] = (x, y)
    return WorldTruth({
        f: (np.fromiter(p, np.int64, len(p)), np.array(list(p.values()), dtype=np.float64).reshape(-1, 2))
        for f, p in people.items()
    })


def check_no_long_gap(frames_of: Mapping[str, Collection[int]], fps: float) -> None:
    """``RecordingError`` where the frame numbers of all ``frames_of`` sources together (a name,
    such as a file's, to the frames it has rows in) leave more than ``LONGEST_EMPTY_S`` at
    ``fps`` without any row, naming the stretch and the sources on either side of it."""
    every = np.unique(np.fromiter((f for frames in frames_of.values() for f in frames), np.int64))
    if len(every) < 2:
        return
    k = int(np.argmax(np.diff(every)))
    before, after = int(every[k]), int(every[k + 1])
    empty_s = (after - before - 1) / fps
    if empty_s <= LONGEST_EMPTY_S:
        return

    def holding(frame: int) -> str:
        return ", ".join(name for name, frames in frames_of.items() if frame in frames)

    raise RecordingError(
        f"frames {before + 1}..{after - 1} hold no row at all, {empty_s / 3600:,.1f} hours at {fps:g} fps, "
        f"between frame {before} ({holding(before)}) and frame {after} ({holding(after)}): a replay steps "
        "through every frame; check those frame numbers, or the fps"
    )


def _rows(path: Path, columns: int) -> Iterator[tuple[str, list[str]]]:
    """Each non-blank line's comma-separated fields (at least ``columns``) and its place."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: cannot read ({getattr(exc, 'strerror', None) or exc})") from None
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        fields = [f.strip() for f in line.split(",")]
        where = f"{path}:{number}"
        if len(fields) < columns:
            raise RecordingError(f"{where}: expected at least {columns} comma-separated values, got {len(fields)}: {line.strip()!r}")
        yield where, fields


def _number(text: str, where: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise RecordingError(f"{where}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise RecordingError(f"{where}: {text!r} is not a finite number")
    return value


def _whole(text: str, where: str, what: str) -> int:
    value = _number(text, where)
    if value != int(value):
        raise RecordingError(f"{where}: the {what} must be a whole number, got {text!r}")
    return int(value)


def _frame(text: str, where: str) -> int:
    frame = _whole(text, where, "frame number")
    if frame < 0:
        raise RecordingError(f"{where}: frame numbers start at 0, got {frame}")
    return frame
