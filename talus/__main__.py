"""``python -m talus ...``: the same as the ``talus`` command (used to start an embedded RT
process with the interpreter that runs the client)."""
import sys

from talus.cli import main

sys.exit(main())
