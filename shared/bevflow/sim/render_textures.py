"""Looks for the fisheye renderer: materials, clothing, lighting and the camera's imperfections.

Everything here is domain randomisation: ``RenderStyle.sample`` draws a floor (tiles, carpet or
concrete), wall and occluder colours, a light and the sensor's faults (gain, white balance, blur,
noise, JPEG quality); ``Appearance.sample`` draws each person's clothes, skin and hair. A detector
trained on many such draws has to rely on shape (a head and shoulders seen from above, a body
stretched away from the image centre), not on one particular look, which is what lets it work on
real frames. ``Appearance.for_identities`` gives the same person the same clothes in every frame
(the live demo).

Colours are BGR floats in [0, 1], as OpenCV stores images.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import functools

import cv2
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

FLOOR_KINDS = ("tiles", "carpet", "concrete")
_NOISE_SIZE = 128  # texels of the tiling noise texture


@dataclass(frozen=True, eq=False)
class RenderStyle:
    """One look of a site and a camera. ``light_dir`` is the unit direction toward the main light
    (world, mostly up); ``ambient`` + ``diffuse`` set the contrast of the shading."""

    floor_kind: str
    floor_colors: FloatArray  # (2, 3): base and second colour (tiles alternate, grout = darker)
    tile_size_m: float
    grout_m: float  # half the width of the dark line between tiles
    noise_texture: FloatArray  # (_NOISE_SIZE, _NOISE_SIZE) in [-1, 1], tiling
    noise_scale_m: float  # metres per texel
    noise_amount: float
    wall_color: FloatArray
    pillar_color: FloatArray
    shelf_color: FloatArray
    clutter_colors: FloatArray  # (8, 3)
    light_dir: FloatArray
    ambient: float
    diffuse: float
    shadow: float  # how dark a person's floor shadow is (0: none)
    gain: FloatArray  # (3,) per-channel gain (exposure x white balance)
    gamma: float
    vignette: float
    blur_sigma_px: float
    noise_sigma: float  # sensor noise, in 8-bit units
    jpeg_quality: int  # 0: no compression
    tile_origin_m: FloatArray = field(default_factory=lambda: np.zeros(2))  # where a grout cross lies

    @classmethod
    def sample(cls, rng: np.random.Generator, shifted_tiles: float = 0.0) -> RenderStyle:
        """A random look. The tiles are laid from the world origin, right under a training render's
        camera, so two grout lines run straight through its image centre; with probability
        ``shifted_tiles`` the grid is shifted, as on a real site, where a grout line passing a
        little to the side of the camera curves past the centre. (0 draws exactly the looks it
        always did.)"""
        base = _random_color(rng, saturation=(0.0, 0.35), value=(0.35, 0.9))
        second = np.clip(base * rng.uniform(0.6, 1.3) + rng.normal(0, 0.05, 3), 0, 1)
        tilt = rng.uniform(0, 0.6)
        azimuth = rng.uniform(0, 2 * np.pi)
        light = np.array([tilt * np.cos(azimuth), tilt * np.sin(azimuth), 1.0])
        ambient = rng.uniform(0.3, 0.65)
        # Some cameras give clean frames: without these the detector learns that every frame is
        # blurred or noisy, and reads the crisp grout lines of a clean tiled floor as people.
        clean = rng.random() < 0.2
        style = cls(
            floor_kind=str(rng.choice(FLOOR_KINDS)),
            floor_colors=np.stack([base, second]),
            tile_size_m=float(rng.uniform(0.3, 1.2)),
            grout_m=float(rng.uniform(0.002, 0.02)),
            noise_texture=_tiling_noise(rng),
            noise_scale_m=float(rng.uniform(0.005, 0.05)),
            noise_amount=float(rng.uniform(0.03, 0.25)),
            wall_color=_random_color(rng, saturation=(0.0, 0.4), value=(0.5, 0.95)),
            pillar_color=_random_color(rng, saturation=(0.0, 0.3), value=(0.4, 0.95)),
            shelf_color=_random_color(rng, saturation=(0.0, 0.7), value=(0.2, 0.9)),
            clutter_colors=np.stack([_random_color(rng) for _ in range(8)]),
            light_dir=light / np.linalg.norm(light),
            ambient=float(ambient),
            diffuse=float(rng.uniform(0.5, 1.0) * (1.1 - ambient)),
            shadow=float(rng.uniform(0.0, 0.45)),
            gain=rng.uniform(0.7, 1.35) * rng.uniform(0.85, 1.15, 3),
            gamma=float(rng.uniform(0.75, 1.3)),
            vignette=float(rng.uniform(0.0, 0.5)),
            blur_sigma_px=0.0 if clean else float(rng.choice([0.0, rng.uniform(0.3, 1.3)])),
            noise_sigma=0.0 if clean else float(rng.uniform(0.0, 9.0)),
            jpeg_quality=0 if clean else int(rng.choice([0, int(rng.integers(30, 96))])),
        )
        if shifted_tiles > 0 and rng.random() < shifted_tiles:
            style = replace(style, tile_origin_m=rng.uniform(0, style.tile_size_m, 2))
        return style

    @classmethod
    def plain(cls) -> RenderStyle:
        """A fixed, clean look (grey tiles, no sensor faults): tests and the default demo."""
        rng = np.random.default_rng(0)
        return cls(
            floor_kind="tiles", floor_colors=np.array([[0.62, 0.64, 0.66], [0.55, 0.57, 0.6]]), tile_size_m=0.6, grout_m=0.008,
            noise_texture=_tiling_noise(rng), noise_scale_m=0.02, noise_amount=0.05,
            wall_color=np.array([0.8, 0.82, 0.84]), pillar_color=np.array([0.75, 0.75, 0.72]),
            shelf_color=np.array([0.35, 0.45, 0.6]), clutter_colors=np.full((8, 3), 0.5),
            light_dir=np.array([0.0, 0.0, 1.0]), ambient=0.45, diffuse=0.55, shadow=0.2,
            gain=np.ones(3), gamma=1.0, vignette=0.0, blur_sigma_px=0.0, noise_sigma=0.0, jpeg_quality=0,
        )  # fmt: skip

    def floor_albedo(self, xy: FloatArray) -> FloatArray:
        """(N, 2) floor points → (N, 3) colours."""
        noise = self.texture_at(xy / self.noise_scale_m)
        base, second = self.floor_colors
        if self.floor_kind == "tiles":
            grid = (xy - self.tile_origin_m) / self.tile_size_m
            cell = np.floor(grid).astype(np.int64)
            checker = ((cell[:, 0] + cell[:, 1]) & 1).astype(np.float64)[:, None]
            color = base * (1 - checker) + second * checker
            frac = grid - cell
            grout = (np.minimum(frac, 1 - frac).min(1) * self.tile_size_m < self.grout_m)[:, None]
            color = np.where(grout, color * 0.6, color)
        elif self.floor_kind == "carpet":
            coarse = self.texture_at(xy / (self.noise_scale_m * 20))[:, None]
            color = base * (1 + 0.25 * coarse) + (second - base) * np.clip(coarse, 0, 1)
        else:
            coarse = self.texture_at(xy / 0.6)[:, None]
            color = base * (1 + 0.15 * coarse)
        shaded: FloatArray = np.clip(color * (1 + self.noise_amount * noise[:, None]), 0, 1)
        return shaded

    def texture_at(self, uv: FloatArray) -> FloatArray:
        """Bilinear lookup of the tiling noise at texel coordinates (N, 2)."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        base = np.floor(uv)
        fx, fy = (uv - base).T
        i = base.astype(np.int64) % _NOISE_SIZE
        j = (i + 1) % _NOISE_SIZE
        t = self.noise_texture
        top = t[i[:, 1], i[:, 0]] * (1 - fx) + t[i[:, 1], j[:, 0]] * fx
        bottom = t[j[:, 1], i[:, 0]] * (1 - fx) + t[j[:, 1], j[:, 0]] * fx
        blended: FloatArray = top * (1 - fy) + bottom * fy
        return blended


@dataclass(frozen=True, eq=False)
class Appearance:
    """Per-person colours (N, 3) and clothing pattern. ``sleeves`` / ``trousers`` say whether the
    forearms and shins are covered; ``stripes`` is a stripe frequency (0: plain cloth); ``hat``
    covers the hair with the hat colour."""

    top: FloatArray
    bottom: FloatArray
    shoes: FloatArray
    skin: FloatArray
    hair: FloatArray
    sleeves: NDArray[np.bool_]
    trousers: NDArray[np.bool_]
    stripes: FloatArray
    hat: NDArray[np.bool_]

    def __len__(self) -> int:
        return len(self.top)

    @classmethod
    def sample(cls, rng: np.random.Generator, n: int) -> Appearance:
        tone = rng.uniform(0.0, 1.0, n)[:, None]
        light_skin, dark_skin = np.array([0.62, 0.72, 0.88]), np.array([0.18, 0.26, 0.38])
        skin = light_skin * (1 - tone) + dark_skin * tone
        hair_dark = rng.uniform(0.02, 0.25, n)[:, None] * np.array([0.8, 0.9, 1.0])
        blond = rng.random(n)[:, None] < 0.15
        hair = np.where(blond, np.array([0.45, 0.65, 0.8]) * rng.uniform(0.7, 1.1, (n, 1)), hair_dark)
        grey = rng.random(n)[:, None] < 0.1
        hair = np.where(grey, rng.uniform(0.5, 0.8, (n, 1)), hair)
        return cls(
            top=np.array([_random_color(rng) for _ in range(n)]).reshape(n, 3),
            bottom=np.array([_random_color(rng, saturation=(0.0, 0.6), value=(0.08, 0.7)) for _ in range(n)]).reshape(n, 3),
            shoes=rng.uniform(0.03, 0.5, (n, 1)) * np.ones(3),
            skin=skin,
            hair=np.clip(hair, 0, 1),
            sleeves=rng.random(n) < 0.6,
            trousers=rng.random(n) < 0.75,
            stripes=np.where(rng.random(n) < 0.25, rng.uniform(15, 60, n), 0.0),
            hat=rng.random(n) < 0.08,
        )

    @classmethod
    def for_identities(cls, identities: NDArray[np.int64], seed: int = 0) -> Appearance:
        """The same clothes for the same identity, whatever else is in the frame."""
        parts = [_identity_appearance(seed, int(i)) for i in np.asarray(identities).tolist()]
        if not parts:
            return cls.sample(np.random.default_rng(seed), 0)
        return cls(**{f: np.concatenate([getattr(p, f) for p in parts]) for f in cls.__dataclass_fields__})

    def part_albedo(self, person: int, part: int, local: FloatArray) -> FloatArray:
        """Colours (K, 3) of K hits on one body part; ``local`` (K, 3) is the hit on the part's unit
        sphere (axis 0 along a limb, axis 2 up for head, torso and pelvis)."""
        k = len(local)
        if part == 0:  # head: hair on top and at the back, face in front
            covered = (local[:, 2] > 0.05) | (local[:, 0] < -0.2)
            color = np.where(covered[:, None], self.top[person] if self.hat[person] else self.hair[person], self.skin[person])
        elif part == 1:
            color = np.broadcast_to(self.skin[person], (k, 3))
        elif part in (2, 4, 5):
            color = np.broadcast_to(self.top[person], (k, 3))
        elif part in (6, 7):
            color = np.broadcast_to(self.top[person] if self.sleeves[person] else self.skin[person], (k, 3))
        elif part in (3, 8, 9):
            color = np.broadcast_to(self.bottom[person], (k, 3))
        elif part in (10, 11):
            color = np.broadcast_to(self.bottom[person] if self.trousers[person] else self.skin[person], (k, 3))
        else:
            color = np.broadcast_to(self.shoes[person], (k, 3))
        freq = self.stripes[person]
        if freq > 0 and part in (2, 4, 5):
            color = color * (0.75 + 0.25 * (np.sin(freq * local[:, 2 if part == 2 else 0]) > 0))[:, None]
        return np.asarray(color, dtype=np.float64)

    def albedo_of(self, persons: NDArray[np.int64], parts: NDArray[np.int64], local: FloatArray) -> FloatArray:
        """``part_albedo`` for K hits at once: hit k on part ``parts[k]`` of person ``persons[k]``."""
        persons, parts = np.asarray(persons, dtype=np.int64), np.asarray(parts, dtype=np.int64)
        k = len(persons)
        out = np.empty((k, 3))
        head = parts == 0
        covered = (local[:, 2] > 0.05) | (local[:, 0] < -0.2)
        head_top = np.where(self.hat[persons, None], self.top[persons], self.hair[persons])
        out[head] = np.where(covered[head, None], head_top[head], self.skin[persons[head]])
        rules = (
            ((1,), self.skin, None),
            ((2, 4, 5), self.top, None),
            ((6, 7), self.top, self.sleeves),
            ((3, 8, 9), self.bottom, None),
            ((10, 11), self.bottom, self.trousers),
        )
        assigned = head.copy()
        for codes, cloth, covers in rules:
            sel = np.isin(parts, codes)
            who = persons[sel]
            out[sel] = cloth[who] if covers is None else np.where(covers[who, None], cloth[who], self.skin[who])
            assigned |= sel
        out[~assigned] = self.shoes[persons[~assigned]]
        striped = (self.stripes[persons] > 0) & np.isin(parts, (2, 4, 5))
        if striped.any():
            axis = np.where(parts[striped] == 2, 2, 0)
            phase = self.stripes[persons[striped]] * local[striped, axis]
            out[striped] *= (0.75 + 0.25 * (np.sin(phase) > 0))[:, None]
        return out


@functools.lru_cache(maxsize=4096)
def _identity_appearance(seed: int, identity: int) -> Appearance:
    # A live feed asks for the same people every frame; drawing their clothes is the slow part.
    return Appearance.sample(np.random.default_rng([seed, identity]), 1)


def finish_image(linear: FloatArray, radius_px: FloatArray, style: RenderStyle, rng: np.random.Generator) -> NDArray[np.uint8]:
    """Shaded colours (H, W, 3) in [0, 1] → an 8-bit BGR frame as a camera delivers it: exposure
    and white balance, gamma, vignetting (``radius_px`` is each pixel's distance from the principal
    point over the image circle's radius, NaN outside the lens), optical blur, sensor noise, JPEG."""
    out = _exposed(linear, radius_px, style) * np.float32(255)
    if style.blur_sigma_px > 0:
        out = np.asarray(cv2.GaussianBlur(out, (0, 0), style.blur_sigma_px), dtype=np.float32)
    if style.noise_sigma > 0:
        out += rng.normal(0, style.noise_sigma, out.shape).astype(np.float32)
    out8: NDArray[np.uint8] = np.clip(out + 0.5, 0, 255).astype(np.uint8)
    if style.jpeg_quality > 0:
        ok, buf = cv2.imencode(".jpg", out8, [cv2.IMWRITE_JPEG_QUALITY, style.jpeg_quality])
        if ok:
            out8 = np.asarray(cv2.imdecode(buf, cv2.IMREAD_COLOR), dtype=np.uint8)
    return out8


def finish_pixels(linear: FloatArray, radius_px: FloatArray, style: RenderStyle) -> NDArray[np.uint8]:
    """``finish_image`` for N separate pixels (N, 3) with their ``radius_px`` (N,), without the
    steps that need neighbours or randomness (blur, noise, JPEG): for a style that has none of
    them, it gives the same values as ``finish_image``."""
    scaled = _exposed(linear, radius_px, style) * np.float32(255) + 0.5
    exposed: NDArray[np.uint8] = np.clip(scaled, 0, 255).astype(np.uint8)
    return exposed


def _exposed(linear: FloatArray, radius_px: FloatArray, style: RenderStyle) -> NDArray[np.float32]:
    """Gain, gamma and vignetting, per pixel, in [0, 1]; black outside the lens."""
    img = np.clip(linear.astype(np.float32) * style.gain.astype(np.float32), 0, 1)
    if style.gamma != 1.0:
        img **= np.float32(style.gamma)
    if style.vignette > 0:
        rim = np.clip(np.nan_to_num(radius_px, nan=1.0), 0, 1).astype(np.float32)
        img *= (1 - np.float32(style.vignette) * rim * rim)[..., None]
    img[np.isnan(radius_px)] = 0.0
    return img


def _random_color(
    rng: np.random.Generator, saturation: tuple[float, float] = (0.0, 0.9), value: tuple[float, float] = (0.1, 0.95)
) -> FloatArray:
    hsv = np.array([[[rng.uniform(0, 180), rng.uniform(*saturation) * 255, rng.uniform(*value) * 255]]], np.float32)
    bgr: FloatArray = cv2.cvtColor(hsv.astype(np.uint8), cv2.COLOR_HSV2BGR)[0, 0].astype(np.float64) / 255.0
    return bgr


def _tiling_noise(rng: np.random.Generator) -> FloatArray:
    """Smooth value noise in [-1, 1] that tiles (blurred with wrap-around borders), two octaves."""
    fine = _wrapped_blur(rng.normal(0, 1, (_NOISE_SIZE, _NOISE_SIZE)), 1.0)
    coarse = _wrapped_blur(rng.normal(0, 1, (_NOISE_SIZE, _NOISE_SIZE)), 6.0)
    noise = fine / (fine.std() + 1e-9) + 0.7 * coarse / (coarse.std() + 1e-9)
    clipped: FloatArray = np.clip(noise / 2.5, -1, 1)
    return clipped


def _wrapped_blur(image: FloatArray, sigma: float) -> FloatArray:
    pad = int(4 * sigma) + 1
    padded = np.pad(image, pad, mode="wrap")
    return np.asarray(cv2.GaussianBlur(padded, (0, 0), sigma), dtype=np.float64)[pad:-pad, pad:-pad]
