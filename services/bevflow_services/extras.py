"""Which of bevflow's pip extras installs each optional module, and the line that says so.

The core library (``bevflow``) and ``bevflow evaluate`` need only the required dependencies, but
for the person detector, which needs one ONNX Runtime build (``RUNTIME_EXTRAS``); the live system
and its parts need the extras of pyproject.toml's [project.optional-dependencies].
A ``ModuleNotFoundError`` for a module listed here means its extra is not installed, which the
``bevflow`` command says in one line; any other missing module is a bug and stays an error.

    >>> extra_for(ModuleNotFoundError("No module named 'zenoh'", name="zenoh"))
    'services'
    >>> install_hint("reports")
    "needs the 'reports' extra: pip install 'bevflow[reports]'"
    >>> install_hint("cpu")
    "needs ONNX Runtime: pip install 'bevflow[cpu]' (or one of 'bevflow[gpu]', 'bevflow[openvino]' instead)"
"""

from __future__ import annotations

import importlib.util

# The builds of ONNX Runtime, one extra each, all installing the ``onnxruntime`` module: a host
# installs exactly one. The first is the default (in ``all``).
RUNTIME_EXTRAS = ("cpu", "gpu", "openvino")

# Top-level import name -> the extra that installs it. tests/test_packaging.py checks this against
# pyproject.toml, so an optional dependency added there cannot be forgotten here.
EXTRA_OF_MODULE: dict[str, str] = {
    "zenoh": "services",
    "fastapi": "services",
    "starlette": "services",  # comes with fastapi; the gateway imports it directly too
    "uvicorn": "services",
    "websockets": "services",
    "argon2": "services",
    "fastapi_offline": "services",
    "prometheus_client": "services",
    "paho": "services",
    "av": "services",  # the ingest's camera streams and video files
    "viser": "view3d",
    "psycopg": "postgres",
    "reportlab": "reports",
    "onnxruntime": "cpu",  # or another of RUNTIME_EXTRAS
    "torch": "train",
    "onnx": "train",
    "onnxscript": "train",
}


def extra_for(error: ModuleNotFoundError) -> str | None:
    """The extra whose absence raised ``error``; None when the missing module is none of theirs."""
    return EXTRA_OF_MODULE.get((error.name or "").split(".")[0])


def install_hint(extra: str) -> str:
    """How a message ends that names a missing extra."""
    if extra in RUNTIME_EXTRAS:
        others = ", ".join(f"'bevflow[{e}]'" for e in RUNTIME_EXTRAS if e != extra)
        return f"needs ONNX Runtime: pip install 'bevflow[{extra}]' (or one of {others} instead)"
    return f"needs the '{extra}' extra: pip install 'bevflow[{extra}]'"


def missing_module(extra: str) -> str | None:
    """The first of ``extra``'s modules that cannot be imported here; None when all can."""
    for module, owner in EXTRA_OF_MODULE.items():
        if owner == extra and importlib.util.find_spec(module) is None:
            return module
    return None


def require(extra: str) -> None:
    """Raise ``ModuleNotFoundError``, as importing it would, when a module of ``extra`` is missing:
    for a command that starts other processes, which would each fail on their own."""
    module = missing_module(extra)
    if module is not None:
        raise ModuleNotFoundError(f"No module named {module!r}", name=module)
