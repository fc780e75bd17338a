"""``talus gui``: the clinician GUI. When no RT process answers at the configured endpoint it
starts an embedded one on the twin, so a fresh machine shows a working robot.

``talus gui --screenshot DIR`` renders every page into PNGs (the docs and tests use them): with
a demo patient and a demo session run on the twin, then exits.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from rt.errors import TalusError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("start", help="open the clinician GUI (the default command)")
    _options(p)
    p.set_defaults(func=run)


def _options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--settings", type=Path, default=None,
                   help="settings file (default $XDG_CONFIG_HOME/talus/gui.json)")
    p.add_argument("--endpoint", default=None, help="RT process endpoint (overrides settings)")
    p.add_argument("--recordings-dir", type=Path, default=None,
                   help="folder of session recordings (overrides settings)")
    p.add_argument("--lang", choices=("en", "es"), default=None,
                   help="language (overrides settings)")
    p.add_argument("--screenshot", type=Path, default=None, metavar="DIR",
                   help="render every page to DIR/<page>.png (demo patient and session), exit")
    p.add_argument("--force", action="store_true",
                   help="with --screenshot: overwrite PNGs already in DIR")


def run(args: argparse.Namespace) -> int:
    from app import settings as settings_io

    try:
        path = args.settings or settings_io.default_path()
        settings = settings_io.load(path)
        updates = {}
        if args.endpoint:
            updates["rt_endpoint"] = args.endpoint
        if args.recordings_dir:
            updates["recordings_dir"] = str(args.recordings_dir.resolve())
        if args.lang:
            updates["language"] = args.lang
        if updates:
            settings = settings.model_copy(update=updates)
            settings = settings_io.GuiSettings.model_validate(settings.model_dump())
        if args.screenshot is not None:
            from app.screenshots import render_all
            files = render_all(args.screenshot, settings, force=args.force)
            print(json.dumps({"screenshots": [str(f) for f in files]}))
            return 0
        from app.launch import run_gui
        return run_gui(settings, path)
    except TalusError as exc:
        print(f"talus gui: {exc}", file=sys.stderr)
        return 2
    except ValueError as exc:   # pydantic's ValidationError is a ValueError
        print(f"talus gui: bad setting: {exc}".splitlines()[0], file=sys.stderr)
        return 2

