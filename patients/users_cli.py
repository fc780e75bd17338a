"""``talus users``: the first admin, accounts, passwords (patients.service enforces roles)."""
from __future__ import annotations

import argparse

from patients.cli_common import (add_common, command, emit, login, need_user, new_password,
                                 open_record, password, table)
from patients.roles import Role


def register(commands: argparse._SubParsersAction) -> None:
    p = commands.add_parser("init", help="create the database if needed and its first admin "
                                         "(--user; password from $TALUS_PASSWORD or typed twice)")
    add_common(p)
    p.set_defaults(func=_init)

    p = commands.add_parser("add", help="add a user (admin); the new password from "
                                        "$TALUS_NEW_PASSWORD or typed twice")
    add_common(p)
    p.add_argument("name")
    p.add_argument("--role", required=True, choices=[r.value for r in Role])
    p.set_defaults(func=_add)

    p = commands.add_parser("passwd", help="change a password: your own (asks the current "
                                           "one), or anyone's as admin (also unlocks)")
    add_common(p)
    p.add_argument("name", nargs="?", help="whose (default: yours)")
    p.set_defaults(func=_passwd)

    p = commands.add_parser("list", help="users, roles, lock state (admin)")
    add_common(p)
    p.set_defaults(func=_list)

    for name, disabled in (("disable", True), ("enable", False)):
        p = commands.add_parser(name, help=f"{name} an account (admin); history is kept")
        add_common(p)
        p.add_argument("name")
        p.set_defaults(func=_disable, disabled=disabled)


@command
def _init(args: argparse.Namespace) -> int:
    from os import environ
    from patients.cli_common import ENV_PASSWORD
    user = need_user(args)
    secret = environ.get(ENV_PASSWORD) or new_password(user, ENV_PASSWORD)
    with open_record(args, create=True) as record:
        record.init_admin(user, secret)
        where = str(record.engine.url.render_as_string(hide_password=True))
    emit(args, {"database": where, "admin": user}, f"first admin {user!r} created in {where}")
    return 0


@command
def _add(args: argparse.Namespace) -> int:
    with open_record(args) as record:
        actor = login(record, args)
        user = record.add_user(actor, args.name, args.role, new_password(args.name))
    emit(args, user, f"user {args.name!r} ({args.role}) added")
    return 0


@command
def _passwd(args: argparse.Namespace) -> int:
    with open_record(args) as record:
        me = need_user(args)
        current = password(f"password for {me}: ")
        actor = record.authenticate(me, current)
        target = args.name or me
        record.set_password(actor, target, new_password(target),
                            old_password=current if target == me else None)
    emit(args, {"user": target, "changed": True}, f"password of {target!r} changed")
    return 0


@command
def _list(args: argparse.Namespace) -> int:
    with open_record(args) as record:
        users = record.list_users(login(record, args))
    emit(args, users, lambda u: table(u, ["username", "role", "disabled", "failed_logins",
                                          "locked_until", "created_at"]))
    return 0


@command
def _disable(args: argparse.Namespace) -> int:
    with open_record(args) as record:
        record.set_user_disabled(login(record, args), args.name, args.disabled)
    state = "disabled" if args.disabled else "enabled"
    emit(args, {"user": args.name, "disabled": args.disabled}, f"user {args.name!r} {state}")
    return 0
