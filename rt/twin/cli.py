"""``talus twin ...`` commands."""
from __future__ import annotations

import argparse


def register(commands: argparse._SubParsersAction) -> None:
    from rt.ati.cli import register_twin_commands

    register_twin_commands(commands)
