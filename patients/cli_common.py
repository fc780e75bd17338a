"""What the clinical-record CLI groups share: --db/--user/--json, password input, output and
turning a ``TalusError`` into one line and exit code 2.

Passwords: never on the command line (it shows in ``ps`` and shell history). The acting user's
comes from $TALUS_PASSWORD or a prompt; a new password (users add/passwd) from
$TALUS_NEW_PASSWORD or a prompt typed twice.
"""
from __future__ import annotations

import argparse
import functools
import getpass
import json
import os
import sys
from collections.abc import Callable
from typing import Any

from rt.errors import TalusError

ENV_USER, ENV_PASSWORD, ENV_NEW_PASSWORD = "TALUS_USER", "TALUS_PASSWORD", "TALUS_NEW_PASSWORD"

Handler = Callable[[argparse.Namespace], int]


def add_common(p: argparse.ArgumentParser, user: bool = True) -> None:
    p.add_argument("--db", default=None,
                   help="database: a SQLite file path or URL (postgresql://USER@HOST/DB); "
                        "default $TALUS_DATABASE_URL, else talus.db in the user data directory")
    if user:
        p.add_argument("--user", default=os.environ.get(ENV_USER),
                       help=f"who you are (default ${ENV_USER}); the password is read from "
                            f"${ENV_PASSWORD} or asked")
    p.add_argument("--json", action="store_true", help="print JSON")


def command(func: Handler) -> Handler:
    """Run a handler; a TalusError becomes one line (JSON with --json) and exit code 2."""
    @functools.wraps(func)
    def run(args: argparse.Namespace) -> int:
        try:
            return func(args)
        except TalusError as exc:
            if getattr(args, "json", False):
                print(json.dumps({"error": str(exc)}))
            else:
                print(f"error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            print("interrupted: nothing more was done", file=sys.stderr)
            return 130
    return run


def password(prompt: str = "password: ") -> str:
    """The acting user's password: $TALUS_PASSWORD, else a prompt on the terminal."""
    env = os.environ.get(ENV_PASSWORD)
    if env:
        return env
    return _prompt(prompt, ENV_PASSWORD)


def new_password(username: str, env: str = ENV_NEW_PASSWORD) -> str:
    """A new password: ``$env``, else typed twice on the terminal."""
    value = os.environ.get(env)
    if value:
        return value
    first = _prompt(f"new password for {username}: ", env)
    if _prompt("again: ", env) != first:
        raise TalusError("the two passwords differ: nothing was changed")
    return first


def _prompt(text: str, env: str) -> str:
    if not sys.stdin.isatty():
        raise TalusError(f"no password: set ${env} or run in a terminal to be asked")
    return getpass.getpass(text)


def need_user(args: argparse.Namespace) -> str:
    if not args.user:
        raise TalusError(f"who are you? give --user NAME (or set ${ENV_USER})")
    return str(args.user)


def open_record(args: argparse.Namespace, create: bool = False) -> Any:
    from patients.service import ClinicalRecord
    return ClinicalRecord.open(args.db, create=create)


def login(record: Any, args: argparse.Namespace) -> Any:
    """Authenticate ``--user`` (password from $TALUS_PASSWORD or a prompt)."""
    user = need_user(args)
    return record.authenticate(user, password(f"password for {user}: "))


def emit(args: argparse.Namespace, value: Any, human: Callable[[Any], str] | str) -> None:
    """Print ``value`` as JSON with --json, else the human text."""
    if args.json:
        print(json.dumps(value, ensure_ascii=False, default=str))
    else:
        text = human if isinstance(human, str) else human(value)
        if text:
            print(text)


def table(rows: list[dict[str, Any]], columns: list[str]) -> str:
    """A plain aligned text table of ``columns`` (None shown as '-')."""
    if not rows:
        return "(none)"
    cells = [[("-" if r.get(c) is None else str(r.get(c))) for c in columns] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(columns)]
    line = lambda vals: "  ".join(v.ljust(w) for v, w in zip(vals, widths)).rstrip()  # noqa: E731
    return "\n".join([line(columns), line(["-" * w for w in widths]), *map(line, cells)])


def write_new_file(path: str, text: str, force: bool) -> None:
    """Write ``text`` to ``path`` via a temporary file; refuse an existing file unless force."""
    import tempfile
    from pathlib import Path
    target = Path(path)
    if target.exists() and not force:
        raise TalusError(f"{target} exists: choose another name, or --force to replace it")
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.chmod(tmp, 0o600)
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
