from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from bevflow.camera import PinholeCamera
from bevflow.datasets.wildtrack import (
    ANNOTATED_AREA,
    WildtrackError,
    load_wildtrack,
    position_to_xy,
)

REAL_ROOT = Path("/work/shared/data/wildtrack")

# Two side-view cameras (metres) looking at a patch of the grid from two sides.
FAKE_CAMERAS = {
    "CVLab1": ((3.0, -12.0, 2.5), (3.0, 0.0, 0.0)),
    "CVLab2": ((-7.0, 1.0, 2.8), (3.0, 1.0, 0.0)),
}
K = np.array([[1500.0, 0.0, 960.0], [0.0, 1500.0, 540.0], [0.0, 0.0, 1.0]])
PERSON_HEIGHT, PERSON_RADIUS = 1.75, 0.25
# frame -> [(personID, positionID)]; written out of order to check sorting
FAKE_FRAMES = {
    10: [(7, 160 + 480 * 340), (8, 240 + 480 * 400), (9, 200 + 480 * 300)],
    0: [(7, 160 + 480 * 320), (8, 240 + 480 * 420), (9, 200 + 480 * 280)],
    5: [(7, 160 + 480 * 330), (8, 240 + 480 * 410), (9, 200 + 480 * 290)],
}
HIDDEN = (9, 1)  # person 9 is not seen by the second camera


def look_at(position: tuple[float, float, float], target: tuple[float, float, float]) -> PinholeCamera:
    c, t = np.asarray(position), np.asarray(target)
    z = (t - c) / np.linalg.norm(t - c)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return PinholeCamera(K=K, dist=np.zeros(5), R=R, t=-R @ c, image_size=(1920, 1080))


def fake_cameras() -> list[PinholeCamera]:
    return [look_at(p, t) for p, t in FAKE_CAMERAS.values()]


def person_box(camera: PinholeCamera, xy: np.ndarray) -> list[int]:
    """Bounding rectangle of an upright cylinder at ``xy``, rounded to whole pixels as annotated."""
    a = np.linspace(0, 2 * math.pi, 24, endpoint=False)
    ring = np.stack([xy[0] + PERSON_RADIUS * np.cos(a), xy[1] + PERSON_RADIUS * np.sin(a)], 1)
    pts = np.concatenate([np.c_[ring, np.zeros(24)], np.c_[ring, np.full(24, PERSON_HEIGHT)]])
    uv = camera.project(pts)
    x0, y0 = np.floor(uv.min(0)).astype(int)
    x1, y1 = np.ceil(uv.max(0)).astype(int)
    return [int(x0), int(y0), int(x1), int(y1)]


def write_fake_wildtrack(root: Path) -> Path:
    """A tiny WILDTRACK folder: 2 calibrated cameras (tvec in cm, as the dataset has them),
    3 annotation files with 7 views each (views 2..6 invisible) and boxes that are true projections."""
    cameras = fake_cameras()
    for sub in ("extrinsic", "intrinsic_zero"):
        (root / "calibrations" / sub).mkdir(parents=True, exist_ok=True)
    for name, cam in zip(FAKE_CAMERAS, cameras, strict=True):
        rvec = " ".join(repr(float(v)) for v in cv2.Rodrigues(cam.R)[0].ravel())
        tvec = " ".join(repr(float(v)) for v in cam.t * 100.0)
        (root / "calibrations" / "extrinsic" / f"extr_{name}.xml").write_text(
            f'<?xml version="1.0"?>\n<opencv_storage>\n  <rvec>\n    {rvec}\n   </rvec> \n  <tvec>\n    {tvec}\n  </tvec>\n</opencv_storage>\n'
        )
        k = " ".join(repr(float(v)) for v in K.ravel())
        (root / "calibrations" / "intrinsic_zero" / f"intr_{name}.xml").write_text(
            '<?xml version="1.0"?>\n<opencv_storage>\n<camera_matrix type_id="opencv-matrix">\n  <rows>3</rows>\n'
            f"  <cols>3</cols>\n  <dt>d</dt>\n  <data>{k}</data></camera_matrix>\n"
            '<distortion_coefficients type_id="opencv-matrix">\n  <rows>5</rows>\n  <cols>1</cols>\n  <dt>d</dt>\n'
            "  <data>\n    0 0 \n    0 0\n    0</data></distortion_coefficients>\n</opencv_storage>\n"
        )
    (root / "annotations_positions").mkdir(parents=True, exist_ok=True)
    for frame, people in FAKE_FRAMES.items():
        records = []
        for pid, pos in people:
            xy = position_to_xy([pos])[0]
            views = []
            for v in range(7):
                box = person_box(cameras[v], xy) if v < 2 and (pid, v) != HIDDEN else [-1, -1, -1, -1]
                views.append(dict(zip(("xmin", "ymin", "xmax", "ymax"), box, strict=True), viewNum=v))
            records.append({"personID": pid, "positionID": pos, "views": views})
        (root / "annotations_positions" / f"{frame:08d}.json").write_text(json.dumps(records))
    return root


@pytest.fixture
def fake_root(tmp_path: Path) -> Path:
    return write_fake_wildtrack(tmp_path / "wildtrack")


@pytest.mark.parametrize(
    ("position_id", "expected_xy"),
    [
        (0, (-3.0, -9.0)),
        (479, (-3.0 + 0.025 * 479, -9.0)),
        (480, (-3.0, -8.975)),
        (160 + 480 * 360, (1.0, 0.0)),
        (480 * 1440 - 1, (8.975, 26.975)),
    ],
)
def test_position_ids_map_to_metres_x_first(position_id: int, expected_xy: tuple[float, float]) -> None:
    np.testing.assert_allclose(position_to_xy([position_id])[0], expected_xy, atol=1e-9)


def test_loads_cameras_in_view_order_with_translation_in_metres(fake_root: Path) -> None:
    ds = load_wildtrack(fake_root)
    assert ds.camera_ids == ("CVLab1", "CVLab2")
    assert ds.view_numbers == (0, 1)
    for cam, (position, _) in zip(ds.cameras, FAKE_CAMERAS.values(), strict=True):
        np.testing.assert_allclose(cam.center, position, atol=1e-6)  # written in cm, read in m
        np.testing.assert_allclose(cam.K, K)
        assert cam.image_size == (1920, 1080)
        assert not cam.dist.any()


def test_frames_sorted_with_ids_feet_and_boxes(fake_root: Path) -> None:
    ds = load_wildtrack(fake_root)
    assert [f.frame for f in ds.frames] == [0, 5, 10]
    first = ds.frames[0]
    assert first.person_ids.tolist() == [7, 8, 9]
    np.testing.assert_allclose(first.feet_xy, [[1.0, -1.0], [3.0, 1.5], [2.0, -2.0]], atol=1e-9)
    assert first.views[0].person_ids.tolist() == [7, 8, 9]
    assert first.views[1].person_ids.tolist() == [7, 8]  # person 9 is invisible (-1) there
    cam = fake_cameras()[1]
    expected = person_box(cam, first.feet_xy[1])
    np.testing.assert_array_equal(first.views[1].boxes.xyxy[1], expected)
    assert len(first.views) == 2  # views 2..6 have no camera and no visible box


def test_ground_truth_feet_project_onto_box_bottoms(fake_root: Path) -> None:
    ds = load_wildtrack(fake_root)
    for frame in ds.frames:
        for cam, view in zip(ds.cameras, frame.views, strict=True):
            rows = [frame.person_ids.tolist().index(p) for p in view.person_ids]
            uv = cam.project(np.c_[frame.feet_xy[rows], np.zeros(len(rows))])
            b = view.boxes
            # perspective skews the box around the feet, but only by a fraction of its size
            assert np.all(np.abs(uv[:, 0] - b.center[:, 0]) < 0.25 * b.width)
            assert np.all((uv[:, 1] <= b.xyxy[:, 3] + 1) & (uv[:, 1] > b.xyxy[:, 3] - 0.1 * b.height))


def test_box_cut_by_image_border_is_kept(fake_root: Path) -> None:
    path = fake_root / "annotations_positions" / "00000005.json"
    records = json.loads(path.read_text())
    records[0]["views"][0].update(xmin=-1, ymin=200, xmax=60, ymax=500)
    path.write_text(json.dumps(records))
    frame = load_wildtrack(fake_root).frames[1]
    np.testing.assert_array_equal(frame.views[0].boxes.xyxy[0], [-1, 200, 60, 500])


@pytest.mark.parametrize(
    ("xy", "inside"),
    [((-3.0, -9.0), True), ((8.975, 26.975), True), ((9.1, 0.0), False), ((0.0, -9.2), False), ((np.nan, 0.0), False)],
)
def test_annotated_area_is_the_grid_extent(xy: tuple[float, float], inside: bool) -> None:
    assert ANNOTATED_AREA.contains(np.array([xy])).tolist() == [inside]


def _break(root: Path, what: str) -> Path:
    """Damage the fake dataset one way; return the path the error must name."""
    ann = root / "annotations_positions"
    extr = root / "calibrations" / "extrinsic"
    first = ann / "00000000.json"
    if what == "missing root":
        return root / "nope"
    if what == "no annotations folder":
        for p in ann.iterdir():
            p.unlink()
        ann.rmdir()
        return ann
    if what == "no annotation files":
        for p in ann.iterdir():
            p.unlink()
        return ann
    if what == "no cameras":
        for p in extr.iterdir():
            p.unlink()
        return extr
    if what == "missing intrinsics":
        (root / "calibrations" / "intrinsic_zero" / "intr_CVLab2.xml").unlink()
        return root / "calibrations" / "intrinsic_zero" / "intr_CVLab2.xml"
    if what == "bad xml":
        (extr / "extr_CVLab1.xml").write_text("<opencv_storage><rvec>1 2 3</rvec>")
        return extr / "extr_CVLab1.xml"
    if what == "short tvec":
        (extr / "extr_CVLab1.xml").write_text("<opencv_storage><rvec>1 2 3</rvec><tvec>1 2</tvec></opencv_storage>")
        return extr / "extr_CVLab1.xml"
    records = json.loads(first.read_text())
    if what == "bad json":
        first.write_text("[{")
    elif what == "missing key":
        del records[1]["positionID"]
        first.write_text(json.dumps(records))
    elif what == "position off the grid":
        records[0]["positionID"] = 480 * 1440
        first.write_text(json.dumps(records))
    elif what == "box in uncalibrated view":
        records[0]["views"][4].update(xmin=10, ymin=10, xmax=50, ymax=120)
        first.write_text(json.dumps(records))
    return first


@pytest.mark.parametrize(
    "what",
    [
        "missing root",
        "no annotations folder",
        "no annotation files",
        "no cameras",
        "missing intrinsics",
        "bad xml",
        "short tvec",
        "bad json",
        "missing key",
        "position off the grid",
        "box in uncalibrated view",
    ],
)
def test_unreadable_dataset_gives_one_error_naming_the_path(fake_root: Path, what: str) -> None:
    bad_path = _break(fake_root, what)
    root = bad_path if what == "missing root" else fake_root
    with pytest.raises(WildtrackError, match=str(bad_path).replace("\\", "\\\\")) as err:
        load_wildtrack(root)
    assert isinstance(err.value, ValueError)
    assert "\n" not in str(err.value)


@pytest.mark.skipif(not REAL_ROOT.is_dir(), reason="the WILDTRACK dataset is not on this machine")
def test_real_wildtrack_feet_project_near_box_bottoms() -> None:
    ds = load_wildtrack(REAL_ROOT)
    assert ds.camera_ids == ("CVLab1", "CVLab2", "CVLab3", "CVLab4", "IDIAP1", "IDIAP2", "IDIAP3")
    assert all(ANNOTATED_AREA.contains(f.feet_xy).all() for f in ds.frames)
    for i, cam in enumerate(ds.cameras):
        errors = []
        for frame in ds.frames[::4]:
            view = frame.views[i]
            rows = [frame.person_ids.tolist().index(p) for p in view.person_ids]
            uv = cam.project(np.c_[frame.feet_xy[rows], np.zeros(len(rows))])
            bottom = np.c_[view.boxes.center[:, 0], view.boxes.xyxy[:, 3]]
            errors.extend(np.linalg.norm(uv - bottom, axis=1))
        # measured medians are 3-16 px; a wrong unit or camera order gives hundreds of pixels
        assert np.median(errors) < 25.0, (ds.camera_ids[i], np.median(errors))


def test_frames_carry_their_capture_clock(fake_root: Path) -> None:
    ds = load_wildtrack(fake_root)
    # annotated frame numbers 0, 5, 10 are 0.5 s apart
    assert [f.frame * ds.seconds_per_frame_number for f in ds.frames] == pytest.approx([0.0, 0.5, 1.0])
