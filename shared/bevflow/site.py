"""The site description: cameras, zones and thresholds, loaded from YAML or JSON and validated.

A site file is what a technician edits. Every mistake in it gets one message that names the file,
the field and the camera or zone, never a traceback::

    site.yaml: cameras[2] (id 'gate-b').intrinsics.fx: Input should be greater than 0

Units are metres and degrees; the world frame has X, Y on the floor and Z up.
"""

from __future__ import annotations

import json
import math
from functools import cached_property
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from bevflow.camera import Camera, make_camera, rotation_from_ypr

PositiveFloat = Annotated[float, Field(gt=0)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Intrinsics(_Strict):
    fx: PositiveFloat
    fy: PositiveFloat
    cx: float
    cy: float
    skew: float = 0.0

    def matrix(self) -> np.ndarray:
        return np.array([[self.fx, self.skew, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


class Pose(_Strict):
    """Where a camera hangs and how it is turned; a camera looking straight down has all angles 0.
    ``yaw_deg`` turns it about the vertical, ``pitch_deg`` tilts it away from vertical."""

    position: tuple[float, float, float]
    yaw_deg: float = 0.0
    pitch_deg: float = 0.0
    roll_deg: float = 0.0


class Extrinsics(_Strict):
    """OpenCV's world-to-camera rotation vector and translation, in metres."""

    rvec: tuple[float, float, float]
    tvec: tuple[float, float, float]


class CameraConfig(_Strict):
    id: Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")]
    model: Literal["fisheye", "pinhole"] = "fisheye"
    image_size: tuple[Annotated[int, Field(gt=0)], Annotated[int, Field(gt=0)]]
    intrinsics: Intrinsics
    distortion: list[float] = Field(default_factory=lambda: [0.0, 0.0, 0.0, 0.0])
    pose: Pose | None = None
    extrinsics: Extrinsics | None = None
    monitored_radius_m: PositiveFloat | None = None
    source: str | None = Field(default=None, description="stream URL, video file or image folder")
    detector: str | None = Field(default=None, description="detector model name; default by height")

    @model_validator(mode="after")
    def _one_pose(self) -> CameraConfig:
        if (self.pose is None) == (self.extrinsics is None):
            raise ValueError("give exactly one of 'pose' (position and angles) or 'extrinsics' (rvec, tvec)")
        n = len(self.distortion)
        if self.model == "fisheye" and n != 4:
            raise ValueError(f"a fisheye camera needs 4 distortion coefficients k1..k4, got {n}")
        if self.model == "pinhole" and n not in (0, 4, 5, 8):
            raise ValueError(f"a pinhole camera needs 0, 4, 5 or 8 distortion coefficients, got {n}")
        return self

    def build(self) -> Camera:
        if self.pose is not None:
            p = self.pose
            R = rotation_from_ypr(p.yaw_deg, p.pitch_deg, p.roll_deg)
            t = -R @ np.asarray(p.position, dtype=np.float64)
        else:
            import cv2

            assert self.extrinsics is not None
            R = cv2.Rodrigues(np.asarray(self.extrinsics.rvec, dtype=np.float64))[0]
            t = np.asarray(self.extrinsics.tvec, dtype=np.float64)
        return make_camera(self.model, self.intrinsics.matrix(), np.asarray(self.distortion), R, t, self.image_size)

    @property
    def height_m(self) -> float:
        """Mounting height above the floor (the camera centre's Z)."""
        return float(self.build().center[2])


class Zone(_Strict):
    id: Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")]
    name: str = ""
    polygon: Annotated[list[tuple[float, float]], Field(min_length=3)]
    capacity: Annotated[int, Field(ge=0)] | None = None
    crowded_level: Annotated[int, Field(ge=0)] | None = Field(
        default=None, description="occupancy above which an interval counts as crowded; default 80 % of capacity"
    )

    @field_validator("polygon")
    @classmethod
    def _has_area(cls, polygon: list[tuple[float, float]]) -> list[tuple[float, float]]:
        xy = np.asarray(polygon)
        area = 0.5 * abs(np.dot(xy[:, 0], np.roll(xy[:, 1], 1)) - np.dot(xy[:, 1], np.roll(xy[:, 0], 1)))
        if area < 1e-6:
            raise ValueError("polygon has no area (are its points in a line?)")
        return polygon

    @property
    def effective_crowded_level(self) -> int | None:
        if self.crowded_level is not None:
            return self.crowded_level
        return None if self.capacity is None else max(1, math.floor(0.8 * self.capacity))


class Thresholds(_Strict):
    fusion_distance_m: PositiveFloat = 0.45
    social_distance_m: PositiveFloat = 2.0
    violation_min_duration_s: Annotated[float, Field(ge=0)] = 2.0
    group_after_s: Annotated[float, Field(gt=0)] | None = Field(
        default=60.0, description="pairs closer than the limit for this long are treated as a group; null disables"
    )
    site_capacity: Annotated[int, Field(ge=0)] | None = None
    capacity_hysteresis: Annotated[int, Field(ge=0)] = 2
    track_activate_hits: Annotated[int, Field(ge=1)] = 3
    track_max_misses: Annotated[int, Field(ge=1)] = 5
    track_gate_m: PositiveFloat = 1.5


class Site(_Strict):
    site: Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")] = "site"
    cameras: Annotated[list[CameraConfig], Field(min_length=1)]
    zones: list[Zone] = Field(default_factory=list)
    thresholds: Thresholds = Field(default_factory=Thresholds)
    floor: tuple[float, float, float, float] | None = Field(
        default=None, description="floor extent (xmin, ymin, xmax, ymax) in metres, for maps"
    )

    @model_validator(mode="after")
    def _unique_ids(self) -> Site:
        for kind, ids in (("camera", [c.id for c in self.cameras]), ("zone", [z.id for z in self.zones])):
            dup = sorted({i for i in ids if ids.count(i) > 1})
            if dup:
                raise ValueError(f"{kind} ids must be unique; repeated: {', '.join(dup)}")
        return self

    @cached_property
    def built_cameras(self) -> dict[str, Camera]:
        return {c.id: c.build() for c in self.cameras}

    def camera(self, camera_id: str) -> Camera:
        return self.built_cameras[camera_id]

    def camera_index(self, camera_id: str) -> int:
        return [c.id for c in self.cameras].index(camera_id)


class SiteError(ValueError):
    """A site file that cannot be used. ``str()`` is the message to show the user."""


def load_site(path: str | Path) -> Site:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SiteError(f"{path}: cannot read the site file ({exc.strerror or exc})") from None
    return parse_site(text, source=str(path), fmt="json" if path.suffix.lower() == ".json" else "yaml")


def parse_site(text: str, source: str = "<site>", fmt: Literal["yaml", "json"] = "yaml") -> Site:
    try:
        raw = json.loads(text) if fmt == "json" else yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        if isinstance(exc, json.JSONDecodeError):
            where = f" at line {exc.lineno}, column {exc.colno}"
        raise SiteError(f"{source}: not valid {fmt.upper()}{where}") from None
    if not isinstance(raw, dict):
        raise SiteError(f"{source}: expected a mapping with 'cameras' at the top, got {type(raw).__name__}")
    try:
        return Site.model_validate(raw)
    except ValidationError as exc:
        raise SiteError("\n".join(_describe(source, raw, err) for err in exc.errors())) from None


def _describe(source: str, raw: dict[str, Any], err: Any) -> str:
    parts: list[str] = []
    node: Any = raw
    for loc in err["loc"]:
        if isinstance(loc, int):
            label = f"[{loc}]"
            item = node[loc] if isinstance(node, list) and loc < len(node) else None
            if isinstance(item, dict) and "id" in item:
                label += f" (id {item['id']!r})"
            parts.append(label)
            node = item
        else:
            parts.append(("." if parts else "") + str(loc))
            node = node.get(loc) if isinstance(node, dict) else None
    field = "".join(parts) or "(top level)"
    return f"{source}: {field}: {err['msg']}"


def dump_site(site: Site) -> str:
    """YAML text of a site, in the field order of the models."""
    return yaml.safe_dump(site.model_dump(mode="json", exclude_none=True), sort_keys=False)
