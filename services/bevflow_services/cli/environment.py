"""Every ``bevflow serve`` flag from an environment variable: ``--id-file`` from
``BEVFLOW_ID_FILE``, ``--connect`` from ``BEVFLOW_CONNECT`` (comma-separated for a flag that
repeats), ``--no-view3d`` from ``BEVFLOW_NO_VIEW3D=1``. The command line wins over the variable
(a repeated flag given there adds to the variable's list, as argparse appends to a default), and
a bad value is refused like a bad flag, naming the variable.

Containers and service managers set options this way, and secrets in URLs (``BEVFLOW_DB``) stay
out of the process list.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable, Mapping
from typing import Any

PREFIX = "BEVFLOW_"
TRUE, FALSE = ("1", "true", "yes", "on"), ("0", "false", "no", "off")


def variable_of(action: argparse.Action) -> str | None:
    """``BEVFLOW_<LONG FLAG>`` for an option, None for a positional argument or ``--help``."""
    flag = next((o for o in action.option_strings if o.startswith("--")), None)
    if flag is None or isinstance(action, argparse._HelpAction):
        return None
    return PREFIX + flag[2:].upper().replace("-", "_")


def apply_environment(parser: argparse.ArgumentParser, environ: Mapping[str, str] = os.environ) -> None:
    """Make each ``BEVFLOW_*`` variable that names a flag of ``parser`` that flag's default (a
    required flag so set is no longer required)."""
    for action in parser._actions:
        name = variable_of(action)
        if name is None or name not in environ:
            continue
        try:
            action.default = _value(action, environ[name])
        except (ValueError, TypeError) as exc:
            parser.error(f"{name}={environ[name]!r}: {exc}")
        action.required = False


def _value(action: argparse.Action, raw: str) -> Any:
    if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction, argparse.BooleanOptionalAction)):
        word = raw.strip().lower()
        if word not in TRUE + FALSE:
            raise ValueError(f"give one of {', '.join(TRUE + FALSE)}")
        given = word in TRUE
        if isinstance(action, argparse.BooleanOptionalAction):
            return given
        return action.const if given else action.default
    # A type given by its registered name (a str) is not used by bevflow's commands.
    convert: Callable[[str], Any] = action.type if callable(action.type) else str
    if isinstance(action, argparse._AppendAction):
        return [convert(part.strip()) for part in raw.split(",") if part.strip()]
    value = convert(raw)
    if action.choices is not None and value not in action.choices:
        raise ValueError(f"choose from {', '.join(map(str, action.choices))}")
    return value


def environment_help() -> str:
    return ("Every option can also come from an environment variable: BEVFLOW_ and the option's long "
            "name in capitals, '-' as '_' (--id-file: BEVFLOW_ID_FILE; repeated options comma-separated; "
            "switches 1 or 0). The command line wins, except that a repeated option given there adds to the variable's.")
