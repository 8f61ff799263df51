"""The project installs every package it has, and the core library stays free of I/O frameworks:
it imports no module of an extra (``bevflow_services.extras``) but the training's."""

from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

import pytest

from bevflow_services.extras import EXTRA_OF_MODULE, RUNTIME_EXTRAS

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_ROOTS = {
    "bevflow": ROOT / "shared" / "bevflow",
    "bevflow_services": ROOT / "services" / "bevflow_services",
    "bevflow_dashboard": ROOT / "dashboard" / "bevflow_dashboard",
}


def _package_folders() -> list[str]:
    names = []
    for name, folder in PACKAGE_ROOTS.items():
        for init in folder.rglob("__init__.py"):
            rel = init.parent.relative_to(folder)
            names.append(".".join((name, *rel.parts)))
    return sorted(names)


def test_every_package_folder_is_listed_in_pyproject() -> None:
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    missing = [p for p in _package_folders() if p not in listed]
    assert not missing, f"add these to [tool.setuptools] packages in pyproject.toml: {missing}"


@pytest.mark.parametrize("path", sorted((ROOT / "shared" / "bevflow").rglob("*.py")), ids=lambda p: str(p.relative_to(ROOT)))
def test_core_library_imports_no_service_frameworks(path: Path) -> None:
    # the person detector imports ONNX Runtime, whichever build is installed, when a model loads
    forbidden = {module for module, extra in EXTRA_OF_MODULE.items() if extra != "train" and extra not in RUNTIME_EXTRAS}
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        for name in names:
            assert name.split(".")[0] not in forbidden, f"{path.name} imports {name}"


def _pins() -> dict[str, str]:
    lines = (ROOT / "constraints.txt").read_text().splitlines()
    pairs = [line.split("==") for line in lines if line and not line.startswith("#")]
    return {_normal(name): version for name, version in pairs}


def _normal(name: str) -> str:
    return name.split("[")[0].strip().lower().replace("_", "-")


def _version(text: str) -> tuple[int, ...]:
    return tuple(int(part) for part in text.split(".")[:3] if part.isdigit())


def _requirements() -> list[str]:
    """Every requirement the tests ran with: the required ones and those of every extra but train
    (torch is not in the test environment) and the ONNX Runtime builds that replace the CPU's
    (run by hand, docs/INSTALL.md), less the extras' references to other extras."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    skipped = {"train", *RUNTIME_EXTRAS[1:]}
    optional = [r for extra, reqs in project["optional-dependencies"].items() if extra not in skipped for r in reqs]
    return [*project["dependencies"], *(r for r in optional if not r.startswith("bevflow["))]


@pytest.mark.parametrize("requirement", _requirements())
def test_each_dependency_is_pinned_at_or_above_its_floor(requirement: str) -> None:
    """constraints.txt pins what the tests ran on; pyproject's floors may not ask for more."""
    name, _, floor = requirement.partition(">=")
    pins = _pins()
    assert _normal(name) in pins, f"{name} is missing from constraints.txt (scripts/freeze_constraints.py)"
    assert floor, f"{requirement}: give a floor, the oldest version the tests ran on"
    assert _version(pins[_normal(name)]) >= _version(floor), f"{requirement} but constraints.txt pins {pins[_normal(name)]}"


def test_constraints_leave_out_the_project_and_local_paths() -> None:
    assert "bevflow" not in _pins()
    assert not [line for line in (ROOT / "constraints.txt").read_text().splitlines() if " @ " in line or line.startswith("-e")]


def test_license_and_third_party_notices() -> None:
    assert "Apache License" in (ROOT / "LICENSE").read_text()[:200]
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["license"] == "Apache-2.0" and project["license-files"] == ["LICENSE", "NOTICE"]  # SPDX, in the wheel
    notice = (ROOT / "NOTICE").read_text()
    for path in re.findall(r"shared/bevflow/\S+?\.(?:onnx|txt|md)\b", notice):
        assert (ROOT / path).is_file(), f"NOTICE names {path}, which does not exist"
    shipped = {p.name for p in (ROOT / "shared/bevflow/data/models").glob("LICENSE-*")}
    assert shipped and all(name in notice for name in shipped), "every model licence file is named in NOTICE"
