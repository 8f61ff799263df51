"""The systemd unit and its example option files: every service has one, every one parses with
bevflow's own command line, and systemd-analyze (when installed) finds nothing wrong in the unit."""

from __future__ import annotations

import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bevflow_services.cli.serve import SERVICES, load_service, parse_service_args, service_parser

ROOT = Path(__file__).resolve().parents[1]
UNIT = ROOT / "systemd" / "bevflow@.service"
ENV_FILES = sorted((ROOT / "systemd" / "env").glob("*.env"))


def service_args(env_file: Path) -> list[str]:
    lines = [line for line in env_file.read_text().splitlines() if line.startswith("BEVFLOW_ARGS=")]
    assert len(lines) == 1, f"{env_file.name}: one BEVFLOW_ARGS= line"
    return shlex.split(lines[0].removeprefix("BEVFLOW_ARGS="))


def test_every_service_has_an_example() -> None:
    assert {p.stem for p in ENV_FILES} == set(SERVICES)


@pytest.mark.parametrize("env_file", ENV_FILES, ids=lambda p: p.stem)
def test_example_options_parse(env_file: Path) -> None:
    name = env_file.stem
    parse_service_args(service_parser(name, load_service(name)), service_args(env_file))


def test_unit_runs_the_instance_with_its_options() -> None:
    unit = UNIT.read_text()
    assert "ExecStart=/opt/bevflow/venv/bin/bevflow serve %i $BEVFLOW_ARGS" in unit
    assert "EnvironmentFile=/etc/bevflow/%i.env" in unit and "StateDirectory=bevflow" in unit and "User=bevflow" in unit


def test_systemd_analyze_finds_nothing_wrong(tmp_path: Path) -> None:
    if shutil.which("systemd-analyze") is None:
        pytest.skip("systemd-analyze is not installed")
    bevflow = Path(sys.executable).with_name("bevflow")
    unit = UNIT.read_text().replace("/opt/bevflow/venv/bin/bevflow", str(bevflow))
    unit = unit.replace("/etc/bevflow/%i.env", str(tmp_path / "%i.env"))
    (tmp_path / "bevflow@.service").write_text(unit)
    shutil.copy(ROOT / "systemd" / "env" / "tracker.env", tmp_path)
    (tmp_path / "bevflow@tracker.service").symlink_to("bevflow@.service")
    done = subprocess.run(["systemd-analyze", "verify", "./bevflow@tracker.service"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=60)
    complaints = [line for line in (done.stdout + done.stderr).splitlines() if "bevflow@" in line]
    assert done.returncode == 0 and not complaints, done.stdout + done.stderr
