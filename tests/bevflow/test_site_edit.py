"""Editing one camera of a site file keeps every other byte: comments, layout, other cameras."""

from __future__ import annotations

import difflib
import doctest
import json
from pathlib import Path

import pytest
import yaml

import bevflow.site_edit
from bevflow.site import BUILTIN_SITES, SiteError, load_site, parse_site
from bevflow.site_edit import _flow, _yaml_float, update_camera_file, update_camera_text

EXAMPLE = (BUILTIN_SITES / "example-hall.yaml").read_text()

BLOCK_STYLE = """\
site: block   # every value written out in blocks
cameras:
  - id: one
    image_size:
      - 1280
      - 1280
    intrinsics:
      fx: 400.0   # from the datasheet
      fy: 400.0
      cx: 640.0
      cy: 640.0
    distortion:
    - 0.0
    - 0.0
    - 0.0
    - 0.0
    pose:
      # measured with a laser
      position: [1.0, 2.0, 3.3]
      yaw_deg: 10.0
    monitored_radius_m: 3.5  # paper's value
  - {id: two, image_size: [640, 480], intrinsics: {fx: 300.0, fy: 300.0, cx: 320.0, cy: 240.0}, pose: {position: [5.0, 2.0, 3.3]}}
zones: []
"""

NEW_LENS = {"intrinsics": {"fx": 634.25, "fy": 633.75, "cx": 1021.5, "cy": 1026.0}, "distortion": [-0.0125, 1e-05, -2.5e-06, 0.0]}
NEW_POSE = {"pose": None, "extrinsics": {"rvec": [3.1, 0.01, -0.02], "tvec": [-7.4, 5.1, 5.5]}}


def changed_lines(before: str, after: str) -> list[str]:
    return [line for line in difflib.ndiff(before.splitlines(), after.splitlines()) if line[:1] in "+-"]


def camera(text: str, camera_id: str) -> dict:
    return next(c for c in yaml.safe_load(text)["cameras"] if c["id"] == camera_id)


@pytest.mark.parametrize(
    ("changes", "expected_diff"),
    [
        (
            NEW_LENS,
            [
                "-     intrinsics: {fx: 634.3, fy: 634.3, cx: 1023.5, cy: 1023.5}",
                "-     distortion: [-0.012, 0.0031, -0.0009, 0.0001]   # k1, k2, k3, k4 (exactly 4 for fisheye)",
                "+     intrinsics: {fx: 634.25, fy: 633.75, cx: 1021.5, cy: 1026.0}",
                "+     distortion: [-0.0125, 1.0e-05, -2.5e-06, 0.0]   # k1, k2, k3, k4 (exactly 4 for fisheye)",
            ],
        ),
        (
            NEW_POSE,
            [
                "-     pose:",
                "-       position: [7.5, 5.0, 5.5]             # x, y, height of the lens above the floor",
                "-       yaw_deg: 0.0",
                "-       pitch_deg: 0.0",
                "-       roll_deg: 0.0",
                "+     extrinsics: {rvec: [3.1, 0.01, -0.02], tvec: [-7.4, 5.1, 5.5]}",
            ],
        ),
        ({"monitored_radius_m": None}, ["-     monitored_radius_m: 9.5"]),
    ],
    ids=["lens", "pose-to-extrinsics", "remove-key"],
)
def test_example_hall_changes_only_the_changed_lines(changes: dict, expected_diff: list[str]) -> None:
    result = update_camera_text(EXAMPLE, "hall-sw", changes)
    assert result.comments_kept
    assert sorted(changed_lines(EXAMPLE, result.text)) == sorted(expected_diff)
    parse_site(result.text)  # still a valid site


def test_every_field_of_a_block_style_file_can_change() -> None:
    changes = {**NEW_LENS, **NEW_POSE, "image_size": [2048, 2048], "source": "rtsp://cam/1: main", "detector": "high"}
    result = update_camera_text(BLOCK_STYLE, "one", changes)
    assert result.comments_kept
    one = camera(result.text, "one")
    assert one["intrinsics"] == NEW_LENS["intrinsics"] and one["distortion"] == NEW_LENS["distortion"]
    assert one["image_size"] == [2048, 2048] and "pose" not in one and one["extrinsics"] == NEW_POSE["extrinsics"]
    assert one["source"] == "rtsp://cam/1: main" and one["detector"] == "high"
    text = result.text
    for kept in ("# every value written out in blocks", "monitored_radius_m: 3.5  # paper's value", "  - {id: two, image_size: [640, 480]"):
        assert kept in text
    assert "# from the datasheet" not in text  # it was inside the replaced intrinsics block
    assert text.index("extrinsics:") < text.index("monitored_radius_m")  # where pose was
    assert text.index("source:") > text.index("monitored_radius_m")  # new keys go last
    assert camera(text, "two") == camera(BLOCK_STYLE, "two")


def test_a_camera_written_as_one_flow_mapping_is_rewritten_without_comments() -> None:
    result = update_camera_text(BLOCK_STYLE, "two", {"intrinsics": {"fx": 310.0, "fy": 311.0, "cx": 321.0, "cy": 239.0}})
    assert not result.comments_kept
    assert camera(result.text, "two")["intrinsics"]["fy"] == 311.0
    assert camera(result.text, "one") == camera(BLOCK_STYLE, "one")


def test_json_sites_keep_their_key_order() -> None:
    raw = yaml.safe_load(BLOCK_STYLE)
    text = json.dumps(raw, indent=2)
    result = update_camera_text(text, "one", NEW_LENS, fmt="json")
    edited = json.loads(result.text)
    assert list(edited["cameras"][0]) == list(raw["cameras"][0])
    assert edited["cameras"][0]["intrinsics"] == NEW_LENS["intrinsics"]


@pytest.mark.parametrize(
    ("camera_id", "changes", "message"),
    [
        ("nobody", NEW_LENS, "no camera 'nobody'; its cameras are hall-sw"),
        ("hall-sw", {"distortion": [0.1, 0.2]}, "exactly 4|needs 4 coefficients"),
        ("hall-sw", {"extrinsics": NEW_POSE["extrinsics"]}, "both 'pose' and 'extrinsics'"),
    ],
)
def test_changes_that_break_the_site_are_refused(camera_id: str, changes: dict, message: str) -> None:
    with pytest.raises(SiteError, match=message):
        update_camera_text(EXAMPLE, camera_id, changes)


def test_file_update_keeps_a_backup_and_the_mode(tmp_path: Path) -> None:
    path = tmp_path / "site.yaml"
    path.write_text(EXAMPLE)
    path.chmod(0o640)
    update_camera_file(path, "hall-ne", NEW_LENS)
    assert (tmp_path / "site.yaml.bak").read_text() == EXAMPLE
    assert load_site(path).cameras[3].intrinsics.fx == 634.25
    assert path.stat().st_mode & 0o777 == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["site.yaml", "site.yaml.bak"]  # no temporary left


def test_a_broken_file_is_left_alone(tmp_path: Path) -> None:
    path = tmp_path / "site.yaml"
    path.write_text("cameras: [\n")
    with pytest.raises(SiteError, match="not valid YAML"):
        update_camera_file(path, "a", NEW_LENS)
    assert path.read_text() == "cameras: [\n" and not (tmp_path / "site.yaml.bak").exists()


@pytest.mark.parametrize("value", [0.0, -0.0, 1e-05, 2.5e16, -1.2345678901234567, 634.3, 1e300, 3.0])
def test_floats_round_trip_through_yaml(value: float) -> None:
    assert yaml.safe_load(_yaml_float(value)) == value
    assert isinstance(yaml.safe_load(_yaml_float(value)), float)


@pytest.mark.parametrize("value", ["plain", "a: b", "#hash", "yes", "1.5", "", {"k": [1, 2.5, None, True]}])
def test_flow_text_loads_back(value: object) -> None:
    assert yaml.safe_load(_flow(value)) == value


def test_doctests() -> None:
    assert doctest.testmod(bevflow.site_edit).failed == 0
