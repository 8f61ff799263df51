"""Height-adaptive scaling (paper, section 3.4): resize a frame so a person at the image centre
is about 20 × 20 px, whatever the mounting height.

Derivation. For a ceiling fisheye looking straight down, a person standing at the image centre
is seen from above; the widest part is the shoulders, about ``SHOULDER_WIDTH_M`` = 0.5 m across at
height ``SHOULDER_HEIGHT_M`` = 1.4 m, so at depth D = H − 1.4 m below a camera at height H. Near
the optical axis every lens model is a pinhole of focal length f (px/rad), so the shoulders span
f · 0.5 / D px. Resizing by

    s = TARGET_PERSON_PX · D / (SHOULDER_WIDTH_M · f) = 40 · D / f

makes that 20 px. The resized focal length is f' = s · f = 40 · D px/rad, whatever the sensor:
the image circle of a 180° equidistant lens (radius f' · π/2) becomes about 126 · D px across,
e.g. 240 px at 3.3 m, 516 px at 5.5 m, 1070 px at 10 m.

People away from the centre appear smaller across (a fisheye compresses the rim) but longer
(their full height shows); the detector is trained on whole fisheye images at this scale, so it
has seen both.

>>> round(scale_factor(camera_height_m=3.3, focal_px=326.0), 4)
0.2331
>>> round(scaled_focal(3.3), 1)
76.0
"""

from __future__ import annotations

SHOULDER_WIDTH_M = 0.5
SHOULDER_HEIGHT_M = 1.4
TARGET_PERSON_PX = 20.0
TARGET_FOCAL_PER_M = TARGET_PERSON_PX / SHOULDER_WIDTH_M  # 40 px/rad per metre of depth
MIN_DEPTH_M = 0.5  # a camera lower than 1.9 m: clamp rather than divide by ~0


def scaled_focal(camera_height_m: float) -> float:
    """The focal length (px/rad) the detector's input has for a camera this high."""
    return TARGET_FOCAL_PER_M * max(camera_height_m - SHOULDER_HEIGHT_M, MIN_DEPTH_M)


def scale_factor(camera_height_m: float, focal_px: float) -> float:
    """The resize factor from a frame of focal length ``focal_px`` to the detector's input."""
    if focal_px <= 0:
        raise ValueError(f"focal length must be positive, got {focal_px}")
    return scaled_focal(camera_height_m) / focal_px
