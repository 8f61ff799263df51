"""The ``bevflow`` command. Each subcommand lives in its own module with a ``register`` function."""

from __future__ import annotations

import argparse
import os
import sys

# Our matrix products are small and many; OpenBLAS's thread pool made one of them 40x slower on a
# busy 2-core machine. Set before numpy is first imported: the subcommand modules, and the runtime
# module that UserError comes from, import it, so they are imported inside the functions below.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def build_parser() -> argparse.ArgumentParser:
    from bevflow_services.cli import (
        bench,
        calibrate,
        demo,
        evaluate,
        healthcheck,
        plan,
        serve,
        train_detector,
        users,
    )

    parser = argparse.ArgumentParser(
        prog="bevflow",
        description="People-flow monitoring for large indoor spaces from ceiling fisheye cameras.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    # In the order ``bevflow --help`` lists them. Registering imports the core library only; what a
    # command needs from an extra it imports when run, so every --help and `bevflow evaluate` work
    # without the extras.
    for command in (demo, serve, evaluate, bench, plan, calibrate, users, train_detector, healthcheck):
        command.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    from bevflow_services import extras
    from bevflow_services.runtime import UserError

    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except UserError as exc:
        print(f"bevflow {args.command}: {exc}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:
        extra = extras.extra_for(exc)
        if extra is None:
            raise  # not an optional dependency: a bug, which its traceback helps find
        print(f"{command_name(args)} {extras.install_hint(extra)}", file=sys.stderr)
        return 2


def command_name(args: argparse.Namespace) -> str:
    """``bevflow serve gateway`` for a service, else ``bevflow COMMAND``."""
    service = [args.service] if args.command == "serve" else []
    return " ".join(["bevflow", args.command, *service])


if __name__ == "__main__":
    sys.exit(main())
