"""``talus rt serve`` composed with what the RT process offers (``talus.composition``)."""
from __future__ import annotations

import argparse

from rt.service_cli import register_serve


def register(commands: argparse._SubParsersAction) -> None:
    from talus.composition import rt_extensions

    register_serve(commands, extensions=rt_extensions)
