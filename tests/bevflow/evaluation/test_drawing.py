"""Drawings of detector runs: one file per frame, never two frames in one file."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from bevflow.detections import Boxes
from bevflow.evaluation.detector import detect_turned_frames
from bevflow.evaluation.drawing import drawing_names, write_drawings


@pytest.mark.parametrize(
    ("images", "names"),
    [
        ([], []),
        (["f.png"], ["f.jpg"]),
        (["a.jpg", "b.png"], ["a.jpg", "b.jpg"]),
        (["a.jpg", "a.png"], ["a.jpg.jpg", "a.png.jpg"]),  # one stem: each keeps its suffix
        (["cam1/0001.jpg", "cam2/0001.jpg"], ["cam1/0001.jpg", "cam2/0001.jpg"]),  # one name, two folders
        (["day/cam1/0001.png", "day/cam1/0002.png"], ["0001.jpg", "0002.jpg"]),  # below the common folder
        (["x/a.jpg", "x/a.jpeg", "y/a.jpg"], ["x/a.jpg.jpg", "x/a.jpeg.jpg", "y/a.jpg"]),
    ],
)
def test_each_image_gets_a_drawing_of_its_own(tmp_path: Path, images: list[str], names: list[str]) -> None:
    assert drawing_names([tmp_path / "frames" / i for i in images]) == [Path(n) for n in names]


def test_a_linked_frame_is_drawn_under_the_links_name(tmp_path: Path) -> None:
    for camera in ("x", "y"):
        (tmp_path / "data" / camera).mkdir(parents=True)
        (tmp_path / "data" / camera / "0001.jpg").write_bytes(b"")
    (tmp_path / "frames").mkdir()
    (tmp_path / "frames" / "a.jpg").symlink_to(tmp_path / "data" / "x" / "0001.jpg")
    (tmp_path / "frames" / "b.jpg").symlink_to(tmp_path / "data" / "y" / "0001.jpg")
    assert drawing_names([tmp_path / "frames" / "a.jpg", tmp_path / "frames" / "b.jpg"]) == [Path("a.jpg"), Path("b.jpg")]


def test_frames_of_one_stem_are_drawn_apart(tmp_path: Path) -> None:
    frames = tmp_path / "frames"
    frames.mkdir()
    for name, grey in (("a.jpg", 40), ("a.png", 200)):
        cv2.imwrite(str(frames / name), np.full((64, 64, 3), grey, np.uint8))

    class Nobody:
        def detect(self, image, camera_height_m, focal_px):  # noqa: ANN001, ANN201
            return Boxes.empty()

    [(results, _)] = detect_turned_frames(Nobody(), None, [0.0], frames, log=lambda m: None)
    written = write_drawings(results, tmp_path / "drawn", 0.5)
    assert sorted(p.name for p in (tmp_path / "drawn").iterdir()) == ["a.jpg.jpg", "a.png.jpg"]
    greys = {p.name: int(np.median(cv2.imread(str(p)))) for p in written}
    assert greys["a.jpg.jpg"] == pytest.approx(40, abs=3) and greys["a.png.jpg"] == pytest.approx(200, abs=3)
