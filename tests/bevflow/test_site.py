"""Site files: what loads, what is refused and how the refusal reads."""

from __future__ import annotations

import copy
import importlib.resources
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from bevflow.camera import FisheyeCamera, PinholeCamera, rotation_from_ypr
from bevflow.remap import BevMosaic
from bevflow.site import Site, SiteError, Thresholds, Zone, dump_site, load_site, parse_site

# Shipped with the package, so read it from there.
EXAMPLE_HALL = Path(str(importlib.resources.files("bevflow") / "data" / "sites" / "example-hall.yaml"))

BASE: dict[str, Any] = {
    "site": "hall",
    "floor": [0, 0, 20, 10],
    "cameras": [
        {
            "id": "cam-a",
            "image_size": [1024, 1024],
            "intrinsics": {"fx": 300, "fy": 300, "cx": 511.5, "cy": 511.5},
            "distortion": [0, 0, 0, 0],
            "pose": {"position": [5, 5, 5.5]},
        },
        {
            "id": "cam-b",
            "image_size": [1024, 1024],
            "intrinsics": {"fx": 300, "fy": 300, "cx": 511.5, "cy": 511.5},
            "pose": {"position": [15, 5, 5.5]},
        },
    ],
    "zones": [
        {"id": "entrance", "polygon": [[0, 0], [4, 0], [4, 4]]},
        {"id": "bar", "polygon": [[5, 0], [9, 0], [9, 4]], "capacity": 10},
    ],
}


def _site_text(edit: Callable[[dict[str, Any]], Any]) -> str:
    raw = copy.deepcopy(BASE)
    edit(raw)
    return yaml.safe_dump(raw, sort_keys=False)


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    """An edit that sets ``a.b.0.c`` (list indices as numbers) to ``value``."""

    def edit(raw: dict[str, Any]) -> None:
        *parents, last = [int(p) if p.isdigit() else p for p in path.split(".")]
        node: Any = raw
        for key in parents:
            node = node[key]
        node[last] = value

    return edit


def _drop(path: str) -> Callable[[dict[str, Any]], None]:
    def edit(raw: dict[str, Any]) -> None:
        *parents, last = [int(p) if p.isdigit() else p for p in path.split(".")]
        node: Any = raw
        for key in parents:
            node = node[key]
        del node[last]

    return edit


# Each row: an edit of a valid site, then the pieces its one-line message must contain:
# the field, the camera or zone, and what is wrong.
INVALID = [
    pytest.param(
        _set("cameras.1.intrinsics.fx", -300.0),
        ["cameras[1] (id 'cam-b').intrinsics.fx", "greater than 0"],
        id="negative-fx",
    ),
    pytest.param(
        _set("cameras.1.intrinsics.fx", "wide"),
        ["cameras[1] (id 'cam-b').intrinsics.fx", "valid number"],
        id="fx-not-a-number",
    ),
    pytest.param(
        _set("cameras.0.intrinsics.cy", float("nan")),
        ["cameras[0] (id 'cam-a').intrinsics.cy", "finite number"],
        id="nan",
    ),
    pytest.param(
        _set("cameras.0.pose.position", [1, 2, float("inf")]),
        ["cameras[0] (id 'cam-a').pose.position[2]", "finite number"],
        id="infinite-height",
    ),
    pytest.param(
        _set("cameras.1.image_size", "1024x1024"),
        ["cameras[1] (id 'cam-b').image_size", "tuple"],
        id="image-size-as-text",
    ),
    pytest.param(
        _set("cameras.1.image_size", [1024, 1024, 3]),
        ["cameras[1] (id 'cam-b').image_size", "at most 2"],
        id="image-size-three-numbers",
    ),
    pytest.param(
        _set("cameras.1.image_size", [1024, 0]),
        ["cameras[1] (id 'cam-b').image_size[1]", "greater than 0"],
        id="zero-height-image",
    ),
    pytest.param(
        _set("cameras.0.model", "fish-eye"),
        ["cameras[0] (id 'cam-a').model", "'fisheye' or 'pinhole'"],
        id="unknown-model",
    ),
    pytest.param(_drop("cameras.1.pose"), ["cameras[1] (id 'cam-b')", "no 'pose'", "'extrinsics'"], id="missing-pose"),
    pytest.param(
        _set("cameras.1.extrinsics", {"rvec": [3.14, 0, 0], "tvec": [0, 0, 5]}),
        ["cameras[1] (id 'cam-b')", "both 'pose' and 'extrinsics'"],
        id="pose-and-extrinsics",
    ),
    pytest.param(
        _drop("cameras.0.intrinsics"), ["cameras[0] (id 'cam-a').intrinsics", "Field required"], id="missing-intrinsics"
    ),
    pytest.param(
        _set("cameras.0.distortion", [0.1, 0.0, 0.0]),
        ["cameras[0] (id 'cam-a').distortion", "fisheye camera needs 4", "got 3"],
        id="fisheye-3-coefficients",
    ),
    pytest.param(
        lambda r: r["cameras"][1].update(model="pinhole", distortion=[0.1] * 6),
        ["cameras[1] (id 'cam-b').distortion", "0, 4, 5 or 8", "got 6"],
        id="pinhole-6-coefficients",
    ),
    pytest.param(
        _set("cameras.1.id", "cam-a"),
        ["cameras:", "id 'cam-a' is used by cameras[0] and cameras[1]"],
        id="duplicate-camera-id",
    ),
    pytest.param(
        _set("cameras.1.id", "cam b"), ["cameras[1] (id 'cam b').id", "letters, digits"], id="camera-id-with-space"
    ),
    pytest.param(_set("cameras", []), ["cameras:", "at least 1"], id="no-cameras"),
    pytest.param(
        _set("cameras.1.heigth", 5.5), ["cameras[1] (id 'cam-b').heigth", "unknown field"], id="unknown-camera-field"
    ),
    pytest.param(
        _set("cameras.0.pose.yaw", 90), ["cameras[0] (id 'cam-a').pose.yaw", "unknown field"], id="unknown-pose-field"
    ),
    pytest.param(_set("camera", []), ["camera:", "unknown field"], id="unknown-top-level-field"),
    pytest.param(
        _set("zones.1.polygon", [[0, 0], [1, 1]]), ["zones[1] (id 'bar').polygon", "at least 3"], id="zone-two-points"
    ),
    pytest.param(
        _set("zones.0.polygon", [[0, 0], [1, 1], [3, 3]]),
        ["zones[0] (id 'entrance').polygon", "no area"],
        id="zone-points-in-a-line",
    ),
    pytest.param(
        _set("zones.1.id", "entrance"),
        ["zones:", "id 'entrance' is used by zones[0] and zones[1]"],
        id="duplicate-zone-id",
    ),
    pytest.param(
        _set("zones.1.capacity", -1),
        ["zones[1] (id 'bar').capacity", "greater than or equal to 0"],
        id="negative-capacity",
    ),
    pytest.param(
        _set("zones.0.colour", "red"), ["zones[0] (id 'entrance').colour", "unknown field"], id="unknown-zone-field"
    ),
    pytest.param(
        _set("thresholds", {"fusion_distance_m": 0}),
        ["thresholds.fusion_distance_m", "greater than 0"],
        id="zero-fusion-distance",
    ),
    pytest.param(
        _set("thresholds", {"track_max_misses": 0}),
        ["thresholds.track_max_misses", "greater than or equal to 1"],
        id="zero-misses",
    ),
    pytest.param(_set("floor", [0, 0, -5, 10]), ["floor:", "xmax > xmin"], id="floor-inverted"),
    # Values that cannot be right (issue 21): a camera under the floor or at head height, a radius
    # no camera watches, a zone off the floor.
    pytest.param(_set("cameras.0.pose.position", [5, 5, -5.5]),
                 ["cameras[0] (id 'cam-a')", "pose.position", "-5.50 m above the floor"], id="camera-under-the-floor"),
    pytest.param(_set("cameras.1.pose.position", [5, 5, 1.0]),
                 ["cameras[1] (id 'cam-b')", "pose.position", "1.00 m above the floor", "between 2 and 100 m"],
                 id="camera-at-head-height"),
    pytest.param(_set("cameras.0.monitored_radius_m", 1e9),
                 ["cameras[0] (id 'cam-a')", "monitored_radius_m: 1e+09 m"], id="radius-1e9"),
    pytest.param(_set("zones.1.polygon", [[50, 50], [60, 50], [60, 60]]),
                 ["zones[1] (id 'bar').polygon", "entirely outside the floor"], id="zone-off-the-floor"),
]


@pytest.mark.parametrize(("edit", "expected"), INVALID)
def test_invalid_site_names_file_field_and_id(edit: Callable[[dict[str, Any]], Any], expected: list[str]) -> None:
    with pytest.raises(SiteError) as caught:
        parse_site(_site_text(edit), source="hall.yaml")
    message = str(caught.value)
    assert message.startswith("hall.yaml: "), message
    for piece in expected:
        assert piece in message, f"{piece!r} not in {message!r}"
    assert "Value error" not in message and "\n" not in message  # one plain line per mistake


def test_every_mistake_is_reported_on_its_own_line() -> None:
    def edit(raw: dict[str, Any]) -> None:
        raw["cameras"][0]["intrinsics"]["fx"] = -1
        raw["zones"][1]["polygon"] = [[0, 0], [1, 1]]

    with pytest.raises(SiteError) as caught:
        parse_site(_site_text(edit), source="hall.yaml")
    lines = str(caught.value).splitlines()
    assert len(lines) == 2
    assert lines[0].startswith("hall.yaml: cameras[0] (id 'cam-a').intrinsics.fx")
    assert lines[1].startswith("hall.yaml: zones[1] (id 'bar').polygon")


@pytest.mark.parametrize(
    ("text", "fmt", "expected"),
    [
        pytest.param(
            "site: hall\ncameras:\n  - id: a\n    image_size: [1024, 1024\n",
            "yaml",
            "site.yaml: not valid YAML at line 5",
            id="unclosed-list",
        ),
        pytest.param(
            "site: hall\ncameras:\n\t- id: a\n", "yaml", "site.yaml: not valid YAML at line 3", id="tab-indent"
        ),
        pytest.param("site: hall\n  cameras: []\n", "yaml", "site.yaml: not valid YAML at line 2", id="bad-indent"),
        pytest.param(
            '{\n  "site": "hall",\n  "cameras": [,]\n}',
            "json",
            "site.yaml: not valid JSON at line 3, column 15: Expecting value",
            id="json-syntax",
        ),
        pytest.param("", "yaml", "site.yaml: the file is empty", id="empty"),
        pytest.param(
            "- id: a\n- id: b\n",
            "yaml",
            "site.yaml: expected a mapping with 'cameras' at the top, got a list",
            id="top-level-list",
        ),
    ],
)
def test_unreadable_text_names_file_and_line(text: str, fmt: str, expected: str) -> None:
    with pytest.raises(SiteError) as caught:
        parse_site(text, source="site.yaml", fmt=fmt)  # type: ignore[arg-type]
    assert str(caught.value).startswith(expected), str(caught.value)


@pytest.mark.parametrize(
    ("make_path", "expected"),
    [
        pytest.param(
            lambda tmp: tmp / "missing.yaml",
            "missing.yaml: cannot read the site file (No such file or directory)",
            id="missing",
        ),
        pytest.param(lambda tmp: tmp, "cannot read the site file", id="a-folder"),
    ],
)
def test_unreadable_file_names_the_file(tmp_path: Path, make_path: Callable[[Path], Path], expected: str) -> None:
    path = make_path(tmp_path)
    with pytest.raises(SiteError) as caught:
        load_site(path)
    assert str(caught.value).startswith(str(path)) and expected in str(caught.value)


def test_errors_from_files_name_the_file(tmp_path: Path) -> None:
    path = tmp_path / "lobby.yml"
    path.write_text(_site_text(_set("cameras.0.intrinsics.fx", 0)))
    with pytest.raises(SiteError, match=r"lobby\.yml: cameras\[0\] \(id 'cam-a'\)\.intrinsics\.fx"):
        load_site(path)


# --- what loads -----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("name", "dump"),
    [
        ("site.yaml", lambda raw: yaml.safe_dump(raw)),
        ("site.yml", lambda raw: yaml.safe_dump(raw)),
        ("site.json", json.dumps),
    ],
)
def test_yaml_and_json_load_the_same_site(tmp_path: Path, name: str, dump: Callable[[Any], str]) -> None:
    path = tmp_path / name
    path.write_text(dump(BASE))
    site = load_site(path)
    assert site == parse_site(yaml.safe_dump(BASE))
    assert [c.id for c in site.cameras] == ["cam-a", "cam-b"] and [z.id for z in site.zones] == ["entrance", "bar"]


def test_json_file_is_parsed_as_json(tmp_path: Path) -> None:
    # YAML would read this (a JSON document with a trailing comma is not valid JSON); the .json
    # suffix must make the stricter parser speak.
    path = tmp_path / "site.json"
    path.write_text('{"cameras": [1, 2,]}')
    with pytest.raises(SiteError, match="not valid JSON"):
        load_site(path)


def test_defaults_follow_the_paper() -> None:
    site = parse_site(_site_text(lambda raw: None))
    t = site.thresholds
    assert (t.fusion_distance_m, t.social_distance_m, t.track_activate_hits, t.track_max_misses) == (0.45, 2.0, 3, 5)
    assert site.cameras[1].model == "fisheye" and site.cameras[1].distortion == [0.0, 0.0, 0.0, 0.0]
    assert Thresholds() == t


def test_pose_builds_the_camera_it_describes() -> None:
    site = parse_site(
        _site_text(_set("cameras.1.pose", {"position": [15, 5, 5.5], "yaw_deg": 30, "pitch_deg": 10, "roll_deg": -5}))
    )
    cam = site.camera("cam-b")
    assert isinstance(cam, FisheyeCamera)
    np.testing.assert_allclose(cam.R, rotation_from_ypr(30, 10, -5), atol=1e-12)
    np.testing.assert_allclose(cam.center, [15, 5, 5.5], atol=1e-12)
    np.testing.assert_allclose(cam.K, [[300, 0, 511.5], [0, 300, 511.5], [0, 0, 1]])
    assert site.cameras[1].height_m == pytest.approx(5.5)


def test_extrinsics_build_the_camera_they_describe() -> None:
    # rvec (π, 0, 0) is the straight-down rotation; tvec = −R·centre.
    def edit(raw: dict[str, Any]) -> None:
        cam = raw["cameras"][1]
        del cam["pose"]
        cam.update(
            model="pinhole",
            distortion=[-0.1, 0.01, 0, 0, 0],
            extrinsics={"rvec": [np.pi, 0, 0], "tvec": [-2.0, 3.0, 4.0]},
        )

    site = parse_site(_site_text(edit))
    cam = site.camera("cam-b")
    assert isinstance(cam, PinholeCamera)
    np.testing.assert_allclose(cam.center, [2.0, 3.0, 4.0], atol=1e-12)
    np.testing.assert_allclose(cam.R, rotation_from_ypr(0, 0, 0), atol=1e-12)
    np.testing.assert_allclose(cam.dist, [-0.1, 0.01, 0, 0, 0])


def test_built_cameras_are_cached_on_the_frozen_site() -> None:
    site = parse_site(_site_text(lambda raw: None))
    first = site.built_cameras
    assert site.built_cameras is first and site.camera("cam-a") is first["cam-a"]
    assert list(first) == ["cam-a", "cam-b"]
    with pytest.raises(ValueError):
        site.site = "other"  # type: ignore[misc]
    # Caching adds nothing that equality, dumping or copying would see.
    assert site == parse_site(_site_text(lambda raw: None))
    assert parse_site(dump_site(site)) == site
    assert "built_cameras" not in site.model_dump()
    fewer = site.model_copy(update={"cameras": site.cameras[:1]})
    assert list(fewer.built_cameras) == ["cam-a"] and fewer.camera_ids == ["cam-a"]


@pytest.mark.parametrize(("camera_id", "index"), [("cam-a", 0), ("cam-b", 1)])
def test_camera_index_follows_file_order(camera_id: str, index: int) -> None:
    assert parse_site(_site_text(lambda raw: None)).camera_index(camera_id) == index


def test_unknown_camera_id_names_the_known_ones() -> None:
    site = parse_site(_site_text(lambda raw: None))
    with pytest.raises(KeyError, match="site 'hall' has no camera 'cam-z'; its cameras are cam-a, cam-b"):
        site.camera("cam-z")
    with pytest.raises(ValueError, match="no camera 'cam-z'"):
        site.camera_index("cam-z")


@pytest.mark.parametrize(
    ("capacity", "crowded_level", "expected"),
    [(None, None, None), (10, None, 8), (1, None, 1), (0, None, 1), (10, 3, 3), (None, 4, 4)],
)
def test_zone_crowded_level_defaults_to_80_percent(capacity, crowded_level, expected) -> None:
    zone = Zone(id="z", polygon=[(0, 0), (1, 0), (0, 1)], capacity=capacity, crowded_level=crowded_level)
    assert zone.effective_crowded_level == expected


def test_dump_round_trips_and_leaves_out_empty_fields() -> None:
    site = parse_site(_site_text(lambda raw: None))
    text = dump_site(site)
    assert parse_site(text) == site
    assert "extrinsics" not in text and "source" not in text


# --- the example a technician copies --------------------------------------------------------------
@pytest.fixture(scope="module")
def example() -> Site:
    return load_site(EXAMPLE_HALL)


def test_example_hall_describes_four_ceiling_fisheyes(example: Site) -> None:
    assert example.floor == (0.0, 0.0, 30.0, 20.0)
    assert len(example.cameras) == 4 and {c.model for c in example.cameras} == {"fisheye"}
    assert [z.id for z in example.zones] == ["entrance", "food-court"]
    for config in example.cameras:
        cam = example.camera(config.id)
        assert isinstance(cam, FisheyeCamera)
        assert config.height_m == pytest.approx(5.5)
        # Ceiling mounts look straight down: the floor below is at the principal point.
        below = np.array([[*cam.center[:2], 0.0]])
        np.testing.assert_allclose(cam.project(below)[0], cam.K[:2, 2], atol=1e-9)
        # The lens polynomial keeps growing over the whole view.
        assert cam.max_theta > np.radians(95)


def test_example_hall_cameras_cover_the_floor_and_zones(example: Site) -> None:
    mosaic = BevMosaic.from_site(example, metres_per_pixel=0.25)
    assert mosaic.size == (120, 80)
    assert (mosaic.camera_index >= 0).all(), "some floor is seen by no camera within its radius"
    # Each quarter of the hall is read from the camera above it.
    for k, config in enumerate(example.cameras):
        u, v = np.rint(mosaic.world_to_bev_pixels(np.array([config.pose.position[:2]]))[0]).astype(int)  # type: ignore[union-attr]
        assert mosaic.camera_index[v, u] == k
    xmin, ymin, xmax, ymax = example.floor  # type: ignore[misc]
    for zone in example.zones:
        xy = np.asarray(zone.polygon)
        assert (
            (xy[:, 0] >= xmin).all()
            and (xy[:, 0] <= xmax).all()
            and (xy[:, 1] >= ymin).all()
            and (xy[:, 1] <= ymax).all()
        )


def test_example_hall_extrinsics_comment_matches_its_pose(example: Site) -> None:
    # The file shows the 'extrinsics' alternative for hall-ne in a comment; it must be right.
    line = next(ln for ln in EXAMPLE_HALL.read_text().splitlines() if "extrinsics: {rvec" in ln)
    alternative = yaml.safe_load(line.lstrip("# ").strip())["extrinsics"]
    raw = yaml.safe_load(EXAMPLE_HALL.read_text())
    camera = next(c for c in raw["cameras"] if c["id"] == "hall-ne")
    del camera["pose"]
    camera["extrinsics"] = alternative
    rebuilt = Site.model_validate(raw).camera("hall-ne")
    np.testing.assert_allclose(rebuilt.center, example.camera("hall-ne").center, atol=1e-3)
    np.testing.assert_allclose(rebuilt.R, example.camera("hall-ne").R, atol=1e-4)


def test_site_argument_is_a_file_or_a_shipped_name(tmp_path, monkeypatch) -> None:
    import bevflow.site as site_module

    (tmp_path / "hall-b.yaml").write_text(EXAMPLE_HALL.read_text())
    monkeypatch.setattr(site_module, "BUILTIN_SITES", tmp_path)
    assert site_module.builtin_site_names() == ["hall-b"]
    by_name = site_module.load_site_or_builtin("hall-b")
    assert by_name == site_module.load_site_or_builtin(str(tmp_path / "hall-b.yaml"))
    with pytest.raises(site_module.SiteError, match="built-in: hall-b"):
        site_module.load_site_or_builtin("hall-c")


@pytest.mark.parametrize(
    ("edit", "warning"),
    [
        (_set("cameras.0.pose.position", [5, 5, 2.2]), "cameras[0] (id 'cam-a'): hangs 2.20 m above the floor"),
        (_set("cameras.1.pose.position", [15, 5, 25.0]), "cameras[1] (id 'cam-b'): hangs 25.00 m"),
        (_set("cameras.0.monitored_radius_m", 15.0), "cameras[0] (id 'cam-a').monitored_radius_m: 15 m"),
        (_set("zones.0.polygon", [[-2, 0], [4, 0], [4, 4]]), "zones[0] (id 'entrance').polygon: part of the zone"),
    ],
)
def test_odd_but_possible_values_load_with_a_warning(edit, warning: str, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level("WARNING", logger="bevflow.site"):
        parse_site(_site_text(edit), source="hall.yaml")
    assert [m for m in caplog.messages if m.startswith("hall.yaml: ") and warning in m], caplog.messages


def test_a_usual_site_loads_without_warnings(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level("WARNING", logger="bevflow.site"):
        parse_site(_site_text(lambda raw: None))
        load_site(EXAMPLE_HALL)
    assert caplog.messages == []
