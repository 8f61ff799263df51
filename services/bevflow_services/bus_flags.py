"""The command-line flags of the message bus, apart from ``bus`` so that a command can offer them
without importing Zenoh (the 'services' extra) until it runs. ``bus.config_from_args`` reads them.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_bus_arguments(parser: argparse.ArgumentParser, *, mode: bool = True) -> None:
    """The command-line flags every service shares (as in the zenoh examples)."""
    group = parser.add_argument_group("message bus (Zenoh)")
    if mode:
        group.add_argument("-m", "--mode", choices=("peer", "client"), default="peer",
                           help="peer: talk to other processes directly; client: go through a router (default: peer)")
    group.add_argument("-e", "--connect", action="append", default=[], metavar="ENDPOINT",
                       help="endpoint to connect to, e.g. tcp/192.168.1.10:7447 (repeatable)")
    group.add_argument("-l", "--listen", action="append", default=[], metavar="ENDPOINT",
                       help="endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable)")
    group.add_argument("--multicast-scouting", action=argparse.BooleanOptionalAction, default=False,
                       help="find other processes on the LAN by multicast (default: off; name endpoints instead)")
    group.add_argument("--shared-memory", action=argparse.BooleanOptionalAction, default=True,
                       help="pass large frames through shared memory between processes on one host (default: on)")
    group.add_argument("--zenoh-config", type=Path, default=None, metavar="FILE",
                       help="a Zenoh JSON5 config file (TLS, access control); "
                       "the settings above, defaults included, override it")
