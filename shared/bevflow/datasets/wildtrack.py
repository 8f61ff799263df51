"""The WILDTRACK multi-camera pedestrian dataset: calibrated cameras, per-view boxes, ground truth.

Layout read (the dataset's own)::

    ROOT/calibrations/extrinsic/extr_<camera>.xml        rvec (radians), tvec (CENTIMETRES)
    ROOT/calibrations/intrinsic_zero/intr_<camera>.xml   K and distortion of the undistorted images
    ROOT/annotations_positions/<frame>.json              one file per annotated frame

Everything comes out in the project's units: metres, world Z up. The extrinsics map world to
camera as in OpenCV; their translation is divided by 100. ``intrinsic_zero`` is used because the
published images (and the annotation boxes) are the undistorted ones.

Each annotation is a person with a ``positionID`` on a 480 × 1440 ground grid, X first, 2.5 cm
spacing, origin (−3.0 m, −9.0 m)::

    X = −3.0 + 0.025 · (id mod 480)        Y = −9.0 + 0.025 · (id div 480)

and one box per view (``viewNum``). A view whose four coordinates are all −1 does not see the
person; a single −1 coordinate is a box cut by the image border and is kept. Boxes are kept as
annotated, so some extend past the 1920 × 1080 image.

Views 0..6 are CVLab1..4, IDIAP1..3. Checked on the 200 public frames: projecting each person's
ground-truth feet through the camera of that view lands within a median 3–16 px of the bottom
centre of the person's box, in every view.

Frame numbers count tenths of a second: the 200 public annotated frames 0, 5, …, 995 are 0.5 s
apart (2 per second), so a walking person moves about 0.7 m between two of them.

The annotated area is the extent of the grid. Only estimates inside it are scored, as is
standard for WILDTRACK: people outside it are not annotated, so detections there are not errors.
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from bevflow.camera import PinholeCamera, rotation_from_vector
from bevflow.detections import Boxes

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

CAMERA_NAMES = ("CVLab1", "CVLab2", "CVLab3", "CVLab4", "IDIAP1", "IDIAP2", "IDIAP3")
"""The camera of annotation view k is ``CAMERA_NAMES[k]``."""
IMAGE_SIZE = (1920, 1080)
GRID_SHAPE = (480, 1440)  # (nx, ny): positionID = ix + 480 · iy
GRID_ORIGIN_M = (-3.0, -9.0)
GRID_STEP_M = 0.025
SECONDS_PER_FRAME_NUMBER = 0.1  # the frames were annotated every 5th of a 10-per-second sequence: 0.5 s apart
_FRAME_FILE = re.compile(r"^(\d+)\.json$")


class WildtrackError(ValueError):
    """A WILDTRACK folder or file that cannot be read; the message names the path."""


@dataclass(frozen=True)
class FloorArea:
    """An axis-aligned rectangle on the floor (metres), bounds included."""

    x_min: float
    x_max: float
    y_min: float
    y_max: float

    def contains(self, xy: FloatArray) -> NDArray[np.bool_]:
        """(N, 2) floor points -> (N,) inside; NaN points are outside."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        with np.errstate(invalid="ignore"):
            return (p[:, 0] >= self.x_min) & (p[:, 0] <= self.x_max) & (p[:, 1] >= self.y_min) & (p[:, 1] <= self.y_max)


ANNOTATED_AREA = FloorArea(
    x_min=GRID_ORIGIN_M[0],
    x_max=GRID_ORIGIN_M[0] + GRID_STEP_M * (GRID_SHAPE[0] - 1),
    y_min=GRID_ORIGIN_M[1],
    y_max=GRID_ORIGIN_M[1] + GRID_STEP_M * (GRID_SHAPE[1] - 1),
)
"""The 480 × 1440 grid's extent: X in [−3.0, 8.975] m, Y in [−9.0, 26.975] m."""


def position_to_xy(position_ids: Sequence[int] | IntArray) -> FloatArray:
    """Grid positionIDs (N,) -> floor points (N, 2) in metres."""
    ids = np.asarray(position_ids, dtype=np.int64).reshape(-1)
    nx = GRID_SHAPE[0]
    return np.stack(
        [GRID_ORIGIN_M[0] + GRID_STEP_M * (ids % nx), GRID_ORIGIN_M[1] + GRID_STEP_M * (ids // nx)], axis=1
    ).astype(np.float64)


@dataclass(frozen=True)
class ViewBoxes:
    """One camera's annotated boxes in one frame, and the person each box belongs to."""

    boxes: Boxes
    person_ids: IntArray


@dataclass(frozen=True)
class WildtrackFrame:
    """One annotated frame: ground truth on the floor and the boxes of every camera.

    ``views[i]`` belongs to ``WildtrackDataset.cameras[i]``."""

    frame: int
    person_ids: IntArray
    feet_xy: FloatArray
    views: tuple[ViewBoxes, ...]


@dataclass(frozen=True)
class WildtrackDataset:
    root: Path
    camera_ids: tuple[str, ...]
    cameras: tuple[PinholeCamera, ...]
    view_numbers: tuple[int, ...]
    """The annotation ``viewNum`` of each camera (its index in ``CAMERA_NAMES``)."""
    frames: tuple[WildtrackFrame, ...]
    area: FloorArea = ANNOTATED_AREA
    seconds_per_frame_number: float = SECONDS_PER_FRAME_NUMBER
    """Capture time of frame f is f × this (seconds); what a tracker needs to predict motion."""


def load_wildtrack(root: Path | str) -> WildtrackDataset:
    """Read a WILDTRACK folder: the cameras whose calibration is present, and every annotated frame
    (sorted by frame number). Raises ``WildtrackError`` for a missing folder or a malformed file."""
    root = Path(root)
    if not root.is_dir():
        raise WildtrackError(f"{root}: no such folder (expected a WILDTRACK dataset root)")
    names = [n for n in CAMERA_NAMES if (root / "calibrations" / "extrinsic" / f"extr_{n}.xml").is_file()]
    if not names:
        raise WildtrackError(f"{root / 'calibrations' / 'extrinsic'}: no extr_<camera>.xml for any of {', '.join(CAMERA_NAMES)}")
    cameras = tuple(load_camera(root / "calibrations", n) for n in names)
    view_numbers = tuple(CAMERA_NAMES.index(n) for n in names)
    annotations = root / "annotations_positions"
    if not annotations.is_dir():
        raise WildtrackError(f"{annotations}: no such folder (expected one JSON file per annotated frame)")
    files = sorted((int(m.group(1)), p) for p in annotations.iterdir() if (m := _FRAME_FILE.match(p.name)))
    if not files:
        raise WildtrackError(f"{annotations}: no <frame>.json annotation files")
    frames = tuple(read_frame(path, frame, view_numbers) for frame, path in files)
    return WildtrackDataset(root=root, camera_ids=tuple(names), cameras=cameras, view_numbers=view_numbers, frames=frames)


def load_camera(calibrations: Path, name: str) -> PinholeCamera:
    """One camera from ``extrinsic/extr_<name>.xml`` and ``intrinsic_zero/intr_<name>.xml``, in metres."""
    extrinsic = calibrations / "extrinsic" / f"extr_{name}.xml"
    intrinsic = calibrations / "intrinsic_zero" / f"intr_{name}.xml"
    rvec = _xml_numbers(extrinsic, "rvec", 3)
    tvec_cm = _xml_numbers(extrinsic, "tvec", 3)
    K = _xml_numbers(intrinsic, "camera_matrix/data", 9).reshape(3, 3)
    dist = _xml_numbers(intrinsic, "distortion_coefficients/data", None)
    if dist.size not in (4, 5, 8):
        raise WildtrackError(f"{intrinsic}: distortion_coefficients has {dist.size} numbers, expected 4, 5 or 8")
    R = rotation_from_vector(rvec)
    return PinholeCamera(K=K, dist=dist, R=R, t=tvec_cm / 100.0, image_size=IMAGE_SIZE)


def _xml_numbers(path: Path, tag: str, count: int | None) -> FloatArray:
    # The files look like OpenCV FileStorage but rvec/tvec are bare text nodes, which
    # cv2.FileStorage does not read as matrices; plain XML parsing handles both forms.
    if not path.is_file():
        raise WildtrackError(f"{path}: no such file")
    try:
        node = ET.parse(path).getroot().find(tag)
    except ET.ParseError as exc:
        raise WildtrackError(f"{path}: not valid XML ({exc})") from None
    if node is None or node.text is None:
        raise WildtrackError(f"{path}: missing <{tag}>")
    try:
        values = np.array([float(v) for v in node.text.split()], dtype=np.float64)
    except ValueError:
        raise WildtrackError(f"{path}: <{tag}> holds something other than numbers") from None
    if count is not None and values.size != count:
        raise WildtrackError(f"{path}: <{tag}> has {values.size} numbers, expected {count}")
    if not np.isfinite(values).all():
        raise WildtrackError(f"{path}: <{tag}> holds a non-finite number")
    return values


def read_frame(path: Path, frame: int, view_numbers: Sequence[int]) -> WildtrackFrame:
    """One ``annotations_positions`` file. ``view_numbers`` are the annotation views that have a
    camera, in camera order; a visible box in any other view is an error."""
    try:
        people = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise WildtrackError(f"{path}: not readable JSON ({exc})") from None
    if not isinstance(people, list):
        raise WildtrackError(f"{path}: expected a list of people, got {type(people).__name__}")
    camera_of_view = {v: i for i, v in enumerate(view_numbers)}
    person_ids, positions = [], []
    per_camera: list[tuple[list[list[float]], list[int]]] = [([], []) for _ in view_numbers]
    for k, person in enumerate(people):
        try:
            pid, position, views = int(person["personID"]), int(person["positionID"]), person["views"]
            boxes = [(int(v["viewNum"]), [float(v[c]) for c in ("xmin", "ymin", "xmax", "ymax")]) for v in views]
        except (KeyError, TypeError, ValueError) as exc:
            raise WildtrackError(f"{path}: person #{k} is malformed ({type(exc).__name__}: {exc})") from None
        if not 0 <= position < GRID_SHAPE[0] * GRID_SHAPE[1]:
            raise WildtrackError(f"{path}: person {pid} has positionID {position}, outside the 480x1440 grid")
        person_ids.append(pid)
        positions.append(position)
        for view, xyxy in boxes:
            if all(c == -1 for c in xyxy):
                continue  # the person is not in this view
            if view not in camera_of_view:
                raise WildtrackError(f"{path}: person {pid} has a box in view {view}, which has no camera calibration")
            if xyxy[2] <= xyxy[0] or xyxy[3] <= xyxy[1]:
                raise WildtrackError(f"{path}: person {pid} has an empty box {xyxy} in view {view}")
            rows, ids = per_camera[camera_of_view[view]]
            rows.append(xyxy)
            ids.append(pid)
    views = tuple(
        ViewBoxes(boxes=Boxes(xyxy=np.array(rows, dtype=np.float64).reshape(-1, 4)), person_ids=np.array(ids, dtype=np.int64))
        for rows, ids in per_camera
    )
    return WildtrackFrame(
        frame=frame,
        person_ids=np.array(person_ids, dtype=np.int64),
        feet_xy=position_to_xy(positions),
        views=views,
    )
