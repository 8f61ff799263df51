"""The ``bevflow`` command. Each subcommand lives in its own module with a ``register`` function."""

from __future__ import annotations

import argparse
import importlib
import os
import sys

# Our matrix products are small and many; OpenBLAS's thread pool made one of them 40x slower on a
# busy 2-core machine. Set before numpy is first imported (the subcommand modules import it).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

# Subcommand modules, in the order ``bevflow --help`` lists them.
COMMANDS = ["demo", "serve", "evaluate", "bench", "plan", "calibrate", "users", "train-detector", "healthcheck"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="bevflow",
        description="People-flow monitoring for large indoor spaces from ceiling fisheye cameras.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        importlib.import_module(f"bevflow_services.cli.{name.replace('-', '_')}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except UserError as exc:
        print(f"bevflow {args.command}: {exc}", file=sys.stderr)
        return 2


class UserError(Exception):
    """Something the user can fix (a bad path, file or option). Printed as one line, no traceback."""


if __name__ == "__main__":
    sys.exit(main())
