"""The site description: cameras, zones and thresholds, loaded from YAML or JSON and validated.

A site file is what a technician edits. Every mistake in it gets one message that names the file,
the field and the camera or zone, never a traceback::

    site.yaml: cameras[2] (id 'gate-b').intrinsics.fx: Input should be greater than 0

Units are metres and degrees; the world frame has X, Y on the floor and Z up.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Mapping
from functools import cached_property
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar

import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, field_validator, model_validator

from bevflow.camera import Camera, make_camera, rotation_from_vector, rotation_from_ypr
from bevflow.detect.providers import DEFAULT_PROVIDERS, check_providers

log = logging.getLogger(__name__)

PositiveFloat = Annotated[float, Field(gt=0)]


class _Strict(BaseModel):
    # A site file never needs .inf or .nan; they would only surface later as NaN positions.
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


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


MONITORED_EDGE_MARGIN_M = 0.5

# What a site file may say, checked when it is read. Beyond the hard limits the value cannot be
# right and the site is refused, naming the field; between them and the usual range it is only
# odd, and loading logs a warning (``odd_values``).
# A ceiling fisheye looks down on people: at 2 m a 1.7 m person's head is at the lens already. A
# pinhole camera may look from a wall (as WILDTRACK's, at about 1.5 to 2 m), but not from the floor.
CAMERA_HEIGHT_LIMITS_M = {"fisheye": (2.0, 100.0), "pinhole": (0.5, 100.0)}
CAMERA_HEIGHT_USUAL_M = {"fisheye": (2.5, 15.0), "pinhole": (1.5, 15.0)}  # the paper's halls: 3.3 to 8.1 m
# The paper claims people are placed well up to 10 m from below a camera (``bevflow.planning``).
MONITORED_RADIUS_LIMIT_M = 30.0
MONITORED_RADIUS_USUAL_M = 10.0


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
    detector: str | None = Field(
        default=None,
        description="detector model name (an ONNX file, a shipped model, rim-tiles or rim-tiles:MODEL); default by height",
    )

    @field_validator("distortion")
    @classmethod
    def _distortion_fits_model(cls, distortion: list[float], info: ValidationInfo) -> list[float]:
        model, n = info.data.get("model"), len(distortion)
        if model == "fisheye" and n != 4:
            raise ValueError(f"a fisheye camera needs 4 coefficients k1..k4, got {n}")
        if model == "pinhole" and n not in (0, 4, 5, 8):
            raise ValueError(
                f"a pinhole camera needs 0, 4, 5 or 8 coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6]]), got {n}"
            )
        return distortion

    @model_validator(mode="after")
    def _one_pose(self) -> CameraConfig:
        if self.pose is None and self.extrinsics is None:
            raise ValueError("no 'pose' (position and angles) or 'extrinsics' (rvec, tvec); give one of them")
        if self.pose is not None and self.extrinsics is not None:
            raise ValueError("both 'pose' and 'extrinsics' are given; keep only one of them")
        return self

    @model_validator(mode="after")
    def _possible_mounting(self) -> CameraConfig:
        field = "pose.position" if self.pose is not None else "extrinsics"
        low, high = CAMERA_HEIGHT_LIMITS_M[self.model]
        height = self.height_m
        if not low <= height <= high:
            raise ValueError(f"{field}: the camera is {height:.2f} m above the floor; a {self.model} camera must hang "
                             f"between {low:g} and {high:g} m (Z up, the floor at 0)")
        radius = self.monitored_radius_m
        if radius is not None and radius > MONITORED_RADIUS_LIMIT_M:
            raise ValueError(f"monitored_radius_m: {radius:g} m cannot be watched from one camera "
                             f"(at most {MONITORED_RADIUS_LIMIT_M:g} m; about {MONITORED_RADIUS_USUAL_M:g} m is the farthest that works)")
        return self

    def build(self) -> Camera:
        if self.pose is not None:
            p = self.pose
            R = rotation_from_ypr(p.yaw_deg, p.pitch_deg, p.roll_deg)
            t = -R @ np.asarray(p.position, dtype=np.float64)
        else:
            assert self.extrinsics is not None
            R = rotation_from_vector(self.extrinsics.rvec)
            t = np.asarray(self.extrinsics.tvec, dtype=np.float64)
        return make_camera(self.model, self.intrinsics.matrix(), np.asarray(self.distortion), R, t, self.image_size)

    @property
    def reporting_radius_m(self) -> float | None:
        """How far from below the camera its detections are used: the monitored radius plus a
        margin, so a person straddling the circle's edge is not cut in and out of view. Beyond it
        a fisheye still finds people, but so small and oblique that their feet are off by a metre
        and fusion can no longer tell them from someone else."""
        return None if self.monitored_radius_m is None else self.monitored_radius_m + MONITORED_EDGE_MARGIN_M

    @property
    def height_m(self) -> float:
        """Mounting height above the floor (the camera centre's Z)."""
        return float(self.build().center[2])


CROWDED_SHARE = 0.8  # without a crowded_level of its own, a zone (or the site) is crowded from 80 % of capacity


def crowded_level_of(capacity: int | None) -> int | None:
    """The default crowded level for ``capacity`` (None without one); at least 1.

    >>> crowded_level_of(50), crowded_level_of(1), crowded_level_of(None)
    (40, 1, None)
    """
    return None if capacity is None else max(1, math.floor(CROWDED_SHARE * capacity))


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
        return crowded_level_of(self.capacity)


class Thresholds(_Strict):
    fusion_distance_m: PositiveFloat = 0.45
    social_distance_m: PositiveFloat = 2.0
    violation_min_duration_s: Annotated[float, Field(ge=0)] = 2.0
    group_after_s: Annotated[float, Field(gt=0)] | None = Field(
        default=60.0, description="pairs closer than the limit for this long are treated as a group; null disables"
    )
    group_walk_s: Annotated[float, Field(gt=0)] | None = Field(
        default=8.0,
        description=(
            "pairs closer than the limit that walk together (same direction and pace) for this long are "
            "treated as a group, and no alert is raised while they keep walking together; people standing "
            "close, as in a queue, are not grouped by this rule; null disables"
        ),
    )
    incident_min_duration_s: Annotated[float, Field(ge=0)] = Field(
        default=45.0, description="a group of people too close becomes an incident once it has lasted this long")
    incident_quiet_s: Annotated[float, Field(ge=0)] = Field(
        default=15.0, description="an incident closes after this long without anyone in it too close")
    incident_ack_min_s: Annotated[float, Field(ge=0)] = Field(
        default=60.0, description="an incident that ended shorter than this (and small) needs no acknowledgement")
    incident_companion_window_s: Annotated[float, Field(ge=0)] = Field(
        default=10.0, description="people already close within this long of being first seen, and close for most of "
        "the next as long, came in together (bevflow.analytics.companions): their closeness opens no incident; 0 "
        "turns the rule off")
    site_capacity: Annotated[int, Field(ge=0)] | None = None
    capacity_hysteresis: Annotated[int, Field(ge=0)] = 2
    capacity_min_duration_s: Annotated[float, Field(ge=0)] = Field(
        default=0.0, description="an over-capacity alert starts only once the count has stayed over capacity this long "
        "(a count flickering across the limit for a second is not an alert)")
    track_activate_hits: Annotated[int, Field(ge=1)] = 3
    track_max_misses: Annotated[int, Field(ge=1)] = 5
    track_gate_m: PositiveFloat = 1.5
    track_hypotheses: Annotated[int, Field(ge=1, le=100)] = Field(
        default=20, description="ways of matching tracks to people held open for two seconds before deciding "
        "(bevflow.tracking.hypotheses); 1 decides at every update. 20 holds identities better in a dense room "
        "(docs/RESULTS.md, CMC2). Past 2,000 tracks divided by this number (100 for 20) fewer are held, one from "
        "2,000 tracks, so that the work per update stays a few times that of deciding at once")
    track_views: bool | None = Field(
        default=None, description="true: the tracker takes each camera's views itself, at most one per camera and "
        "person, and fuses only the views no track took to find new people (bevflow.tracking.views); false fuses "
        "every view first and tracks the fused people; null (the default) takes the views where every camera looks "
        "more than 45 degrees away from straight down (side views) and fuses first otherwise. Views held identities "
        "better with four side cameras in a dense room, and left false tracks with ceiling fisheyes and the shipped "
        "detectors (docs/RESULTS.md)")


class BusTls(_Strict):
    """TLS for the message bus between hosts. Paths to PEM files on each host (relative paths
    are taken from the working directory of the service). ``cert`` and ``key`` are this host's
    certificate, needed where a service or router listens (and on clients with ``mutual``);
    ``root_ca`` is the authority that signed the certificates of the hosts this one connects to."""

    root_ca: str | None = None
    cert: str | None = None
    key: str | None = None
    mutual: bool = Field(default=False, description="also require clients to show a certificate signed by root_ca")

    @model_validator(mode="after")
    def _cert_with_key(self) -> BusTls:
        if (self.cert is None) != (self.key is None):
            raise ValueError("give 'cert' and 'key' together (this host's certificate and its private key)")
        if self.root_ca is None and self.cert is None:
            raise ValueError("give 'root_ca' (to check the router) and/or 'cert' and 'key' (to listen)")
        if self.mutual and (self.root_ca is None or self.cert is None):
            raise ValueError("'mutual' needs 'root_ca', 'cert' and 'key'")
        return self


class BusAuth(_Strict):
    """User name and password on the message bus. The password itself never goes in the site
    file: ``password_file`` names a file holding it, ``password_env`` an environment variable.
    A router checks clients against ``users_file``, lines of ``user:password``."""

    user: Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")] | None = None
    password_file: str | None = None
    password_env: Annotated[str, Field(min_length=1)] | None = None
    users_file: str | None = None

    @model_validator(mode="before")
    @classmethod
    def _no_plaintext_password(cls, raw: Any) -> Any:
        if isinstance(raw, dict) and "password" in raw:
            raise ValueError("never write the password in the site file: put it in a file ('password_file') "
                             "or an environment variable ('password_env')")
        return raw

    @model_validator(mode="after")
    def _user_with_password(self) -> BusAuth:
        sources = (self.password_file is not None) + (self.password_env is not None)
        if self.user is not None and sources != 1:
            raise ValueError("give the user's password as exactly one of 'password_file' or 'password_env'")
        if self.user is None and sources:
            raise ValueError("a password without a 'user'")
        if self.user is None and self.users_file is None:
            raise ValueError("give 'user' (and its password) to log in, and/or 'users_file' to check others")
        return self


class BusSecurity(_Strict):
    """How the hosts of a site secure the message bus (Zenoh) between them."""

    tls: BusTls | None = None
    auth: BusAuth | None = None


class DetectorRange(_Strict):
    """Cameras mounted from ``min_height_m`` (inclusive) to ``max_height_m`` (exclusive) that name
    no ``detector`` of their own use ``model``: an ONNX file (relative to the site file), the
    name of a model shipped with bevflow, ``rim-tiles``, or ``rim-tiles:MODEL`` (rim tiles with
    MODEL on the tiles)."""

    min_height_m: Annotated[float, Field(ge=0)] = 0.0
    max_height_m: PositiveFloat
    model: Annotated[str, Field(min_length=1)]

    @model_validator(mode="after")
    def _not_empty(self) -> DetectorRange:
        if not self.min_height_m < self.max_height_m:
            raise ValueError(f"min_height_m {self.min_height_m} must be below max_height_m {self.max_height_m}")
        return self


# The lists of a site whose entries have ids of their own.
_Identified = TypeVar("_Identified", "CameraConfig", "Zone")


class Site(_Strict):
    site: Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")] = "site"
    cameras: Annotated[list[CameraConfig], Field(min_length=1)]
    zones: list[Zone] = Field(default_factory=list)
    thresholds: Thresholds = Field(default_factory=Thresholds)
    floor: tuple[float, float, float, float] | None = Field(
        default=None, description="floor extent (xmin, ymin, xmax, ymax) in metres, for maps"
    )
    bus: BusSecurity | None = Field(default=None, description="TLS and passwords on the message bus between hosts")
    detectors: list[DetectorRange] | None = Field(
        default=None, description="detector model by mounting height; default: the shipped model for every height"
    )
    detector_providers: list[str] = Field(
        default_factory=lambda: list(DEFAULT_PROVIDERS),
        description="ONNX Runtime execution providers for the detector, most wanted first (tensorrt, cuda, openvino, "
        "cpu); those the installed build lacks are skipped with a warning, and the CPU is always the last resort",
    )

    @property
    def crowded_level(self) -> int | None:
        """The whole site's crowded level: the default share of ``thresholds.site_capacity``."""
        return crowded_level_of(self.thresholds.site_capacity)

    @field_validator("detector_providers")
    @classmethod
    def _known_providers(cls, names: list[str]) -> list[str]:
        return check_providers(names)

    @field_validator("detectors")
    @classmethod
    def _ranges_do_not_overlap(cls, ranges: list[DetectorRange] | None) -> list[DetectorRange] | None:
        ordered = sorted(ranges or [], key=lambda r: r.min_height_m)
        for a, b in zip(ordered, ordered[1:], strict=False):
            if b.min_height_m < a.max_height_m:
                raise ValueError(f"detector height ranges overlap: [{a.min_height_m:g}, {a.max_height_m:g}) "
                                 f"and [{b.min_height_m:g}, {b.max_height_m:g})")
        return ranges

    @field_validator("cameras", "zones")
    @classmethod
    def _unique_ids(cls, items: list[_Identified], info: ValidationInfo) -> list[_Identified]:
        where: dict[str, list[int]] = {}
        for i, item in enumerate(items):
            where.setdefault(item.id, []).append(i)
        repeated = [
            f"id {i!r} is used by {' and '.join(f'{info.field_name}[{k}]' for k in at)}"
            for i, at in where.items()
            if len(at) > 1
        ]
        if repeated:
            raise ValueError(f"ids must be unique; {'; '.join(repeated)}")
        return items

    @model_validator(mode="after")
    def _zones_on_the_floor(self) -> Site:
        for k, zone in enumerate(self.zones):
            if self.floor is not None and outside_floor(zone.polygon, self.floor) == "entirely":
                raise ValueError(f"zones[{k}] (id {zone.id!r}).polygon: the zone lies entirely outside the floor "
                                 f"{list(self.floor)}")
        return self

    @field_validator("floor")
    @classmethod
    def _floor_has_area(
        cls, floor: tuple[float, float, float, float] | None
    ) -> tuple[float, float, float, float] | None:
        if floor is not None and not (floor[2] > floor[0] and floor[3] > floor[1]):
            raise ValueError(f"expected (xmin, ymin, xmax, ymax) with xmax > xmin and ymax > ymin, got {list(floor)}")
        return floor

    @cached_property
    def built_cameras(self) -> dict[str, Camera]:
        """Camera models by id, in file order; built once per site object."""
        return {c.id: c.build() for c in self.cameras}

    def model_copy(self, *, update: Mapping[str, Any] | None = None, deep: bool = False) -> Site:
        """As pydantic's, but without the cached camera models, which ``update`` may outdate."""
        copy = super().model_copy(update=update, deep=deep)
        for name in _CACHED:
            copy.__dict__.pop(name, None)
        return copy

    @cached_property
    def camera_ids(self) -> list[str]:
        """Camera ids in file order; a camera's position here is its index in ``Cylinders.camera``."""
        return [c.id for c in self.cameras]

    def camera(self, camera_id: str) -> Camera:
        """The built camera model of ``camera_id``; KeyError naming the known ids otherwise."""
        if camera_id not in self.built_cameras:
            raise KeyError(self._unknown(camera_id))
        return self.built_cameras[camera_id]

    def camera_index(self, camera_id: str) -> int:
        """Position of ``camera_id`` in ``cameras``; ValueError naming the known ids otherwise."""
        if camera_id not in self.camera_ids:
            raise ValueError(self._unknown(camera_id))
        return self.camera_ids.index(camera_id)

    def _unknown(self, camera_id: str) -> str:
        return f"site {self.site!r} has no camera {camera_id!r}; its cameras are {', '.join(self.camera_ids)}"


_CACHED = ("built_cameras", "camera_ids")


def outside_floor(polygon: list[tuple[float, float]], floor: tuple[float, float, float, float]) -> str:
    """Whether a polygon lies "entirely", "partly" or "not" outside a floor rectangle (by its
    corners and bounding box: a zone is a few corners drawn by hand)."""
    xs, ys = [p[0] for p in polygon], [p[1] for p in polygon]
    x0, y0, x1, y1 = floor
    if max(xs) <= x0 or min(xs) >= x1 or max(ys) <= y0 or min(ys) >= y1:
        return "entirely"
    inside = all(x0 <= x <= x1 and y0 <= y <= y1 for x, y in polygon)
    return "not" if inside else "partly"


def odd_values(site: Site) -> list[str]:
    """What is possible but unusual in a site, one line each naming the field: worth a look
    before the site runs (loading logs them as warnings)."""
    odd = []
    for k, camera in enumerate(site.cameras):
        where = f"cameras[{k}] (id {camera.id!r})"
        low, high = CAMERA_HEIGHT_USUAL_M[camera.model]
        if not low <= camera.height_m <= high:
            odd.append(f"{where}: hangs {camera.height_m:.2f} m above the floor; {camera.model} cameras usually hang "
                       f"{low:g} to {high:g} m")
        radius = camera.monitored_radius_m
        if radius is not None and radius > min(MONITORED_RADIUS_USUAL_M, 4 * camera.height_m):
            odd.append(f"{where}.monitored_radius_m: {radius:g} m is more than a camera at {camera.height_m:.2f} m "
                       f"usually places people well (about {min(MONITORED_RADIUS_USUAL_M, 4 * camera.height_m):.1f} m)")
    for k, zone in enumerate(site.zones):
        if site.floor is not None and outside_floor(zone.polygon, site.floor) == "partly":
            odd.append(f"zones[{k}] (id {zone.id!r}).polygon: part of the zone lies outside the floor {list(site.floor)}")
    return odd


class SiteError(ValueError):
    """A site file that cannot be used. ``str()`` is the message to show the user."""


BUILTIN_SITES = Path(__file__).resolve().parent / "data" / "sites"


def builtin_site_names() -> list[str]:
    """Sites shipped with bevflow, usable by name wherever a site file is asked for."""
    return sorted(p.stem for p in BUILTIN_SITES.glob("*.yaml"))


def load_site_or_builtin(value: str | Path) -> Site:
    """A site file, or the name of a site shipped with bevflow (``demo-hall``, ``example-hall``)."""
    path = Path(value)
    if not path.exists() and path.suffix == "" and len(path.parts) == 1:
        shipped = BUILTIN_SITES / f"{value}.yaml"
        if shipped.is_file():
            return load_site(shipped)
        raise SiteError(f"{value}: no such site file, and no built-in site of that name "
                        f"(built-in: {', '.join(builtin_site_names())})")
    return load_site(path)


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
        raise SiteError(f"{source}: not valid {fmt.upper()}{_syntax_error_place(exc)}") from None
    if raw is None:
        raise SiteError(f"{source}: the file is empty; a site needs at least a 'cameras' list")
    if not isinstance(raw, dict):
        raise SiteError(f"{source}: expected a mapping with 'cameras' at the top, got a {type(raw).__name__}")
    try:
        site = Site.model_validate(raw)
    except ValidationError as exc:
        raise SiteError("\n".join(_describe(source, raw, err) for err in exc.errors())) from None
    for line in odd_values(site):
        log.warning("%s: %s", source, line)
    return site


def _syntax_error_place(exc: json.JSONDecodeError | yaml.YAMLError) -> str:
    if isinstance(exc, json.JSONDecodeError):
        return f" at line {exc.lineno}, column {exc.colno}: {exc.msg}"
    mark = getattr(exc, "problem_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
    problem = getattr(exc, "problem", None)
    return f"{where}: {problem}" if problem else where


# pydantic's wording, where a technician needs something plainer.
_PLAIN_MESSAGES = {
    "extra_forbidden": "unknown field (misspelt, or in the wrong section?)",
    "string_pattern_mismatch": "use only letters, digits, '_', '.' and '-'",
    "finite_number": "must be a finite number",
}


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
            # A misspelt key may be empty or hold control characters: quote it so the message
            # stays one readable line per mistake.
            name = str(loc) if str(loc).isprintable() and str(loc).strip() else repr(loc)
            parts.append(("." if parts else "") + name)
            node = node.get(loc) if isinstance(node, dict) else None
    field = "".join(parts) or "(top level)"
    message = _PLAIN_MESSAGES.get(err["type"], err["msg"])
    if err["type"] == "value_error":
        message = str(err.get("ctx", {}).get("error", message))  # without pydantic's "Value error, "
    return f"{source}: {field}: {message}"


class _SiteDumper(yaml.SafeDumper):
    """Writes lists of numbers inline (``position: [6.5, 4.2, 5.5]``), as a person would."""


def _represent_list(dumper: yaml.SafeDumper, value: list[Any]) -> yaml.Node:
    flat = all(isinstance(v, (int, float)) for v in value)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", value, flow_style=flat)


_SiteDumper.add_representer(list, _represent_list)


def dump_site(site: Site) -> str:
    """YAML text of a site, in the field order of the models."""
    return yaml.dump(site.model_dump(mode="json", exclude_none=True), Dumper=_SiteDumper, sort_keys=False)
