"""``bevflow_services.extras`` agrees with pyproject.toml: every optional dependency's modules map
to its extra (so a dependency added there cannot be forgotten), every mapped module comes with its
extra, and ``all`` is every extra a site runs."""

from __future__ import annotations

import functools
import importlib.metadata
import re
import sys
import tomllib
from pathlib import Path

import pytest

from bevflow_services import extras

ROOT = Path(__file__).resolve().parents[2]
OPTIONAL = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
# No module of bevflow imports from these: the test tools, and ``all``, which only gathers others.
NOT_IMPORTED = {"test", "all"}
# Extras a site's live system does not run: training happens elsewhere.
NOT_FOR_SITES = {"train"}


def _name(requirement: str) -> str:
    """The distribution a requirement names, normalised (PEP 503): ``psycopg[binary]>=3.3`` -> psycopg."""
    match = re.match(r"[A-Za-z0-9._-]+", requirement)
    assert match, requirement
    return re.sub(r"[-_.]+", "-", match.group(0)).lower()


@functools.cache
def _installed_modules() -> dict[str, set[str]]:
    """Each installed distribution's public top-level modules."""
    modules: dict[str, set[str]] = {}
    for module, owners in importlib.metadata.packages_distributions().items():
        for owner in owners:
            if not module.startswith("_"):
                modules.setdefault(_name(owner), set()).add(module)
    return modules


def _modules_of(distribution: str) -> set[str]:
    """The top-level modules ``distribution`` installs; its name as a module where it is not
    installed here (the train extra's torch and onnx are not in the test environment)."""
    return _installed_modules().get(distribution) or {distribution.replace("-", "_")}


def _requires(distribution: str) -> list[str]:
    """The distributions ``distribution`` always requires (none where it is not installed)."""
    try:
        requirements = importlib.metadata.requires(distribution) or []
    except importlib.metadata.PackageNotFoundError:
        return []
    return [_name(r) for r in requirements if "extra ==" not in r]


OPTIONAL_DEPENDENCIES = [(extra, _name(r)) for extra, reqs in OPTIONAL.items() if extra not in NOT_IMPORTED for r in reqs]


@pytest.mark.parametrize(("extra", "distribution"), OPTIONAL_DEPENDENCIES)
def test_each_optional_dependency_maps_to_its_extra(extra: str, distribution: str) -> None:
    for module in _modules_of(distribution):
        assert extras.EXTRA_OF_MODULE.get(module) == extra, (
            f"{distribution} ({extra}) installs '{module}': map it to '{extra}' in bevflow_services/extras.py")


@pytest.mark.parametrize(("module", "extra"), sorted(extras.EXTRA_OF_MODULE.items()))
def test_each_mapped_module_comes_with_its_extra(module: str, extra: str) -> None:
    assert extra in OPTIONAL and extra not in NOT_IMPORTED, f"'{module}' maps to '{extra}', which pyproject.toml lacks"
    listed = [_name(r) for r in OPTIONAL[extra]]
    distributions = listed + [required for d in listed for required in _requires(d)]
    assert module in set().union(*map(_modules_of, distributions)), f"no distribution of the '{extra}' extra, nor one they require, installs '{module}'"


def test_all_is_every_extra_a_site_runs_and_the_tests_install_it() -> None:
    gathered = re.fullmatch(r"bevflow\[(.+)\]", OPTIONAL["all"][0])
    assert len(OPTIONAL["all"]) == 1 and gathered
    assert sorted(gathered.group(1).split(",")) == sorted(set(OPTIONAL) - NOT_IMPORTED - NOT_FOR_SITES)
    assert "bevflow[all]" in OPTIONAL["test"]


@pytest.mark.parametrize(
    ("missing", "extra"),
    [("zenoh", "services"), ("zenoh.ext", "services"), ("reportlab.graphics", "reports"), ("psycopg", "postgres"),
     ("torch", "train"), ("bevflow_services.no_such_module", None), ("not_a_real_package_for_bevflow_tests", None), (None, None)],
)
def test_the_extra_of_a_missing_module(missing: str | None, extra: str | None) -> None:
    assert extras.extra_for(ModuleNotFoundError(f"No module named {missing!r}", name=missing)) == extra


def test_require_raises_as_the_import_would(monkeypatch: pytest.MonkeyPatch) -> None:
    extras.require("services")  # installed here
    monkeypatch.setitem(sys.modules, "viser", None)  # what importing viser would meet where it is missing
    assert extras.missing_module("view3d") == "viser"
    with pytest.raises(ModuleNotFoundError) as raised:
        extras.require("view3d")
    assert raised.value.name == "viser" and extras.extra_for(raised.value) == "view3d"
