"""`bevflow serve`: dispatch to a service's main, its flags, and clear errors for missing ones.

The services are stand-ins written into a temporary package, so these tests do not depend on which
real services exist yet.
"""

from __future__ import annotations

import argparse
import sys
import textwrap

import pytest

from bevflow_services import bus
from bevflow_services.cli import serve
from bevflow_services.runtime import UserError

FAKE_TRACKER = '''
"""Track people (a stand-in)."""
from bevflow_services import bus
CALLS = []

def add_arguments(parser):
    parser.add_argument("--max-wait-ms", type=int, default=150)

def main(args):
    CALLS.append(args)
    if args.max_wait_ms < 0:
        raise bus.BusError("cannot join the bus (test)")
    return 7
'''


def _fake_tracker():
    from fakesvc.tracker import main
    return main


def _fake_detector():
    from fakesvc.detector import main
    return main


def _fake_projector():
    from fakesvc.projector import main
    return main


def _fake_ingest():
    from fakesvc.ingest import main
    return main


def _fake_gateway():
    from fakesvc.gateway import main  # the package has no gateway
    return main


FAKE_LOADERS = {"tracker": _fake_tracker, "detector": _fake_detector, "projector": _fake_projector,
                "ingest": _fake_ingest, "gateway": _fake_gateway}


@pytest.fixture
def package(tmp_path, monkeypatch):
    """Loaders for a package ``fakesvc`` with a working tracker, a detector that needs a missing
    third-party package, a projector with a broken internal import, an ingest without ``main`` and
    no gateway."""
    root = tmp_path / "fakesvc"
    files = {
        "__init__.py": "",
        "tracker/__init__.py": "",
        "tracker/main.py": FAKE_TRACKER,
        "detector/__init__.py": "",
        "detector/main.py": "import not_a_real_package_for_bevflow_tests\ndef main(args): return 0\n",
        "projector/__init__.py": "",
        "projector/main.py": "import fakesvc.no_such_module\ndef main(args): return 0\n",
        "ingest/__init__.py": "",
        "ingest/main.py": "MAIN = None\n",
    }
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(textwrap.dedent(text))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield FAKE_LOADERS
    for name in [m for m in sys.modules if m == "fakesvc" or m.startswith("fakesvc.")]:
        del sys.modules[name]


def test_runs_the_service_with_common_and_own_flags(package):
    argv = ["--site", "sites/hall-a.yaml", "--max-wait-ms", "90", "-m", "client", "-e", "tcp/10.0.0.2:7447"]
    assert serve.run_service("tracker", argv, loaders=package, package="fakesvc") == 7
    args = sys.modules["fakesvc.tracker.main"].CALLS[-1]
    assert (args.site, args.site_id, args.max_wait_ms, args.service) == ("sites/hall-a.yaml", None, 90, "tracker")
    assert bus.config_from_args(args) == bus.BusConfig(mode="client", connect=("tcp/10.0.0.2:7447",))


def test_site_id_can_be_given(package):
    serve.run_service("tracker", ["--site", "demo", "--site-id", "terminal-2"], loaders=package, package="fakesvc")
    assert sys.modules["fakesvc.tracker.main"].CALLS[-1].site_id == "terminal-2"


@pytest.mark.parametrize(
    "service, argv, error, message",
    [
        ("gateway", ["--site", "x"], UserError, "^service gateway is not available in this build$"),
        ("ingest", ["--site", "x"], UserError, "service ingest is not available in this build"),
        # A missing package stays an error; `bevflow` names the extra when it is an optional one (test_main).
        ("detector", ["--site", "x"], ModuleNotFoundError, "not_a_real_package_for_bevflow_tests"),
        ("projector", ["--site", "x"], ModuleNotFoundError, "fakesvc.no_such_module"),
        ("tracker", ["--site", "x", "--max-wait-ms", "-1"], UserError, "cannot join the bus"),
        ("tracker", ["--site", "x", "-m", "client"], UserError, "client mode needs"),
    ],
)
def test_errors(package, service, argv, error, message):
    with pytest.raises(error, match=message):
        serve.run_service(service, argv, loaders=package, package="fakesvc")


@pytest.mark.parametrize(
    "argv",
    [
        [],  # --site is required
        ["--site", "x", "--site-id", "a/b"],
        ["--site", "x", "--mode", "router"],
        ["--site", "x", "--unknown-flag"],
    ],
)
def test_bad_command_lines_exit_with_usage(package, argv, capsys):
    with pytest.raises(SystemExit) as exit_info:
        serve.run_service("tracker", argv, loaders=package, package="fakesvc")
    assert exit_info.value.code == 2
    assert "usage: bevflow serve tracker" in capsys.readouterr().err


def test_registered_command_hands_the_rest_of_the_line_to_the_service():
    parser = argparse.ArgumentParser(prog="bevflow")
    serve.register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["serve", "ingest", "--site", "hall.yaml", "--help"])
    assert (args.service, args.service_args, args.func) == ("ingest", ["--site", "hall.yaml", "--help"], serve.handler)
    with pytest.raises(SystemExit):
        parser.parse_args(["serve", "toaster"])


def test_every_service_is_listed():
    assert list(serve.SERVICES) == ["router", "ingest", "detector", "projector", "tracker", "gateway", "recorder", "mqtt", "webhook"]


def test_every_service_has_a_loader_for_its_main_module():
    assert list(serve.LOADERS) == list(serve.SERVICES)
    for name in serve.SERVICES:
        assert serve.load_service(name).__name__ == f"bevflow_services.{name}.main"
