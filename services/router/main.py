"""Run a Zenoh router, for deployments where services on several hosts meet through one address.

No ``zenohd`` binary is packaged for Python, and none is needed: a session opened in router mode
routes for every client-mode session that connects to it. Services then run with
``--mode client --connect tcp/ROUTER_HOST:7447``.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

from bevflow_services import bus
from bevflow_services.cli.serve import stop_on_signals

DEFAULT_LISTEN = "tcp/0.0.0.0:7447"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = f"Without --listen the router listens on {DEFAULT_LISTEN}."


def main(args: argparse.Namespace) -> int:
    """Route until SIGINT or SIGTERM. With ``args.site_id`` set, announce the router's liveliness
    in that site so the gateway lists it among the live services."""
    cfg = bus.config_from_args(args, mode="router")
    if not cfg.listen:
        cfg = replace(cfg, listen=(DEFAULT_LISTEN,))
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
