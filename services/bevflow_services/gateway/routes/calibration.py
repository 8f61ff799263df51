"""``/api/calibration``: what the installer's calibration page needs (``bevflow_dashboard/calibration.html``).

- ``GET  /api/calibration``: the site as the site file now says (it may have changed since the
  gateway started), whether it can be saved, and each camera's pose, frame source and drift state;
- ``GET  /api/calibration/cameras/{id}/frame``: a JPEG still of the camera: its latest frame, or,
  when none has arrived, its view of the floor's metre grid drawn through the current calibration;
- ``POST /api/calibration/cameras/{id}/solve``: the pose from image <-> floor points, with each
  point's error (nothing is written);
- ``PUT  /api/calibration/cameras/{id}/extrinsics``: the same, written into the site file;
- ``GET  /api/calibration/consistency``: per overlapping camera pair, how far apart the two cameras
  put the same people (from the projectors' recent cylinders);
- ``GET  /api/calibration/drift``: per camera, whether the tracker reports it moved.

The router is self-contained. What it reads from ``app.state``, all optional:

- ``site_file``: the ``Path`` of the site file (``site_file.site_file_of(args.site)``); without it the site
  is a built-in one or unknown, and saving answers 409;
- ``calibration_inputs``: a ``calibration_inputs.CalibrationInputs`` that the bus feeds with the projectors'
  cylinders (``put_cylinders``) and frames (``put_frame``, or on demand through its
  ``fetch_frame``); without one the router makes an empty one, and the page shows rendered frames
  and no consistency.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from pathlib import Path
from typing import Annotated, Literal

import cv2
import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Query, Response
from pydantic import BaseModel, Field
from starlette.requests import HTTPConnection

from bevflow.calibration.consistency import check_consistency
from bevflow.calibration.extrinsics import (
    CHECKABLE_POINTS,
    ExtrinsicsError,
    PoseFit,
    check_fit,
    estimate_pose,
    make_correspondences,
)
from bevflow.calibration.floor_grid import BACKGROUND, floor_extent, render_floor_grid
from bevflow.camera import Camera
from bevflow.planning import PlanError, usable_radius
from bevflow.schemas import CalibrationDrift, FrameHeader, iso_utc
from bevflow.site import Site, SiteError, load_site
from bevflow.site_edit import update_camera_file

from bevflow_services.gateway.calibration_inputs import CalibrationInputs
from bevflow_services.gateway.state import GatewayState

router = APIRouter(prefix="/api/calibration", tags=["calibration"])

MAX_RMS_PX = 3.0  # the same limits as `bevflow calibrate extrinsics`
MAX_GROUND_ERROR_M = 0.15
JPEG_QUALITY = 85


_INPUTS_LOCK = threading.Lock()
_SAVE_LOCK = threading.Lock()


def get_inputs(conn: HTTPConnection) -> CalibrationInputs:
    with _INPUTS_LOCK:
        inputs = getattr(conn.app.state, "calibration_inputs", None)
        if inputs is None:
            inputs = conn.app.state.calibration_inputs = CalibrationInputs()
        return inputs


def get_site_file(conn: HTTPConnection) -> Path | None:
    return getattr(conn.app.state, "site_file", None)


def get_current_site(conn: HTTPConnection) -> Site:
    """The site as its file says now (a save changes it), or the gateway's site without a file."""
    path = get_site_file(conn)
    if path is None:
        return conn.app.state.gateway.site
    try:
        return load_site(path)
    except SiteError as exc:
        raise HTTPException(409, f"the site file cannot be read now: {exc}") from None


InputsDep = Annotated[CalibrationInputs, Depends(get_inputs)]
SiteFileDep = Annotated[Path | None, Depends(get_site_file)]
CurrentSiteDep = Annotated[Site, Depends(get_current_site)]


def get_gateway(conn: HTTPConnection) -> GatewayState:
    return conn.app.state.gateway


GatewayDep = Annotated[GatewayState, Depends(get_gateway)]


# --- models -----------------------------------------------------------------------------------------
class CameraDrift(BaseModel):
    camera: str
    state: Literal["ok", "moved"] = Field(description="moved: the tracker reports that the camera's estimates shifted")
    shift_m: float | None = Field(default=None, description="how far its estimates shifted against reference_camera")
    reference_camera: str | None = None
    since: str | None = Field(default=None, description="when the shift was noticed, ISO-8601 UTC")
    alert_id: str | None = None


class CalibrationCamera(BaseModel):
    id: str
    model: Literal["fisheye", "pinhole"]
    image_size: tuple[int, int]
    position: tuple[float, float, float] = Field(description="camera centre in world metres, from the current pose")
    tilt_deg: float = Field(description="angle between the optical axis and straight down")
    monitored_radius_m: float | None
    coverage_radius_m: float | None = Field(
        description="the monitored radius, or where the site leaves it out, the usable radius at this height "
        "(as `bevflow plan` computes it for a fisheye); null for a pinhole without one")
    frame: Literal["live", "rendered"] = Field(description="live: a frame of the camera has been seen; rendered: none yet")
    drift: CameraDrift


class CalibrationSite(BaseModel):
    site: str
    site_file: str | None = Field(description="the file saves go to; null when the site is built in")
    editable: bool
    reason: str = Field(description="why saving is not possible; empty when it is")
    floor: tuple[float, float, float, float] = Field(description="floor extent for the plan (xmin, ymin, xmax, ymax)")
    zones: list[list[tuple[float, float]]]
    cameras: list[CalibrationCamera]
    min_points: int = CHECKABLE_POINTS
    max_rms_px: float = MAX_RMS_PX
    max_ground_error_m: float = MAX_GROUND_ERROR_M


class PointIn(BaseModel):
    name: str | None = Field(default=None, description="default: the point's number, from 1")
    pixel: tuple[float, float] = Field(description="u, v in pixels of the camera's full image")
    world: Annotated[list[float], Field(min_length=2, max_length=3)] = Field(description="x, y (floor) or x, y, z in metres")


class SolveRequest(BaseModel):
    points: list[PointIn]
    max_rms_px: Annotated[float, Field(gt=0)] = MAX_RMS_PX
    max_ground_error_m: Annotated[float, Field(gt=0)] = MAX_GROUND_ERROR_M


class PointError(BaseModel):
    name: str
    pixel: tuple[float, float]
    world: tuple[float, float, float]
    projected: tuple[float, float] | None = Field(description="where the solved pose puts the world point in the image")
    reprojection_px: float | None = Field(description="distance from pixel to projected; null if the pose cannot see it")
    ground_error_m: float | None = Field(description="distance on the floor from where the pixel lands to the world point")


class PoseSolution(BaseModel):
    camera: str
    rvec: tuple[float, float, float]
    tvec: tuple[float, float, float]
    position: tuple[float, float, float]
    tilt_deg: float
    rms_px: float | None
    rms_ground_m: float | None
    points: list[PointError]
    accepted: bool = Field(description="within max_rms_px and max_ground_error_m; only an accepted pose is saved")
    refusal: str | None = Field(description="why the pose would be refused")
    warnings: list[str]


class SavedPose(PoseSolution):
    site_file: str
    backup: str
    comments_kept: bool = Field(description="false if the file had to be written again without its comments")
    next: str = Field(description="what to do now")


class PairAgreement(BaseModel):
    camera_a: str
    camera_b: str
    samples: int
    median_offset_m: float
    median_offset: tuple[float, float]
    spread_m: float
    judged: bool = Field(description="enough samples (min_samples) to judge")
    agrees: bool | None = Field(description="median offset within the tolerance; null when not judged")


class ConsistencyReport(BaseModel):
    ticks: int = Field(description="ticks of recent projector output looked at")
    tolerance_m: float
    min_samples: int
    pairs: list[PairAgreement]


# --- routes -----------------------------------------------------------------------------------------
@router.get("", response_model=CalibrationSite, summary="The site's cameras, their poses and whether they can be saved")
def calibration_site(site: CurrentSiteDep, site_file: SiteFileDep, inputs: InputsDep, gateway: GatewayDep) -> CalibrationSite:
    drift = {d.camera: d for d in _drift_states(site, gateway)}
    cameras = []
    for config in site.cameras:
        camera = site.camera(config.id)
        cameras.append(CalibrationCamera(
            id=config.id,
            model=config.model,
            image_size=config.image_size,
            position=tuple(float(v) for v in camera.center),  # type: ignore[arg-type]
            tilt_deg=camera.tilt_deg,
            monitored_radius_m=config.monitored_radius_m,
            coverage_radius_m=_coverage_radius(config.monitored_radius_m, config.model, float(camera.center[2])),
            frame="live" if inputs.latest_frame(config.id, fetch=False) is not None else "rendered",
            drift=drift[config.id],
        ))
    reason = "" if site_file is not None else (
        "the gateway runs a built-in site; start it with --site pointing to a site file to save calibrations")
    return CalibrationSite(
        site=site.site,
        site_file=None if site_file is None else str(site_file),
        editable=site_file is not None,
        reason=reason,
        floor=_plan_extent(site),
        zones=[list(z.polygon) for z in site.zones],
        cameras=cameras,
    )


@router.get(
    "/cameras/{camera_id}/frame",
    summary="A JPEG still of the camera: its latest frame, or its view of the floor grid",
    response_class=Response,
    responses={200: {"content": {"image/jpeg": {}}, "description": "X-Frame-Source says live or rendered"}},
)
def camera_frame(
    camera_id: str,
    site: CurrentSiteDep,
    inputs: InputsDep,
    grid: Annotated[bool, Query(description="draw the floor grid of the current calibration over a live frame")] = False,
) -> Response:
    camera = _camera(site, camera_id)
    latest = inputs.latest_frame(camera_id)
    drawn = None
    if latest is None or grid:
        extent = floor_extent(camera, site.floor)
        drawn = _grid_image(camera, extent, tuple(tuple(map(tuple, z.polygon)) for z in site.zones))  # type: ignore[arg-type]
    if latest is None:
        assert drawn is not None
        return _jpeg(drawn, "rendered")
    image = _decoded(*latest)
    w, h = camera.image_size
    if image.shape[:2] != (h, w):  # the camera model's pixels are the ones clicked
        image = cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
    if drawn is not None:
        lines = (drawn != np.array([[BACKGROUND]], dtype=np.uint8)).any(axis=2)
        image = image.copy()
        image[lines] = drawn[lines]
    return _jpeg(image, "live")


@router.post("/cameras/{camera_id}/solve", response_model=PoseSolution, summary="The pose from image <-> floor points (nothing is saved)")
def solve(camera_id: str, request: SolveRequest, site: CurrentSiteDep) -> PoseSolution:
    camera, fit = _fit(site, camera_id, request)
    return _solution(camera_id, camera, fit, request)


@router.put(
    "/cameras/{camera_id}/extrinsics",
    response_model=SavedPose,
    summary="Solve the pose from image <-> floor points and write it into the site file",
    responses={409: {"description": "the site is not a file (a built-in site), or the file cannot be read or written"}},
)
def save_extrinsics(camera_id: str, request: SolveRequest, site: CurrentSiteDep, site_file: SiteFileDep) -> SavedPose:
    if site_file is None:
        raise HTTPException(409, "cannot save: the gateway runs a built-in site, not a site file; restart it with "
                                 "--site pointing to your site file (copy the built-in one to start)")
    camera, fit = _fit(site, camera_id, request)
    solution = _solution(camera_id, camera, fit, request)
    if not solution.accepted:
        raise HTTPException(400, f"not saved: {solution.refusal}")
    changes = {"pose": None, "extrinsics": {"rvec": [float(v) for v in fit.rvec], "tvec": [float(v) for v in fit.t]}}
    with _SAVE_LOCK:
        try:
            result = update_camera_file(site_file, camera_id, changes)
        except SiteError as exc:
            raise HTTPException(409, f"not saved: {exc}") from None
    backup = site_file.with_name(site_file.name + ".bak")
    return SavedPose(
        **solution.model_dump(),
        site_file=str(site_file),
        backup=str(backup),
        comments_kept=result.comments_kept,
        next=(f"restart the projector and tracker services so they use the new pose of {camera_id}; once people walk "
              f"through the overlaps, check the camera pairs below (or: bevflow calibrate check --site {site_file} --live 120)"),
    )


@router.get("/consistency", response_model=ConsistencyReport, summary="Do overlapping cameras put the same people in the same place?")
def consistency(
    site: CurrentSiteDep,
    inputs: InputsDep,
    gate_m: Annotated[float, Query(gt=0, le=5, description="how far apart two cameras' estimates of one person may be")] = 1.0,
    min_samples: Annotated[int, Query(ge=1, description="judge only pairs with at least this many samples")] = 20,
    tolerance_m: Annotated[float | None, Query(gt=0, description="default: the site's fusion distance")] = None,
) -> ConsistencyReport:
    index = {c: i for i, c in enumerate(site.camera_ids)}
    frames = [
        {index[c]: cylinders.with_camera(index[c]) for c, cylinders in tick.items() if c in index}
        for tick in inputs.ticks()
    ]
    cameras = [site.camera(c) for c in site.camera_ids]
    rows = check_consistency(cameras, site.camera_ids, frames, gate_m=gate_m)
    tolerance = tolerance_m if tolerance_m is not None else site.thresholds.fusion_distance_m
    pairs = [
        PairAgreement(
            camera_a=r.camera_a, camera_b=r.camera_b, samples=r.samples, median_offset_m=r.median_offset_m,
            median_offset=r.median_offset, spread_m=r.spread_m, judged=r.samples >= min_samples,
            agrees=(r.median_offset_m <= tolerance) if r.samples >= min_samples else None,
        )
        for r in rows
    ]
    return ConsistencyReport(ticks=len(frames), tolerance_m=tolerance, min_samples=min_samples, pairs=pairs)


@router.get("/drift", response_model=list[CameraDrift], summary="Per camera, whether the tracker reports that it moved")
def drift(site: CurrentSiteDep, gateway: GatewayDep) -> list[CameraDrift]:
    return _drift_states(site, gateway)


# --- helpers ----------------------------------------------------------------------------------------
def _camera(site: Site, camera_id: str) -> Camera:
    if camera_id not in site.camera_ids:
        raise HTTPException(404, f"camera_id: unknown camera {camera_id!r}; known cameras: {', '.join(site.camera_ids)}")
    return site.camera(camera_id)


def _fit(site: Site, camera_id: str, request: SolveRequest) -> tuple[Camera, PoseFit]:
    camera = _camera(site, camera_id)
    rows = [(p.name or str(k), p.pixel, p.world) for k, p in enumerate(request.points, start=1)]
    try:
        return camera, estimate_pose(camera, make_correspondences(rows, source="points"))
    except ExtrinsicsError as exc:
        raise HTTPException(400, str(exc)) from None


def _finite(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _solution(camera_id: str, camera: Camera, fit: PoseFit, request: SolveRequest) -> PoseSolution:
    points = fit.points
    # Where the solved pose puts each world point: the page draws it beside the clicked pixel.
    projected = [None if not np.isfinite(p).all() else (float(p[0]), float(p[1]))
                 for p in camera.with_pose(fit.R, fit.t).project(points.world)]
    refusal = None
    try:
        check_fit(fit, request.max_rms_px, request.max_ground_error_m)
    except ExtrinsicsError as exc:
        refusal = str(exc)
    warnings = []
    if len(points) < CHECKABLE_POINTS:
        warnings.append(f"with fewer than {CHECKABLE_POINTS} points a wrong point hardly shows in the errors; add more")
    return PoseSolution(
        camera=camera_id,
        rvec=tuple(float(v) for v in fit.rvec),  # type: ignore[arg-type]
        tvec=tuple(float(v) for v in fit.t),  # type: ignore[arg-type]
        position=tuple(float(v) for v in fit.center),  # type: ignore[arg-type]
        tilt_deg=fit.tilt_deg,
        rms_px=_finite(fit.rms_px),
        rms_ground_m=_finite(fit.rms_ground_m),
        points=[
            PointError(
                name=name,
                pixel=(float(points.pixels[k, 0]), float(points.pixels[k, 1])),
                world=(float(points.world[k, 0]), float(points.world[k, 1]), float(points.world[k, 2])),
                projected=projected[k],
                reprojection_px=_finite(fit.reprojection_px[k]),
                ground_error_m=_finite(fit.ground_error_m[k]),
            )
            for k, name in enumerate(points.names)
        ],
        accepted=refusal is None,
        refusal=refusal,
        warnings=warnings,
    )


def _drift_states(site: Site, gateway: GatewayState) -> list[CameraDrift]:
    moved = {e.camera: e for e in gateway.active_alerts() if isinstance(e, CalibrationDrift)}
    out = []
    for camera_id in site.camera_ids:
        event = moved.get(camera_id)
        if event is None:
            out.append(CameraDrift(camera=camera_id, state="ok"))
        else:
            out.append(CameraDrift(camera=camera_id, state="moved", shift_m=event.shift_m, reference_camera=event.reference_camera,
                                   since=iso_utc(event.start_ns), alert_id=event.id))
    return out


def _coverage_radius(monitored_m: float | None, model: str, height_m: float) -> float | None:
    if monitored_m is not None or model != "fisheye":
        return monitored_m
    try:
        return usable_radius(height_m)
    except PlanError:  # a height the detector is not made for
        return None


def _plan_extent(site: Site) -> tuple[float, float, float, float]:
    if site.floor is not None:
        return site.floor
    boxes = []
    for config in site.cameras:
        x, y, height = (float(v) for v in site.camera(config.id).center)
        reach = config.monitored_radius_m or 2.0 * max(height, 1.0)
        boxes.append((x - reach, y - reach, x + reach, y + reach))
    for zone in site.zones:
        xy = np.asarray(zone.polygon)
        boxes.append((*xy.min(axis=0), *xy.max(axis=0)))
    b = np.asarray(boxes, dtype=np.float64)
    return (float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 2].max()), float(b[:, 3].max()))


_GRID_CACHE: OrderedDict[tuple, np.ndarray] = OrderedDict()
_GRID_LOCK = threading.Lock()


def _grid_image(camera: Camera, extent: tuple[float, float, float, float], zones: tuple) -> np.ndarray:
    """The rendered floor grid, cached: a page asks for the same camera's still again and again."""
    key = (camera.kind, camera.K.tobytes(), camera.dist.tobytes(), camera.R.tobytes(), camera.t.tobytes(),
           camera.image_size, extent, zones)
    with _GRID_LOCK:
        cached = _GRID_CACHE.get(key)
    if cached is not None:
        return cached
    image = render_floor_grid(camera, extent, zones=zones)
    with _GRID_LOCK:
        _GRID_CACHE[key] = image
        while len(_GRID_CACHE) > 16:
            _GRID_CACHE.popitem(last=False)
    return image


def _decoded(header: FrameHeader, image: np.ndarray) -> np.ndarray:
    if header.encoding == "jpeg":
        decoded = cv2.imdecode(np.asarray(image, dtype=np.uint8), cv2.IMREAD_COLOR)
        if decoded is None:
            raise HTTPException(502, f"the latest frame of {header.camera!r} is not a readable JPEG")
        return decoded
    if header.encoding == "gray8":
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    return image


def _jpeg(image: np.ndarray, source: str) -> Response:
    ok, encoded = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return Response(encoded.tobytes(), media_type="image/jpeg", headers={"X-Frame-Source": source, "Cache-Control": "no-store"})

