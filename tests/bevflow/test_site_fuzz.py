"""Property-based fuzzing of the site loader: whatever a technician (or a corrupted disk) puts in
a site file, ``parse_site`` returns a usable ``Site`` or raises ``SiteError`` with a message that
names the file, never another exception."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bevflow.site import BUILTIN_SITES, Site, SiteError, parse_site
from tests.bevflow.test_schemas_fuzz import json_values, mutated

FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SOURCE = "fuzz.yaml"

SITE_FILES = sorted(BUILTIN_SITES.glob("*.yaml"))
# A small site using every section (both camera models, pose and extrinsics, zones, thresholds).
SMALL_SITE: dict[str, Any] = {
    "site": "hall",
    "floor": [-5, -5, 15, 5],
    "cameras": [
        {"id": "north", "image_size": [800, 800], "intrinsics": {"fx": 250, "fy": 250, "cx": 400, "cy": 400},
         "pose": {"position": [0, 0, 4], "yaw_deg": 10}, "monitored_radius_m": 6},
        {"id": "side", "model": "pinhole", "image_size": [640, 480],
         "intrinsics": {"fx": 500, "fy": 500, "cx": 320, "cy": 240}, "distortion": [0.1, 0, 0, 0, 0],
         "extrinsics": {"rvec": [2.0, 0, 0], "tvec": [0, 0, 4]}},
    ],
    "zones": [{"id": "gate", "polygon": [[0, 0], [4, 0], [4, 4]], "capacity": 3, "crowded_level": 2}],
    "thresholds": {"social_distance_m": 1.5, "site_capacity": 12, "group_after_s": None},
}
SEEDS = [SMALL_SITE] + [yaml.safe_load(p.read_text(encoding="utf-8")) for p in SITE_FILES]


def check_parse(text: str, fmt: str = "yaml") -> Site | None:
    """Parse; a refusal must be a ``SiteError`` whose every line names the file. What is
    accepted must build its cameras (services do that first) and map the floor."""
    try:
        site = parse_site(text, source=SOURCE, fmt=fmt)  # type: ignore[arg-type]
    except SiteError as exc:
        lines = str(exc).splitlines()
        assert lines and all(line.startswith(f"{SOURCE}: ") and len(line) > len(SOURCE) + 2 for line in lines), str(exc)
        return None
    cameras = site.built_cameras
    assert list(cameras) == site.camera_ids
    for camera in cameras.values():
        assert np.isfinite(camera.center).all()
    return site


def test_the_seed_sites_are_valid() -> None:
    assert len(SEEDS) >= 2
    for seed in SEEDS:
        assert check_parse(yaml.safe_dump(seed)) is not None


@FUZZ
@given(text=st.text(max_size=300))
def test_arbitrary_text_is_a_site_or_a_site_error(text: str) -> None:
    check_parse(text, "yaml")
    check_parse(text, "json")


@FUZZ
@given(tree=json_values)
def test_arbitrary_trees_are_a_site_or_a_site_error(tree: Any) -> None:
    check_parse(yaml.safe_dump(tree), "yaml")
    check_parse(json.dumps(tree), "json")


@FUZZ
@given(data=st.data(), seed=st.sampled_from(range(len(SEEDS))))
def test_mutated_site_files_are_a_site_or_a_site_error(data: st.DataObject, seed: int) -> None:
    tree = data.draw(mutated(SEEDS[seed]))
    fmt = data.draw(st.sampled_from(["yaml", "json"]))
    check_parse(yaml.safe_dump(tree) if fmt == "yaml" else json.dumps(tree), fmt)


@FUZZ
@given(data=st.data())
def test_mutated_yaml_text_is_a_site_or_a_site_error(data: st.DataObject) -> None:
    # Byte-level damage: a truncated file, a stray character, a lost indent.
    text = yaml.safe_dump(SMALL_SITE)
    at = data.draw(st.integers(0, len(text)))
    damage = data.draw(st.sampled_from(["cut", "insert", "delete"]))
    if damage == "cut":
        text = text[:at]
    elif damage == "insert":
        stray = data.draw(st.sampled_from([":", "-", " ", "\t", "[", "{", "&a", "*a", "!!", "'", "\x00", "é"]))
        text = text[:at] + stray + text[at:]
    else:
        text = text[:at] + text[at + data.draw(st.integers(1, 20)):]
    check_parse(text)


@pytest.mark.parametrize(
    "text",
    [
        pytest.param("!!python/object:os.system {}", id="python-tag"),
        pytest.param("a: &a [*a]", id="recursive-alias"),
        pytest.param("cameras: &c [{id: a}]\nzones: *c", id="alias-reused"),
        pytest.param("? [1, 2]\n: x\ncameras: []", id="complex-key"),
        pytest.param("1: 2\ncameras: [1]", id="int-key"),
        pytest.param("cameras:\n  - " + "[" * 200 + "]" * 200, id="deep-nesting"),
        pytest.param("cameras: [{id: a, intrinsics: {fx: 1e400, fy: 1, cx: 0, cy: 0}}]", id="overflow"),
        pytest.param("site: hall\nsite: hall2\ncameras: []", id="duplicate-key"),
        pytest.param("\ufeffcameras: []", id="bom"),
    ],
)
def test_hostile_yaml_is_a_site_error(text: str) -> None:
    with pytest.raises(SiteError, match=f"^{SOURCE}: "):
        parse_site(text, source=SOURCE)
