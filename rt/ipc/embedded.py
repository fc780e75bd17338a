"""An RT process for a client that found none: started on the twin as a child process,
stopped when the client is done (``talus session run`` and the GUI on a fresh machine)."""
from __future__ import annotations

import contextlib
import json
import signal
import subprocess
import sys
from collections.abc import Iterator

from rt.errors import HardwareError, TalusError

#: The command that serves an RT process (the entry point composes what it offers).
SERVE_COMMAND = [sys.executable, "-m", "talus", "rt", "serve"]
#: Longest wait for the child to bind and answer (s): loading the model and compiling the
#: kernels takes a few seconds on a cold machine.
START_TIMEOUT_S = 60.0
#: Heartbeat timeout of an embedded RT process running the twin as fast as possible (s).
FAST_HEARTBEAT_TIMEOUT_S = 1.0


def answers(endpoint: str, timeout_s: float) -> bool:
    """True when an RT process answers ``status`` at ``endpoint`` within ``timeout_s``."""
    from rt.ipc.client import RtClient, default_client_id

    try:
        with RtClient(endpoint, client_id=default_client_id("probe"),
                      timeout_s=timeout_s) as client:
            client.status()
        return True
    except TalusError:
        return False


@contextlib.contextmanager
def rt_process(endpoint: str, probe_timeout_s: float = 0.5, robot: str | None = None,
               fast: bool = False, recordings_dir: str | None = None,
               heartbeat_timeout_s: float | None = None) -> Iterator[str]:
    """Yield the endpoint of an RT process: the one at ``endpoint`` if it answers, else an
    embedded one on the twin (free loopback ports), stopped (SIGTERM) on exit.
    ``heartbeat_timeout_s`` widens the owner's heartbeat timeout of the embedded one (a demo
    on a loaded machine); None keeps the robot's (or the fast mode's) default."""
    if answers(endpoint, probe_timeout_s):
        yield endpoint
        return
    cmd = [*SERVE_COMMAND, "--backend", "sim", "--endpoint", "tcp://127.0.0.1:*",
           "--pub-endpoint", "tcp://127.0.0.1:*"]
    if robot:
        cmd += ["--robot", robot]
    if fast:
        # Back to back, the loop shares the GIL and the cores with everything else: the
        # owner's heartbeat (a test or demo client on the same machine) gets a wider timeout.
        cmd += ["--fast"]
        heartbeat_timeout_s = heartbeat_timeout_s or FAST_HEARTBEAT_TIMEOUT_S
    if heartbeat_timeout_s is not None:
        cmd += ["--heartbeat-timeout", str(heartbeat_timeout_s)]
    if recordings_dir:
        cmd += ["--recordings-dir", recordings_dir]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = _first_line(proc)
        try:
            serving = json.loads(line)["serving"]
        except (ValueError, KeyError, TypeError):
            err = proc.stderr.read() if proc.poll() is not None and proc.stderr else ""
            raise HardwareError(f"the embedded RT process did not start: "
                                f"{(line or err).strip()[-500:]}") from None
        yield serving["endpoint"]
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def _first_line(proc: subprocess.Popen) -> str:
    import selectors

    assert proc.stdout is not None
    sel = selectors.DefaultSelector()
    sel.register(proc.stdout, selectors.EVENT_READ)
    if not sel.select(START_TIMEOUT_S):
        raise HardwareError(f"the embedded RT process did not answer within {START_TIMEOUT_S} s")
    return proc.stdout.readline()
