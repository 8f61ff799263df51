"""TLS and passwords on the bus, from the site file's ``bus:`` section, tested on loopback with a
throwaway certificate authority: a client with the right credentials receives messages through
a secured router; one with a wrong password, or that does not trust the router, does not."""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import textwrap
import threading
from pathlib import Path

import pytest

from bevflow import schemas
from bevflow.site import SiteError, parse_site
from bevflow_services import bus
from tests.services.router.test_main import Router
from tests.services.test_bus import free_port, wait_for

CAMERA = """
cameras:
  - {id: a, image_size: [10, 10], intrinsics: {fx: 1, fy: 1, cx: 5, cy: 5}, pose: {position: [0, 0, 3]}}
"""
PASSWORD = "correct horse battery staple"


def make_authority(folder: Path) -> dict[str, Path]:
    """A CA, and a certificate it signed for localhost/127.0.0.1, made with the openssl CLI."""
    openssl = shutil.which("openssl")
    if openssl is None:
        pytest.skip("the openssl command is not installed, and no other way to make a test certificate is")

    def run(*args: str) -> None:
        subprocess.run([openssl, *args], cwd=folder, check=True, capture_output=True)

    curve = ("-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes")
    run("req", "-x509", *curve, "-keyout", "ca.key", "-out", "ca.pem", "-days", "2", "-subj", "/CN=bevflow test CA")
    run("req", *curve, "-keyout", "key.pem", "-out", "host.csr", "-subj", "/CN=localhost")
    (folder / "san.cnf").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    run("x509", "-req", "-in", "host.csr", "-CA", "ca.pem", "-CAkey", "ca.key", "-CAcreateserial",
        "-out", "cert.pem", "-days", "2", "-extfile", "san.cnf")
    # A second authority that signed nothing of ours: trusting it must not be enough.
    run("req", "-x509", *curve, "-keyout", "other.key", "-out", "other-ca.pem", "-days", "2", "-subj", "/CN=other")
    return {name: folder / f"{name}.pem" for name in ("ca", "cert", "key", "other-ca")}


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("pki")
    files = make_authority(folder)
    (folder / "users").write_text(f"bevflow:{PASSWORD}\nviewer:other-secret\n")
    (folder / "password").write_text(PASSWORD + "\n")
    (folder / "wrong-password").write_text("guess\n")
    return {**files, "users": folder / "users", "password": folder / "password",
            "wrong-password": folder / "wrong-password"}


def site_file(folder: Path, bus_yaml: str, name: str = "site.yaml") -> Path:
    path = folder / name
    path.write_text(CAMERA + "bus:\n" + textwrap.indent(textwrap.dedent(bus_yaml).strip(), "  ") + "\n")
    return path


def client_site(folder: Path, pki: dict[str, Path], *, ca: str = "ca", password: str = "password") -> Path:
    return site_file(folder, f"""
        tls: {{root_ca: {pki[ca]}}}
        auth: {{user: bevflow, password_file: {pki[password]}}}
    """, name=f"client-{ca}-{password}.yaml")


# --- the site section ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("bus_yaml", "message"),
    [
        ("auth: {user: u, password: hunter2}", "never write the password in the site file"),
        ("auth: {user: u}", "exactly one of 'password_file' or 'password_env'"),
        ("auth: {user: u, password_file: a, password_env: B}", "exactly one of"),
        ("auth: {password_env: B}", "a password without a 'user'"),
        ("tls: {cert: c.pem}", "'cert' and 'key' together"),
        ("tls: {}", "give 'root_ca'"),
        ("tls: {root_ca: ca.pem, mutual: true}", "'mutual' needs"),
        ("tls: {root_ca: ca.pem, ca: x}", "bus.tls.ca: unknown field"),
    ],
)
def test_the_bus_section_refuses_mistakes(bus_yaml: str, message: str) -> None:
    with pytest.raises(SiteError, match=message):
        parse_site(CAMERA + "bus: {" + bus_yaml + "}")


def test_no_bus_section_means_an_open_bus(tmp_path: Path) -> None:
    path = tmp_path / "site.yaml"
    path.write_text(CAMERA)
    assert bus.site_security(path) is None and bus.site_security(None) is None


def test_the_site_section_reaches_zenoh(tmp_path: Path, pki: dict[str, Path]) -> None:
    path = site_file(tmp_path, f"""
        tls: {{root_ca: {pki['ca']}, cert: {pki['cert']}, key: {pki['key']}, mutual: true}}
        auth: {{user: bevflow, password_file: {pki['password']}, users_file: {pki['users']}}}
    """)
    security = bus.site_security(path)
    assert security is not None and security.password == PASSWORD  # the file's newline is not part of it
    assert PASSWORD not in repr(security)
    conf = bus.BusConfig(mode="client", connect=("tls/127.0.0.1:7447",), security=security).to_zenoh()
    expected = {
        "transport/link/tls/root_ca_certificate": str(pki["ca"]),
        "transport/link/tls/listen_certificate": str(pki["cert"]),
        "transport/link/tls/listen_private_key": str(pki["key"]),
        "transport/link/tls/connect_certificate": str(pki["cert"]),
        "transport/link/tls/connect_private_key": str(pki["key"]),
        "transport/link/tls/enable_mtls": True,
        "transport/auth/usrpwd/user": "bevflow",
        "transport/auth/usrpwd/password": PASSWORD,
        "transport/auth/usrpwd/dictionary_file": str(pki["users"]),
    }
    assert {key: json.loads(conf.get_json(key)) for key in expected} == expected


def test_the_password_can_come_from_the_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = site_file(tmp_path, "auth: {user: bevflow, password_env: BEVFLOW_TEST_BUS_PASSWORD}")
    monkeypatch.setenv("BEVFLOW_TEST_BUS_PASSWORD", "from-env")
    assert bus.site_security(path) == bus.Security(user="bevflow", password="from-env")
    monkeypatch.delenv("BEVFLOW_TEST_BUS_PASSWORD")
    with pytest.raises(bus.BusError, match="environment variable BEVFLOW_TEST_BUS_PASSWORD is not set"):
        bus.site_security(path)


@pytest.mark.parametrize(
    ("bus_yaml", "message"),
    [
        ("tls: {root_ca: /nonexistent/ca.pem}", r"bus.tls.root_ca: cannot read /nonexistent/ca.pem \(No such file"),
        ("auth: {user: u, password_file: /nonexistent/pw}", "bus.auth.password_file: cannot read /nonexistent/pw"),
        ("auth: {users_file: /nonexistent/users}", "bus.auth.users_file: cannot read"),
    ],
)
def test_missing_files_are_named(tmp_path: Path, bus_yaml: str, message: str) -> None:
    with pytest.raises(bus.BusError, match=message):
        bus.site_security(site_file(tmp_path, bus_yaml))


def test_an_empty_password_file_is_refused(tmp_path: Path) -> None:
    (tmp_path / "pw").write_text("\n")
    with pytest.raises(bus.BusError, match="is empty"):
        bus.site_security(site_file(tmp_path, f"auth: {{user: u, password_file: {tmp_path / 'pw'}}}"))


@pytest.mark.parametrize(
    ("endpoint", "allowed"),
    [
        ("tls/10.0.0.5:7447", True),
        ("quic/10.0.0.5:7447", True),
        ("tcp/127.0.0.1:7447", True),  # never leaves the host
        ("tcp/localhost:0", True),
        ("tcp/10.0.0.5:7447", False),
        ("tcp/0.0.0.0:7447", False),
        ("udp/192.168.1.2:7447", False),
    ],
)
def test_with_tls_only_encrypted_or_loopback_endpoints(pki: dict[str, Path], endpoint: str, allowed: bool) -> None:
    security = bus.Security(root_ca=pki["ca"])
    if allowed:
        bus.BusConfig(mode="client", connect=(endpoint,), security=security)
    else:
        with pytest.raises(bus.BusError, match=f"endpoint {endpoint} is not encrypted: use tls/"):
            bus.BusConfig(mode="client", connect=(endpoint,), security=security)


def test_config_from_args_reads_the_site(tmp_path: Path, pki: dict[str, Path]) -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--site")
    bus.add_bus_arguments(parser)
    args = parser.parse_args(["--site", str(client_site(tmp_path, pki)), "-m", "client", "-e", "tls/127.0.0.1:1"])
    cfg = bus.config_from_args(args)
    assert cfg.security == bus.Security(root_ca=pki["ca"], user="bevflow", password=PASSWORD)
    args.site = str(tmp_path / "missing.yaml")
    assert bus.config_from_args(args).security is None  # the service itself reports a site it cannot load
    args.site = str(site_file(tmp_path, "auth: {user: u, password_file: /nonexistent/pw}"))
    with pytest.raises(bus.BusError, match="password_file: cannot read /nonexistent/pw"):
        bus.config_from_args(args)


@pytest.mark.parametrize(
    ("site", "message"),
    [("missing.yaml", "missing.yaml: cannot read the site file"), ("bad.yaml", "bus.auth: never write the password")],
)
def test_the_router_reports_a_site_it_cannot_use(tmp_path: Path, site: str, message: str) -> None:
    from bevflow_services.cli.serve import run_service
    from bevflow_services.runtime import UserError

    site_file(tmp_path, "auth: {user: u, password: x}", name="bad.yaml")
    with pytest.raises(UserError, match=message):
        run_service("router", ["--site", str(tmp_path / site), "--listen", f"tcp/127.0.0.1:{free_port()}"])


# --- on loopback, through a secured router process ---------------------------------------------------
@pytest.fixture(scope="module")
def router(tmp_path_factory: pytest.TempPathFactory, pki: dict[str, Path]):
    """``bevflow serve router`` with TLS and a users file, from its site file."""
    folder = tmp_path_factory.mktemp("router")
    path = site_file(folder, f"""
        tls: {{cert: {pki['cert']}, key: {pki['key']}}}
        auth: {{users_file: {pki['users']}}}
    """)
    endpoint = f"tls/127.0.0.1:{free_port()}"
    process = Router("--site", str(path), "--listen", endpoint)
    assert "listening on " + endpoint in process.next_line(), process.output()
    yield endpoint
    process.stop()


def client_session(site: Path, endpoint: str):
    return bus.open_session(bus.BusConfig(mode="client", connect=(endpoint,), security=bus.site_security(site)))


def test_a_client_with_the_right_credentials_receives_messages(tmp_path: Path, pki, router: str) -> None:
    site = client_site(tmp_path, pki)
    publisher, subscriber = client_session(site, router), client_session(site, router)
    try:
        received: list[schemas.Occupancy] = []
        got = threading.Event()
        key = "bevflow/secure/occupancy"
        on_message = lambda m: (received.append(m), got.set())  # noqa: E731
        with bus.subscribe(subscriber, key, bus.JsonCodec(schemas.Occupancy), on_message), \
                bus.Publication(publisher, key, bus.JsonCodec(schemas.Occupancy)) as pub:
            message = schemas.Occupancy(site="secure", time_ns=1, total=3)
            assert wait_for(lambda: (pub.put(message), got.wait(0.1))[1])
        assert received[0] == message
    finally:
        publisher.close()
        subscriber.close()


@pytest.mark.parametrize(
    ("ca", "password", "why"),
    [
        ("ca", "wrong-password", "wrong password"),
        ("other-ca", "password", "router certificate not trusted"),
    ],
)
def test_a_client_without_the_right_credentials_cannot_join(tmp_path: Path, pki, router: str, ca: str, password: str,
                                                           why: str) -> None:
    with pytest.raises(bus.BusError, match="cannot join the bus"):
        client_session(client_site(tmp_path, pki, ca=ca, password=password), router).close()


def test_a_plain_client_cannot_join_a_tls_router(router: str) -> None:
    plain = "tcp/" + router.split("/", 1)[1]
    with pytest.raises(bus.BusError, match="cannot join the bus"):
        bus.open_session(bus.BusConfig(mode="client", connect=(plain,))).close()
