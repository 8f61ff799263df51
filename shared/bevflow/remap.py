"""Precomputed remap tables: rectified views and a bird's-eye mosaic, each one ``cv2.remap``.

The paper's tip (section 3.3): work out once where every output pixel reads from, so that at run
time a rectified view of one camera, or a bird's-eye view (BEV) of the whole floor from several
cameras, costs a single table lookup per output pixel.

- ``rectify_maps(camera, out_size, fov_deg)``: a virtual pinhole camera at the same place as
  ``camera`` looking straight down; straight floor lines stay straight and the floor has one
  scale.
- ``BevMosaic.build(cameras, extent, metres_per_pixel)``: every floor pixel reads from the camera
  whose nadir is nearest to it in ground distance, among those whose image holds it. The frames
  are stacked side by side into one "atlas" image, so ``render(frames)`` is one copy per frame and
  one ``cv2.remap``.

>>> from bevflow.camera import FisheyeCamera
>>> cam = FisheyeCamera.looking_down((2.0, 1.5, 3.0), (256, 256), fov_deg=180.0)
>>> mosaic = BevMosaic.build([cam], extent=(0.0, 0.0, 4.0, 3.0), metres_per_pixel=0.05)
>>> mosaic.render([np.full((256, 256), 9, np.uint8)]).shape
(60, 80)
>>> mosaic.world_to_bev_pixels(np.array([[2.0, 1.5]])).tolist()
[[39.5, 29.5]]
>>> int(mosaic.camera_index[30, 40])
0
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from numpy.typing import NDArray

from bevflow.camera import Camera, PinholeCamera, rotation_from_ypr

if TYPE_CHECKING:
    from bevflow.site import Site

Map = NDArray[np.float32]

#: cv2.remap refuses source and output images with a side of SHRT_MAX (32767) pixels or more.
ATLAS_MAX_SIDE = 32766
#: Table value for output pixels that read from nowhere: far enough outside any image that every
#: interpolation kernel (Lanczos reaches 4 px) sees only the border value.
OUTSIDE = -16.0


# --- one camera -----------------------------------------------------------------------------------
def view_maps(source: Camera, target: Camera) -> tuple[Map, Map]:
    """Tables for ``cv2.remap(source_frame, map_x, map_y, ...)`` that produce ``target``'s image.

    Only rays are matched, so this is exact when both cameras share their optical centre (a
    virtual camera placed at the real one, as ``rectify_maps`` does)."""
    w, h = target.image_size
    uv = _pixel_centres(w, h)
    in_source = target.world_rays(uv) @ source.R.T
    return _as_maps(source.project_directions(in_source), source.image_size, (h, w))


def downward_view(
    camera: Camera, out_size: tuple[int, int], fov_deg: float = 90.0, yaw_deg: float | None = None
) -> PinholeCamera:
    """A distortion-free pinhole camera at ``camera``'s centre, looking straight down.

    ``fov_deg`` spans the output's width. ``yaw_deg`` turns it about the vertical; by default it
    follows ``camera``'s image x axis, so the rectified view keeps the frame's orientation."""
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"a pinhole view needs 0 < fov_deg < 180, got {fov_deg}")
    w, h = out_size
    f = (w / 2.0) / math.tan(math.radians(fov_deg) / 2.0)
    K = np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    if yaw_deg is None:
        x_axis = camera.R[0]  # the camera's image x axis as a world direction
        yaw_deg = math.degrees(math.atan2(x_axis[1], x_axis[0])) if np.hypot(x_axis[0], x_axis[1]) > 1e-9 else 0.0
    R = rotation_from_ypr(yaw_deg, 0.0, 0.0)
    return PinholeCamera(K=K, dist=np.zeros(0), R=R, t=-R @ camera.center, image_size=(w, h))


def rectify_maps(
    camera: Camera, out_size: tuple[int, int], fov_deg: float = 90.0, yaw_deg: float | None = None
) -> tuple[Map, Map]:
    """Tables that turn ``camera``'s frames into a straight-down pinhole view (``downward_view``).

    >>> from bevflow.camera import FisheyeCamera
    >>> cam = FisheyeCamera.looking_down((0.0, 0.0, 3.0), (512, 512), fov_deg=185.0)
    >>> map_x, map_y = rectify_maps(cam, (320, 240), fov_deg=120.0)
    >>> map_x.shape, map_x.dtype.name
    ((240, 320), 'float32')
    """
    return view_maps(camera, downward_view(camera, out_size, fov_deg, yaw_deg))


# --- the floor raster -----------------------------------------------------------------------------
@dataclass(frozen=True)
class BevGrid:
    """A raster over the floor, drawn as seen from above: column u grows with X, row v grows with
    −Y (so X points right and Y up), and pixel (u, v) is centred at integer coordinates, covering
    [xmin, xmin + w·m] × [ymax − h·m, ymax]."""

    extent: tuple[float, float, float, float]
    metres_per_pixel: float

    def __post_init__(self) -> None:
        xmin, ymin, xmax, ymax = (float(v) for v in self.extent)
        m = float(self.metres_per_pixel)
        if not (math.isfinite(m) and m > 0):
            raise ValueError(f"metres_per_pixel must be positive, got {self.metres_per_pixel}")
        if not (xmax > xmin and ymax > ymin):
            raise ValueError(
                f"extent must be (xmin, ymin, xmax, ymax) with xmax > xmin and ymax > ymin, got {self.extent}"
            )
        object.__setattr__(self, "extent", (xmin, ymin, xmax, ymax))
        object.__setattr__(self, "metres_per_pixel", m)
        w, h = self.size
        if max(w, h) > ATLAS_MAX_SIDE:
            raise ValueError(
                f"a {w}×{h} px bird's-eye view is too large for cv2.remap "
                f"(at most {ATLAS_MAX_SIDE} px a side); use more metres_per_pixel"
            )

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        xmin, ymin, xmax, ymax = self.extent
        m = self.metres_per_pixel
        return max(1, math.ceil((xmax - xmin) / m - 1e-9)), max(1, math.ceil((ymax - ymin) / m - 1e-9))

    def world_to_pixels(self, xy: NDArray[np.float64]) -> NDArray[np.float64]:
        """Floor points (N, 2+) in metres to BEV pixels (N, 2); Z, if given, is ignored."""
        p = np.asarray(xy, dtype=np.float64)
        p = p.reshape(-1, p.shape[-1])
        xmin, _, _, ymax = self.extent
        m = self.metres_per_pixel
        return np.stack([(p[:, 0] - xmin) / m - 0.5, (ymax - p[:, 1]) / m - 0.5], axis=1)

    def pixels_to_world(self, uv: NDArray[np.float64], z: float = 0.0) -> NDArray[np.float64]:
        """BEV pixels (N, 2) to world points (N, 3) on the plane Z = z."""
        p = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        xmin, _, _, ymax = self.extent
        m = self.metres_per_pixel
        return np.stack([xmin + (p[:, 0] + 0.5) * m, ymax - (p[:, 1] + 0.5) * m, np.full(len(p), float(z))], axis=1)


# --- several cameras ----------------------------------------------------------------------------
def atlas_layout(
    image_sizes: Sequence[tuple[int, int]], max_side: int = ATLAS_MAX_SIDE
) -> tuple[NDArray[np.int64], tuple[int, int]]:
    """Where each frame goes in the atlas: side by side, starting a new row only when the next
    frame would make the atlas wider than ``max_side`` (cv2.remap's limit).

    Returns the top-left (x, y) of each frame (K, 2) and the atlas (width, height)."""
    offsets = np.zeros((len(image_sizes), 2), dtype=np.int64)
    x = y = row_height = width = 0
    for k, (w, h) in enumerate(image_sizes):
        if w > max_side or h > max_side:
            raise ValueError(
                f"camera {k}: a {w}×{h} px image is too large for cv2.remap (at most {max_side} px a side)"
            )
        if x > 0 and x + w > max_side:
            x, y, row_height = 0, y + row_height, 0
        offsets[k] = (x, y)
        x += w
        row_height = max(row_height, h)
        width = max(width, x)
    height = y + row_height
    if height > max_side:
        raise ValueError(
            f"{len(image_sizes)} cameras do not fit one remap atlas ({height} px tall, at most {max_side}); "
            "build one mosaic per region"
        )
    return offsets, (width, height)


@dataclass(frozen=True, eq=False)
class BevMosaic:
    """A bird's-eye view of the floor stitched from several cameras with one ``cv2.remap``.

    ``camera_index`` (h, w) says which camera each BEV pixel reads from (−1: none sees it), which
    doubles as a coverage map. ``map_x``, ``map_y`` index the atlas of all frames laid out by
    ``offsets``; use ``build`` or ``from_site`` rather than the constructor."""

    grid: BevGrid
    image_sizes: tuple[tuple[int, int], ...]
    offsets: NDArray[np.int64]
    atlas_size: tuple[int, int]
    map_x: Map
    map_y: Map
    camera_index: NDArray[np.int16]

    @classmethod
    def build(
        cls,
        cameras: Sequence[Camera],
        extent: tuple[float, float, float, float],
        metres_per_pixel: float,
        z: float = 0.0,
        max_distance_m: float | Sequence[float | None] | None = None,
        margin_px: float = 0.0,
        max_atlas_side: int = ATLAS_MAX_SIDE,
    ) -> BevMosaic:
        """Choose, for every BEV pixel on the plane Z = ``z``, the camera nearest in ground distance
        whose image holds the point at least ``margin_px`` inside its edges and, if
        ``max_distance_m`` is given (one value, or one per camera; None for no limit), within that
        ground distance of the camera. Vectorised over pixels; one pass per camera."""
        if not cameras:
            raise ValueError("a mosaic needs at least one camera")
        limits = _per_camera(max_distance_m, len(cameras))
        grid = BevGrid(extent, metres_per_pixel)
        w, h = grid.size
        uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        floor = grid.pixels_to_world(np.stack([uu.ravel(), vv.ravel()], axis=1), z)

        best = np.full(len(floor), np.inf)
        index = np.full(len(floor), -1, dtype=np.int16)
        source = np.full((len(floor), 2), OUTSIDE)
        offsets, atlas_size = atlas_layout([c.image_size for c in cameras], max_atlas_side)
        for k, cam in enumerate(cameras):
            uv = cam.project(floor)
            ground = np.hypot(floor[:, 0] - cam.center[0], floor[:, 1] - cam.center[1])
            better = cam.in_image(uv, margin=-margin_px) & (ground < best) & (ground <= limits[k])
            best[better] = ground[better]
            index[better] = k
            source[better] = uv[better] + offsets[k]
        return cls(
            grid=grid,
            image_sizes=tuple(c.image_size for c in cameras),
            offsets=offsets,
            atlas_size=atlas_size,
            map_x=source[:, 0].astype(np.float32).reshape(h, w),
            map_y=source[:, 1].astype(np.float32).reshape(h, w),
            camera_index=index.reshape(h, w),
        )

    @classmethod
    def from_site(
        cls,
        site: Site,
        metres_per_pixel: float,
        z: float = 0.0,
        extent: tuple[float, float, float, float] | None = None,
    ) -> BevMosaic:
        """A mosaic of every camera of a site over its ``floor`` extent (or ``extent``), each camera
        limited to its ``monitored_radius_m``."""
        extent = extent or site.floor
        if extent is None:
            raise ValueError(f"site {site.site!r} has no 'floor' extent; pass extent=(xmin, ymin, xmax, ymax)")
        cameras = list(site.built_cameras.values())
        return cls.build(
            cameras, extent, metres_per_pixel, z, max_distance_m=[c.monitored_radius_m for c in site.cameras]
        )

    # --- coordinates ------------------------------------------------------------------------------
    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the rendered view in pixels."""
        return self.grid.size

    def world_to_bev_pixels(self, xy: NDArray[np.float64]) -> NDArray[np.float64]:
        """Floor points (N, 2+) in metres to pixels (N, 2) of the rendered view."""
        return self.grid.world_to_pixels(xy)

    def bev_pixels_to_world(self, uv: NDArray[np.float64], z: float = 0.0) -> NDArray[np.float64]:
        """Pixels (N, 2) of the rendered view to world points (N, 3) at height ``z``."""
        return self.grid.pixels_to_world(uv, z)

    # --- rendering --------------------------------------------------------------------------------
    @cached_property
    def fixed_point_maps(self) -> tuple[NDArray[np.int16], NDArray[np.uint16]]:
        """The same tables in OpenCV's fixed-point form (1/32 px), which remaps faster."""
        xy, fraction = cv2.convertMaps(self.map_x, self.map_y, cv2.CV_16SC2)
        return np.asarray(xy, dtype=np.int16), np.asarray(fraction, dtype=np.uint16)

    def atlas(self, frames: Sequence[NDArray[Any]]) -> NDArray[Any]:
        """The frames, one per camera in build order, copied into one image at ``offsets``."""
        if len(frames) != len(self.image_sizes):
            raise ValueError(f"expected {len(self.image_sizes)} frames, one per camera, got {len(frames)}")
        first = np.asarray(frames[0])
        w, h = self.atlas_size
        # Only padding (frames of unequal size) needs clearing; the tables never read elsewhere.
        padded = sum(fw * fh for fw, fh in self.image_sizes) < w * h
        atlas = (np.zeros if padded else np.empty)((h, w, *first.shape[2:]), dtype=first.dtype)
        for k, (frame, (fw, fh), (x, y)) in enumerate(zip(frames, self.image_sizes, self.offsets, strict=True)):
            expected = (fh, fw, *first.shape[2:])
            if frame.shape != expected or frame.dtype != first.dtype:
                got = f"{_shape(frame.shape)} {frame.dtype}"
                raise ValueError(f"frame {k}: expected {_shape(expected)} {first.dtype}, got {got}")
            atlas[y : y + fh, x : x + fw] = frame
        return atlas

    def render(
        self,
        frames: Sequence[NDArray[Any]],
        border_value: float = 0.0,
        interpolation: int = cv2.INTER_LINEAR,
        fixed_point: bool = True,
    ) -> NDArray[Any]:
        """The bird's-eye view (h, w[, c]) of one frame per camera (in build order, same dtype and
        channels). Pixels no camera sees get ``border_value``. ``fixed_point`` uses the faster
        1/32-px tables; pass False for the exact float ones."""
        map1, map2 = self.fixed_point_maps if fixed_point else (self.map_x, self.map_y)
        # A bare number would fill only the first channel: OpenCV reads it as Scalar(v, 0, 0, 0).
        border = (float(border_value),) * 4
        view: NDArray[Any] = cv2.remap(
            self.atlas(frames), map1, map2, interpolation, borderMode=cv2.BORDER_CONSTANT, borderValue=border
        )
        return view


# --- helpers --------------------------------------------------------------------------------------
def _pixel_centres(w: int, h: int) -> NDArray[np.float64]:
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    return np.stack([uu.ravel(), vv.ravel()], axis=1)


def _as_maps(source_uv: NDArray[np.float64], source_size: tuple[int, int], out_hw: tuple[int, int]) -> tuple[Map, Map]:
    """Source pixels (N, 2) to float32 tables of shape ``out_hw``; unseen and far-off pixels point
    to ``OUTSIDE`` (a margin of one pixel keeps the anti-aliased border of the frame)."""
    w, h = source_size
    uv = np.asarray(source_uv, dtype=np.float64)
    near = np.isfinite(uv).all(axis=1) & (uv[:, 0] >= -1) & (uv[:, 0] <= w) & (uv[:, 1] >= -1) & (uv[:, 1] <= h)
    uv = np.where(near[:, None], uv, OUTSIDE)
    return uv[:, 0].astype(np.float32).reshape(out_hw), uv[:, 1].astype(np.float32).reshape(out_hw)


def _shape(shape: tuple[int, ...]) -> str:
    return "×".join(map(str, shape))


def _per_camera(value: float | Sequence[float | None] | None, n: int) -> NDArray[np.float64]:
    if value is None or isinstance(value, (int, float, np.number)):
        values: list[float | None] = [None if value is None else float(value)] * n
    else:
        values = list(value)
        if len(values) != n:
            raise ValueError(f"max_distance_m has {len(values)} values for {n} cameras")
    return np.array([np.inf if v is None else float(v) for v in values])
