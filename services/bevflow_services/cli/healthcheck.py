"""``bevflow healthcheck SERVICE``: exit 0 when this host's SERVICE is up, 1 when it is not.

For container and service-manager health probes (compose.yaml's ``healthcheck``). What "up"
means differs by service:

- ``router``: its port accepts a TCP connection on this host;
- ``gateway``: it answers HTTP on ``--url`` (``/api/health``; 503, "the site is not ok", still
  means the gateway itself runs: restarting it would not bring a camera back);
- every other service: a process of this host (same host name) holds the service's liveliness
  token on the bus, which it does from start-up until it stops or dies.
"""

from __future__ import annotations

import argparse
import socket
import ssl
import sys
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any

from bevflow_services.bus_flags import add_bus_arguments
from bevflow_services.cli.environment import apply_environment
from bevflow_services.runtime import UserError, service_site

EPILOG = """what "up" means:
  router    its port (--port) accepts a TCP connection on this host
  gateway   it answers HTTP on --url with 200 or 503 (503: the site is not ok, but the gateway runs)
  others    a process on this host holds the service's liveliness token on the bus; give --site
            and the bus flags the service runs with (e.g. --mode client --connect tcp/router:7447)

examples:
  bevflow healthcheck router
  bevflow healthcheck gateway --url https://127.0.0.1:8000/api/health
  bevflow healthcheck tracker --site /config/site.yaml --mode client --connect tcp/router:7447
  bevflow healthcheck container     # in a container whose command is `bevflow serve ...`"""
BUS_SERVICES = ("ingest", "detector", "projector", "tracker", "recorder", "mqtt", "webhook")
# A gateway that answers at all is alive; 503 only says the site it watches is not ok.
ALIVE_HTTP_CODES = (200, 503)


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "healthcheck",
        help="exit 0 when a service on this host is up (for container health probes)",
        description="Exit 0 when SERVICE is up on this host, 1 when it is not (for container health probes).",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("service", choices=("router", "gateway", *BUS_SERVICES, "container"), metavar="SERVICE",
                        help="router, gateway, " + ", ".join(BUS_SERVICES) + ", or container: the service "
                        "this container runs, read with its options from process 1's command line")
    parser.add_argument("--timeout", type=float, default=5.0, metavar="S",
                        help="give up and report the service down after S seconds (default 5)")
    parser.add_argument("--port", type=int, default=7447, help="router: the port it listens on (default 7447)")
    parser.add_argument("--url", default="http://127.0.0.1:8000/api/health",
                        help="gateway: the health URL to ask (default http://127.0.0.1:8000/api/health)")
    parser.add_argument("--site", default=None,
                        help="bus services: the site file or built-in site name the service runs with")
    parser.add_argument("--any-host", action="store_true",
                        help="bus services: count an instance on any host, not only this one")
    add_bus_arguments(parser)
    parser.set_defaults(func=handler, parser=parser)


def handler(args: argparse.Namespace) -> int:
    if args.service == "container":
        args = args.parser.parse_args(probe_argv(pid1_command_line()) + ["--timeout", str(args.timeout)])
    if args.service == "router":
        up, why = router_up(args.port, args.timeout)
    elif args.service == "gateway":
        up, why = gateway_up(args.url, args.timeout)
    else:
        if args.site is None:
            raise UserError(f"healthcheck {args.service}: give --site, the site the service runs with")
        up, why = bus_service_up(args)
    print(f"{args.service}: {'up' if up else 'down'} ({why})", file=sys.stdout if up else sys.stderr)
    return 0 if up else 1


def router_up(port: int, timeout: float) -> tuple[bool, str]:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=timeout):
            return True, f"port {port} accepts connections"
    except OSError as exc:
        return False, f"port {port}: {exc.strerror or exc}"


def gateway_up(url: str, timeout: float) -> tuple[bool, str]:
    # The gateway's own certificate need not name 127.0.0.1: this only asks whether it answers.
    context = ssl.create_default_context()
    context.check_hostname = False
    context.verify_mode = ssl.CERT_NONE
    try:
        with urllib.request.urlopen(url, timeout=timeout, context=context) as response:
            code = response.status
    except urllib.error.HTTPError as exc:
        code = exc.code
    except (urllib.error.URLError, OSError) as exc:
        return False, f"{url}: {getattr(exc, 'reason', exc)}"
    return code in ALIVE_HTTP_CODES, f"{url} answered {code}"


def bus_service_up(args: argparse.Namespace) -> tuple[bool, str]:
    from bevflow_services import bus  # here: the router and gateway checks work without the 'services' extra

    _site, site_id = service_site(args)
    host = bus.default_instance_id().rsplit("-", 1)[0]
    wanted = args.service

    def mine(live: set[bus.LiveService]) -> bool:
        return any(s.service == wanted and (args.any_host or s.instance.rsplit("-", 1)[0] == host) for s in live)

    try:
        session = bus.open_session(bus.config_from_args(args))
    except bus.BusError as exc:
        return False, str(exc)
    try:
        services = bus.LiveServices(session, bus.Keys(site_id))
        try:
            up = services.wait_until(mine, args.timeout)
        finally:
            services.close()
    finally:
        session.close()
    where = "on the bus" if args.any_host else f"on host {host}"
    return up, f"{'a' if up else 'no'} live {wanted} of site {site_id!r} {where}"


def pid1_command_line() -> list[str]:
    try:
        raw = Path("/proc/1/cmdline").read_bytes()
    except OSError as exc:
        raise UserError(f"healthcheck container: cannot read process 1's command line ({exc.strerror})") from None
    return [part.decode(errors="replace") for part in raw.split(b"\0") if part]


def probe_argv(command: list[str]) -> list[str]:
    """The healthcheck arguments that check the service a ``bevflow serve SERVICE ...`` command
    line runs: the port it listens on, or the site and bus flags it joins the bus with."""
    if "serve" not in command[:-1]:
        raise UserError(f"healthcheck container: process 1 is not `bevflow serve SERVICE` ({' '.join(command)})")
    at = command.index("serve")
    service, rest = command[at + 1], command[at + 2:]
    seen = argparse.ArgumentParser(add_help=False, allow_abbrev=False)
    for names, settings in SERVE_FLAGS:
        seen.add_argument(*names, **settings)
    apply_environment(seen)  # the service read its BEVFLOW_* variables too; this runs with the same
    flags, _ = seen.parse_known_args(rest)
    if service == "router":
        port = flags.listen[0].rsplit(":", 1)[1] if flags.listen else "7447"
        return ["router", "--port", port]
    if service == "gateway":
        host = "127.0.0.1" if flags.host in WILDCARD_HOSTS else flags.host
        host = f"[{host}]" if ":" in host else host
        scheme = "https" if flags.tls_cert else "http"
        return ["gateway", "--url", f"{scheme}://{host}:{flags.port}/api/health"]
    argv = [service, "--mode", flags.mode] + (["--site", flags.site] if flags.site else [])
    argv += [f"--connect={endpoint}" for endpoint in flags.connect]
    return argv + ([f"--zenoh-config={flags.zenoh_config}"] if flags.zenoh_config else [])


# What probe_argv reads of a `bevflow serve` command line (the defaults are the services' own).
SERVE_FLAGS: list[tuple[tuple[str, ...], dict[str, Any]]] = [
    (("--site",), {}),
    (("-m", "--mode"), {"default": "peer"}),
    (("-e", "--connect"), {"action": "append", "default": []}),
    (("-l", "--listen"), {"action": "append", "default": []}),
    (("--zenoh-config",), {}),
    (("--host",), {"default": "127.0.0.1"}),
    (("--port",), {"default": "8000"}),
    (("--tls-cert",), {}),
]
WILDCARD_HOSTS = ("0.0.0.0", "::", "127.0.0.1", "localhost")
