"""Every ">>>" example in the services runs, each module imported under its package name
(bevflow_services.…) as the installed package is."""

from __future__ import annotations

import doctest
import importlib
from pathlib import Path

import pytest

SERVICES = Path(__file__).resolve().parents[2] / "services" / "bevflow_services"


def _modules_with_examples() -> list[str]:
    names = []
    for path in sorted(SERVICES.rglob("*.py")):
        if ">>>" in path.read_text(encoding="utf-8"):
            parts = path.relative_to(SERVICES).with_suffix("").parts
            names.append(".".join(("bevflow_services", *(p for p in parts if p != "__init__"))))
    return names


@pytest.mark.parametrize("name", _modules_with_examples())
def test_examples_run(name: str) -> None:
    result = doctest.testmod(importlib.import_module(name))
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples in {name} failed"
