"""compose.yaml and the Dockerfile, read and checked without a Docker engine: every file they
use exists, every command parses, every service has a health check, and only the gateway's
port is published."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from bevflow.site import load_site, load_site_or_builtin

from bevflow_services.cli import build_parser
from bevflow_services.cli.healthcheck import probe_argv
from bevflow_services.cli.serve import load_service, parse_service_args, service_parser

ROOT = Path(__file__).resolve().parents[1]
COMPOSE = yaml.safe_load((ROOT / "compose.yaml").read_text())
SITE_OVERRIDE = yaml.safe_load((ROOT / "docker" / "compose.site.yaml").read_text())
GPU_OVERRIDE = yaml.safe_load((ROOT / "docker" / "compose.gpu.yaml").read_text())
DOCKERFILE = (ROOT / "docker" / "Dockerfile").read_text()
SERVICES = sorted(COMPOSE["services"])
# The bus in plain text and the 3D view (no login) stay inside the compose network.
PRIVATE_PORTS = {7447, 8001}


def bind_sources(service: dict) -> list[str]:
    return [v.split(":")[0] for v in service.get("volumes", []) if v.startswith((".", "/"))]


def test_every_bevflow_service_runs() -> None:
    assert set(SERVICES) == {"router", "ingest", "detector", "projector", "tracker", "recorder", "gateway"}


@pytest.mark.parametrize("name", SERVICES)
def test_mounted_files_exist_in_the_repository(name: str) -> None:
    for source in bind_sources(COMPOSE["services"][name]):
        assert not source.startswith("/"), f"{name} mounts {source}, outside the repository"
        assert (ROOT / source).is_file(), f"{name} mounts {source}, which the repository does not have"


@pytest.mark.parametrize("name", SERVICES)
def test_command_parses(name: str) -> None:
    command = COMPOSE["services"][name]["command"]
    assert command[:2] == ["serve", name]
    parse_service_args(service_parser(name, load_service(name)), command[2:])


@pytest.mark.parametrize("name", SERVICES)
def test_health_check_parses_and_probes_the_service(name: str) -> None:
    test = COMPOSE["services"][name]["healthcheck"]["test"]
    assert test[:2] == ["CMD", "bevflow"]
    args = build_parser().parse_args(test[2:])
    assert args.command == "healthcheck"
    probe = build_parser().parse_args(["healthcheck", *probe_argv(["bevflow", *COMPOSE["services"][name]["command"]])])
    assert probe.service == name
    if name not in ("router", "gateway"):
        assert probe.site == "/config/site.yaml" and probe.connect == ["tcp/router:7447"]


def test_only_the_gateway_port_is_published() -> None:
    published = {name: s["ports"] for name, s in COMPOSE["services"].items() if s.get("ports")}
    assert list(published) == ["gateway"]
    for mapping in published["gateway"]:
        assert int(str(mapping).split(":")[-1]) not in PRIVATE_PORTS


def test_services_wait_for_a_healthy_router() -> None:
    for name in SERVICES:
        if name != "router":
            assert COMPOSE["services"][name]["depends_on"]["router"]["condition"] == "service_healthy"


def test_compose_site_is_the_demo_hall() -> None:
    assert load_site(ROOT / "docker" / "site.yaml") == load_site_or_builtin("demo-hall")


def test_site_override_replaces_the_site_of_every_service() -> None:
    assert set(SITE_OVERRIDE["services"]) == set(SERVICES)
    for name, service in SITE_OVERRIDE["services"].items():
        targets = [v.rsplit(":", 2)[-2] for v in service["volumes"]]
        assert targets == ["/config/site.yaml"], name
    ingest = SITE_OVERRIDE["services"]["ingest"]["command"]
    assert "--simulate" not in ingest
    parse_service_args(service_parser("ingest", load_service("ingest")), ingest[2:])


def test_gpu_override_builds_the_detector_its_own_image_on_the_gpu() -> None:
    assert set(GPU_OVERRIDE["services"]) == {"detector"}
    detector = GPU_OVERRIDE["services"]["detector"]
    assert detector["build"]["args"]["BEVFLOW_EXTRAS"] == "services,gpu"
    assert detector["build"]["dockerfile"] == COMPOSE["services"]["detector"]["build"]["dockerfile"]
    assert detector["image"] != COMPOSE["services"]["detector"]["image"]  # the CPU image stays as it is
    assert detector["deploy"]["resources"]["reservations"]["devices"] == [{"driver": "nvidia", "count": 1, "capabilities": ["gpu"]}]
    command = detector["command"]
    assert command[:2] == ["serve", "detector"] and command[2:8] == COMPOSE["services"]["detector"]["command"][2:8]
    args = parse_service_args(service_parser("detector", load_service("detector")), command[2:])
    assert args.providers == "cuda,cpu"


def test_dockerfile_copies_only_what_exists() -> None:
    for line in re.findall(r"^COPY (.+) \S+$", DOCKERFILE, flags=re.M):
        for source in line.split():
            assert (ROOT / source).exists(), f"the Dockerfile copies {source}, which the repository does not have"


def test_dockerfile_gives_the_data_folder_to_its_user_and_checks_health() -> None:
    user = DOCKERFILE.index("USER bevflow")
    assert re.search(r"chown bevflow:bevflow /data", DOCKERFILE[:user])
    assert DOCKERFILE.index('VOLUME ["/data"]') > user
    assert 'CMD ["bevflow", "healthcheck", "container"]' in DOCKERFILE
    assert "ARG BEVFLOW_EXTRAS=all\n" in DOCKERFILE  # every extra unless the build names others
    assert 'pip install -c constraints.txt ".[${BEVFLOW_EXTRAS}]"' in DOCKERFILE
