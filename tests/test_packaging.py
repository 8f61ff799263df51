"""The project installs every package it has, and the core library stays free of I/O frameworks."""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_ROOTS = {"bevflow": ROOT / "shared" / "bevflow", "bevflow_services": ROOT / "services", "bevflow_dashboard": ROOT / "dashboard"}


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
    forbidden = {"zenoh", "fastapi", "viser", "uvicorn", "starlette"}
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        for name in names:
            assert name.split(".")[0] not in forbidden, f"{path.name} imports {name}"
