"""``bevflow`` without an extra: a command that needs it says which in one line and exits with
status 2, no traceback; one that does not (``evaluate``, ``--help``) runs; and a missing module that
is no optional dependency stays an error, with its traceback.

Each case runs in its own process whose ``sys.modules`` holds None for the modules taken away,
which is what importing a package that is not installed meets."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from bevflow_services.extras import EXTRA_OF_MODULE, install_hint

WITHOUT = """
import sys
for name in filter(None, sys.argv[1].split(",")):
    sys.modules[name] = None
from bevflow_services.cli import main
sys.exit(main(sys.argv[2:]))
"""
# Every extra a site runs; train's torch is not installed here, and numpy's array checks import it
# when they find it in sys.modules.
EVERY_SITE_EXTRA = [module for module, extra in EXTRA_OF_MODULE.items() if extra != "train"]


def bevflow_without(missing: list[str], argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-c", WITHOUT, ",".join(missing), *argv], cwd=cwd,
                          capture_output=True, text=True, timeout=120)


# (modules taken away, the command line, the command the line names, the extra it names)
MISSING_EXTRAS = [
    (["zenoh"], ["serve", "gateway", "--site", "demo-hall"], "bevflow serve gateway", "services"),
    (["zenoh"], ["serve", "tracker", "--help"], "bevflow serve tracker", "services"),
    (["paho"], ["serve", "mqtt", "--site", "demo-hall"], "bevflow serve mqtt", "services"),
    (["viser"], ["serve", "gateway", "--site", "demo-hall", "--auth", "off", "--view3d-port", "8001"],
     "bevflow serve gateway", "view3d"),
    (["zenoh"], ["demo"], "bevflow demo", "services"),
    (["zenoh"], ["healthcheck", "tracker", "--site", "demo-hall"], "bevflow healthcheck", "services"),
    (["argon2"], ["users", "--db", "users.db", "list"], "bevflow users", "services"),
    (["psycopg"], ["users", "--db", "postgresql://bevflow@127.0.0.1:9/none", "list"], "bevflow users", "postgres"),
    (["torch"], ["train-detector", "export", "--checkpoint", "c.pt", "--out", "m.onnx"], "bevflow train-detector", "train"),
    (["onnxruntime"], ["evaluate", "--suite", "paper", "--detector", "--frames-scale", "0.01", "--jobs", "1"],
     "bevflow evaluate", "cpu"),
    (["onnxruntime"], ["demo"], "bevflow demo", "cpu"),
]


@pytest.mark.parametrize(("missing", "argv", "command", "extra"), MISSING_EXTRAS,
                         ids=[" ".join(argv[:2]) + f" without {missing[0]}" for missing, argv, *_ in MISSING_EXTRAS])
def test_a_missing_extra_is_one_line_naming_it(tmp_path: Path, missing: list[str], argv: list[str], command: str,
                                               extra: str) -> None:
    result = bevflow_without(missing, argv, tmp_path)
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == f"{command} {install_hint(extra)}\n"


@pytest.mark.parametrize(
    "argv",
    [
        ["--help"],
        ["serve", "--help"],
        ["evaluate", "--suite", "paper", "--frames-scale", "0.01", "--jobs", "1"],
    ],
)
def test_what_needs_no_extra_runs_without_them(tmp_path: Path, argv: list[str]) -> None:
    result = bevflow_without(EVERY_SITE_EXTRA, argv, tmp_path)
    assert result.returncode == 0, result.stderr
    assert "extra" not in result.stderr


def test_a_missing_module_of_no_extra_is_an_error_with_its_traceback(tmp_path: Path) -> None:
    # anyio comes with fastapi; missing, the installation is broken, which no extra mends.
    result = bevflow_without(["anyio"], ["serve", "gateway", "--site", "demo-hall"], tmp_path)
    assert result.returncode == 1
    assert "Traceback" in result.stderr and "ModuleNotFoundError" in result.stderr and "anyio" in result.stderr
    assert "pip install" not in result.stderr
