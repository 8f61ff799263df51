"""Run a Zenoh router, for deployments where services on several hosts meet through one address.

No ``zenohd`` binary is packaged for Python, and none is needed: a session opened in router mode
routes for every client-mode session that connects to it. Services then run with
``--mode client --connect tcp/ROUTER_HOST:7447``.

With ``--site``, the router takes TLS and passwords from the site file's ``bus:`` section, like
the services of that site do, and listens on ``tls/0.0.0.0:7447`` by default.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

from bevflow_services import bus
from bevflow_services.runtime import stop_on_signals

DEFAULT_LISTEN = "tcp/0.0.0.0:7447"
DEFAULT_TLS_LISTEN = "tls/0.0.0.0:7447"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--site", default=None,
                        help="a site file (or built-in site name) whose 'bus:' section sets TLS and passwords")
    parser.epilog = (f"Without --listen the router listens on {DEFAULT_LISTEN}, "
                     f"or {DEFAULT_TLS_LISTEN} when the site sets bus.tls.")


def main(args: argparse.Namespace) -> int:
    """Route until SIGINT or SIGTERM. With ``args.site_id`` set, announce the router's liveliness
    in that site so the gateway lists it among the live services."""
    if getattr(args, "site", None) is not None:
        bus.site_security(args.site)  # the router has no other use for the site: report its errors here
    cfg = bus.config_from_args(args, mode="router")
    if not cfg.listen:
        secure = cfg.security is not None and cfg.security.tls
        cfg = replace(cfg, listen=(DEFAULT_TLS_LISTEN if secure else DEFAULT_LISTEN,))
    session = bus.open_session(cfg)
    try:
        with stop_on_signals() as stop:
            site_id = getattr(args, "site_id", None)
            token = bus.announce(session, bus.Keys(site_id), "router", str(session.zid())) if site_id else None
            print(f"bevflow router {session.zid()} listening on {', '.join(cfg.listen)}", flush=True)
            if cfg.connect:
                print(f"bevflow router linked to {', '.join(cfg.connect)}", flush=True)
            while not stop.wait(0.2):
                pass
            if token is not None:
                token.undeclare()
    finally:
        session.close()
    print("bevflow router stopped", flush=True)
    return 0
