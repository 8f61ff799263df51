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
# The ONNX Runtime builds that replace the default (CPU) one, so are never installed beside it
# here: the module each installs, as checked by installing them on their own.
REPLACEMENT_RUNTIMES = {"onnxruntime-gpu": {"onnxruntime"}, "onnxruntime-openvino": {"onnxruntime"}}


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
    if distribution in REPLACEMENT_RUNTIMES:
        return REPLACEMENT_RUNTIMES[distribution]
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
    # every ONNX Runtime build's module is named by the default build's extra, which a hint names first
    expected = extras.RUNTIME_EXTRAS[0] if extra in extras.RUNTIME_EXTRAS else extra
    for module in _modules_of(distribution):
        assert extras.EXTRA_OF_MODULE.get(module) == expected, (
            f"{distribution} ({extra}) installs '{module}': map it to '{expected}' in bevflow_services/extras.py")


@pytest.mark.parametrize(("module", "extra"), sorted(extras.EXTRA_OF_MODULE.items()))
def test_each_mapped_module_comes_with_its_extra(module: str, extra: str) -> None:
    assert extra in OPTIONAL and extra not in NOT_IMPORTED, f"'{module}' maps to '{extra}', which pyproject.toml lacks"
    listed = [_name(r) for r in OPTIONAL[extra]]
    if extra in extras.RUNTIME_EXTRAS:
        listed = [_name(r) for runtime in extras.RUNTIME_EXTRAS for r in OPTIONAL[runtime]]
    distributions = listed + [required for d in listed for required in _requires(d)]
    assert module in set().union(*map(_modules_of, distributions)), f"no distribution of the '{extra}' extra, nor one they require, installs '{module}'"


def test_all_is_every_extra_a_site_runs_and_the_tests_install_it() -> None:
    gathered = re.fullmatch(r"bevflow\[(.+)\]", OPTIONAL["all"][0])
    assert len(OPTIONAL["all"]) == 1 and gathered
    other_runtimes = set(extras.RUNTIME_EXTRAS[1:])  # all detects on the default build, the CPU's
    assert sorted(gathered.group(1).split(",")) == sorted(set(OPTIONAL) - NOT_IMPORTED - NOT_FOR_SITES - other_runtimes)
    assert "bevflow[all]" in OPTIONAL["test"]


def _runtimes_in(requirements: list[str], seen: frozenset[str] = frozenset()) -> set[str]:
    """The runtime extras that ``requirements`` install, following ``bevflow[...]`` references."""
    found: set[str] = set()
    for requirement in requirements:
        gathered = re.fullmatch(r"bevflow\[(.+)\]", requirement)
        for extra in gathered.group(1).split(",") if gathered else []:
            if extra in extras.RUNTIME_EXTRAS:
                found.add(extra)
            elif extra not in seen:
                found |= _runtimes_in(OPTIONAL[extra], seen | {extra})
    return found


@pytest.mark.parametrize("extra", sorted(OPTIONAL))
def test_no_extra_installs_two_onnx_runtime_builds(extra: str) -> None:
    """Each build installs the ``onnxruntime`` module: two would overwrite each other's files."""
    runtimes = _runtimes_in(OPTIONAL[extra]) | ({extra} & set(extras.RUNTIME_EXTRAS))
    assert len(runtimes) <= 1, f"'{extra}' installs {sorted(runtimes)}"
    assert runtimes <= {extra, extras.RUNTIME_EXTRAS[0]}, f"'{extra}' installs {sorted(runtimes)} rather than the default"


def test_the_required_dependencies_hold_no_onnx_runtime_build() -> None:
    required = {_name(r) for r in tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]}
    builds = {_name(r) for runtime in extras.RUNTIME_EXTRAS for r in OPTIONAL[runtime]}
    assert not required & builds, "a build in the required set could not be replaced by another's extra"


@pytest.mark.parametrize(
    ("missing", "extra"),
    [("zenoh", "services"), ("zenoh.ext", "services"), ("reportlab.graphics", "reports"), ("psycopg", "postgres"),
     ("torch", "train"), ("onnxruntime", "cpu"), ("onnxruntime.quantization", "cpu"), ("bevflow_services.no_such_module", None), ("not_a_real_package_for_bevflow_tests", None), (None, None)],
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
