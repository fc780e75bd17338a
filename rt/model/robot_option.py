"""The ``--robot FILE`` option every command that loads the robot model offers.

A lab replaces the packaged nominal description by its identified robot; every command that
simulates, benchmarks or drives that robot must then use the same file.
"""
from __future__ import annotations

import argparse

HELP = "robot description YAML (default: the packaged nominal twin)"


def add_robot_option(parser: argparse.ArgumentParser) -> None:
    """Add ``--robot FILE`` (default None: the packaged nominal description)."""
    parser.add_argument("--robot", default=None, metavar="FILE", help=HELP)
