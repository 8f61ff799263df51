"""``bevflow users``: the gateway's users and API tokens, in the history database.

    bevflow users --db history.db add ana --role admin      # asks for the password twice
    bevflow users --db history.db list
    bevflow users --db history.db token wallscreen --label "lobby screen"
    bevflow users --db history.db remove ana

Passwords are read from the terminal (never from the command line, where other users and the
shell history would see them), or from standard input with ``--password-stdin`` for scripts.
"""

from __future__ import annotations

import argparse
import getpass
import sys
import time

from bevflow_services.runtime import UserError

ROLES = ("viewer", "operator", "admin")


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "users",
        help="add, list and remove the gateway's users; make API tokens",
        description="Manage who may use the gateway (`bevflow serve gateway --auth on`). Roles: viewer (dashboard, "
                    "read-only API), operator (also acknowledges alerts and traces people), admin (also calibration, "
                    "the site file and users).",
    )
    parser.add_argument("--db", required=True, metavar="URL",
                        help="the database the gateway keeps its users in (its --auth-db, else its --db)")
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    add = actions.add_parser("add", help="add a user (asks for the password)")
    add.add_argument("name")
    add.add_argument("--role", choices=ROLES, required=True)
    add.add_argument("--password-stdin", action="store_true", help="read the password from the first line of stdin")
    passwd = actions.add_parser("password", help="set a user's password (ends their dashboard sessions and API tokens)")
    passwd.add_argument("name")
    passwd.add_argument("--password-stdin", action="store_true", help="read the password from the first line of stdin")
    actions.add_parser("list", help="list users, their roles and their API tokens")
    remove = actions.add_parser("remove", help="remove a user, their sessions and API tokens")
    remove.add_argument("name")
    token = actions.add_parser("token", help="make an API token for a user (printed once)")
    token.add_argument("name")
    token.add_argument("--label", default="", help="what the token is for, shown by `list`")
    revoke = actions.add_parser("revoke", help="revoke an API token by its number (see `list`)")
    revoke.add_argument("token_id", type=int)
    parser.set_defaults(func=run)


def read_password(from_stdin: bool) -> str:
    """The new password: stdin's first line, or typed twice at the terminal."""
    if from_stdin:
        return sys.stdin.readline().rstrip("\n")
    if not sys.stdin.isatty():
        raise UserError("no terminal to type a password at: pipe it in with --password-stdin")
    first = getpass.getpass("Password: ")
    if getpass.getpass("Again: ") != first:
        raise UserError("the two passwords differ; nothing changed")
    return first


def run(args: argparse.Namespace) -> int:
    from bevflow_services.gateway.auth import Access, new_api_token
    from bevflow_services.gateway.password_policy import PasswordError
    from bevflow_services.storage import StorageError
    from bevflow_services.storage.access import AccessStore

    try:
        store = AccessStore.open(args.db)
    except StorageError as exc:
        raise UserError(f"--db: {exc}") from None
    access = Access(store)
    now = time.time_ns()
    try:
        if args.action == "add":
            user = store.add_user(args.name, args.role, access.hash_password(read_password(args.password_stdin), args.name), now)
            print(f"added {user.name} ({user.role})")
        elif args.action == "password":
            store.set_password(args.name, access.hash_password(read_password(args.password_stdin), args.name))
            print(f"password of {args.name} changed; their dashboard sessions and API tokens ended")
        elif args.action == "list":
            tokens = store.tokens()
            for user in store.users():
                mine = [t for t in tokens if t.user == user.name]
                labels = ", ".join(f"#{t.id} {t.label}".strip() for t in mine)
                print(f"{user.name:<24} {user.role:<9}" + (f" tokens: {labels}" if mine else ""))
            if not store.user_count():
                print("no users yet: add an admin with `bevflow users --db URL add NAME --role admin`")
        elif args.action == "remove":
            store.remove_user(args.name)
            print(f"removed {args.name}")
        elif args.action == "token":
            secret = new_api_token()
            token = store.add_token(secret, args.name, args.label, now)
            print(f"API token #{token.id} for {args.name} (shown only now; send it as 'Authorization: Bearer TOKEN', "
                  f"or ?token=TOKEN on websockets):", file=sys.stderr)
            print(secret)
        elif args.action == "revoke":
            store.revoke_token(args.token_id)
            print(f"revoked API token #{args.token_id}")
    except (ValueError, PasswordError) as exc:
        raise UserError(str(exc)) from None
    except KeyError as exc:
        raise UserError(str(exc.args[0]) if exc.args else "not found") from None
    finally:
        store.close()
    return 0
