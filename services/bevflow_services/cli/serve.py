"""``bevflow serve SERVICE``: run one of bevflow's services in this process.

Each service is a package ``bevflow_services.<service>`` whose ``main`` module has
``main(args) -> int`` and, optionally, ``add_arguments(parser)`` for its own flags. Every service
gets ``--site-id`` and the bus flags of :func:`bevflow_services.bus_flags.add_bus_arguments`; all
but the router also get a required ``--site``. A service's module is imported (by its loader in
``LOADERS``) only when it is started, so one service's heavy or missing dependencies never slow or
break the others. The bus (zenoh, of the 'services' extra) too is imported only when a service
starts, so that the other commands work without the extras. A missing optional dependency reaches
``bevflow``'s ``main`` as the ``ModuleNotFoundError`` naming it, which says which extra to install.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Callable, Mapping
from types import ModuleType

from bevflow_services import redact
from bevflow_services.bus_flags import add_bus_arguments
from bevflow_services.cli import environment
from bevflow_services.runtime import UserError

SERVICES: dict[str, str] = {
    "router": "route messages between hosts and client-mode services (a Zenoh router)",
    "ingest": "read cameras (streams, files, the simulator) and publish frames",
    "detector": "find people in frames and publish 2D boxes",
    "projector": "turn 2D boxes into world cylinders with each camera's calibration",
    "tracker": "fuse cameras, track people, publish tracks, occupancy and alerts",
    "gateway": "serve the REST API, websockets, the dashboard and the 3D view",
    "recorder": "write occupancy, alerts and trajectories to the history database",
    "mqtt": "publish alerts and occupancy to an MQTT broker, none lost while it is down",
    "webhook": "POST alerts to a URL, signed, retried until delivered",
}
PACKAGE = "bevflow_services"

Loader = Callable[[], ModuleType]


# One loader per service: a plain import, run only when that service starts.
def _router() -> ModuleType:
    from bevflow_services.router import main
    return main


def _ingest() -> ModuleType:
    from bevflow_services.ingest import main
    return main


def _detector() -> ModuleType:
    from bevflow_services.detector import main
    return main


def _projector() -> ModuleType:
    from bevflow_services.projector import main
    return main


def _tracker() -> ModuleType:
    from bevflow_services.tracker import main
    return main


def _gateway() -> ModuleType:
    from bevflow_services.gateway import main
    return main


def _recorder() -> ModuleType:
    from bevflow_services.recorder import main
    return main


def _mqtt() -> ModuleType:
    from bevflow_services.mqtt import main
    return main


def _webhook() -> ModuleType:
    from bevflow_services.webhook import main
    return main


LOADERS: dict[str, Loader] = {
    "router": _router,
    "ingest": _ingest,
    "detector": _detector,
    "projector": _projector,
    "tracker": _tracker,
    "gateway": _gateway,
    "recorder": _recorder,
    "mqtt": _mqtt,
    "webhook": _webhook,
}


def register(subparsers: argparse._SubParsersAction) -> None:
    epilog = "services:\n" + "\n".join(f"  {name:<10} {text}" for name, text in SERVICES.items())
    epilog += "\n\n`bevflow serve SERVICE --help` lists a service's own options."
    parser = subparsers.add_parser(
        "serve",
        help="run one service (router, ingest, detector, projector, tracker, gateway, recorder, mqtt, webhook)",
        description="Run one bevflow service in this process, until Ctrl-C or SIGTERM.",
        epilog=epilog,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("service", choices=list(SERVICES), metavar="SERVICE", help="which service to run (see below)")
    # The service's own parser reads the rest, so each service can add flags without this module
    # importing every service up front.
    parser.add_argument("service_args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    parser.set_defaults(func=handler)


def handler(args: argparse.Namespace) -> int:
    return run_service(args.service, args.service_args)


def run_service(name: str, argv: list[str], *, loaders: Mapping[str, Loader] | None = None,
                package: str = PACKAGE) -> int:
    """Parse ``argv`` with the service's parser and run its ``main``."""
    from bevflow_services import bus

    module = load_service(name, loaders=loaders, package=package)
    args = parse_service_args(service_parser(name, module), argv)
    logging.basicConfig(level=args.log_level.upper(), format=f"%(asctime)s {name} %(levelname)s %(name)s: %(message)s")
    redact.install()  # no password or token in any log line, whichever code logs it
    try:
        bus.config_from_args(args)  # bad bus flags fail here, before the service starts anything
        return int(module.main(args) or 0)
    except bus.BusError as exc:
        raise UserError(str(exc)) from None


def load_service(name: str, *, loaders: Mapping[str, Loader] | None = None, package: str = PACKAGE) -> ModuleType:
    """The service's ``main`` module, from its loader (``LOADERS`` unless given; ``package`` is
    where those loaders import from); ``UserError`` when this build lacks it, the
    ``ModuleNotFoundError`` itself when the module needs a package that is not installed."""
    module_name = f"{package}.{name}.main"
    loader = (LOADERS if loaders is None else loaders).get(name)
    if loader is None:
        raise UserError(f"service {name} is not available in this build")
    try:
        module = loader()
    except ModuleNotFoundError as exc:
        missing = exc.name or ""
        if module_name == missing or module_name.startswith(missing + "."):
            raise UserError(f"service {name} is not available in this build") from None
        raise
    if not callable(getattr(module, "main", None)):
        raise UserError(f"service {name} is not available in this build (its module has no main)")
    return module


def service_parser(name: str, module: ModuleType) -> argparse.ArgumentParser:
    """The command line of ``bevflow serve NAME``: common flags plus the service's own."""
    first_paragraph = (module.__doc__ or SERVICES.get(name, "")).strip().split("\n\n")[0]
    parser = argparse.ArgumentParser(prog=f"bevflow serve {name}", description=" ".join(first_paragraph.split()),
                                     epilog=environment.environment_help())
    is_router = name == "router"
    if not is_router:
        parser.add_argument("--site", required=True,
                            help="the site: a site file (YAML or JSON) or the name of a built-in site")
    parser.add_argument("--site-id", default=None,
                        help="announce the router among this site's live services" if is_router else
                        "the site's name on the bus, which all services of one site share "
                        "(default: the 'site' name in the site file)")
    parser.add_argument("--log-level", default="info", choices=["debug", "info", "warning", "error"],
                        help="how much the service logs (default info)")
    add_bus_arguments(parser, mode=not is_router)
    add_arguments = getattr(module, "add_arguments", None)
    if add_arguments is not None:
        add_arguments(parser)
    parser.set_defaults(service=name)
    environment.apply_environment(parser)
    return parser


def parse_service_args(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace:
    """Parse, and check that a given ``--site-id`` fits in a bus key."""
    from bevflow_services import bus

    args = parser.parse_args(argv)
    if args.site_id is not None:
        try:
            bus.Keys(args.site_id)
        except ValueError as exc:
            parser.error(f"--site-id: {exc}")
    return args
