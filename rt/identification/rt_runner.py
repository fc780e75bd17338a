"""The client's side of ``talus identify run --backend rt``: the excitation and the validation
trajectory played by the RT process as ``identify_excitation`` programs and recorded there.

It takes control of the robot, heartbeats, and for each trajectory sends ``run
identify_excitation {excitation, duration_s, out, label}``, then waits for ``out`` to appear
(the RT process links it complete once the robot is back at rest). The recordings are the
user's files: ``--record-dir`` must not already hold them.
"""
from __future__ import annotations

import time
from pathlib import Path

from rt.errors import HardwareError, InputError
from rt.identification.excitation import FourierExcitation
from rt.identification.program import PROGRAM_NAME, ExcitationSpec
from rt.ipc.client import RtUnavailableError

#: Heartbeat period (s): well inside the RT process's heartbeat timeout.
HEARTBEAT_S = 0.05
#: Beyond the excitation's duration, how long the client waits for the recording (s).
WAIT_MARGIN_S = 90.0
POLL_S = 0.1


def record_on_rt(endpoint: str, trajectories: list[tuple[str, FourierExcitation, float]],
                 record_dir: Path, timeout_s: float = 5.0) -> list[Path]:
    """Play each (label, excitation, seconds) in turn on the RT process at ``endpoint``;
    returns the recordings (``record_dir/identification-<label>.mcap``)."""
    from rt.ipc.client import RtClient, default_client_id

    outs = [record_dir / f"identification-{label}.mcap" for label, _, _ in trajectories]
    for out in outs:
        if out.exists():
            raise InputError(f"{out} exists; choose another --record-dir (recordings are "
                             "never overwritten)")
    client = RtClient(endpoint, client_id=default_client_id("identify"), timeout_s=timeout_s)
    try:
        client.control_acquire("talus identify run")
    except RtUnavailableError:
        client.close()
        raise RtUnavailableError(f"no RT process answers at {endpoint}; start one with "
                                 "`talus rt serve` (on the twin) first") from None
    except BaseException:
        client.close()
        raise
    try:
        client.start_heartbeat(HEARTBEAT_S)
        for (label, exc, seconds), out in zip(trajectories, outs):
            started = client.run(PROGRAM_NAME, {
                "excitation": ExcitationSpec.of(exc).model_dump(), "duration_s": seconds,
                "out": str(out.resolve()), "label": label})
            deadline = time.monotonic() + float(started["duration_s"]) + WAIT_MARGIN_S
            while not out.exists():
                if time.monotonic() > deadline:
                    raise HardwareError(f"the RT process wrote no {label} recording within "
                                        f"{started['duration_s'] + WAIT_MARGIN_S:.0f} s")
                time.sleep(POLL_S)
            _wait_at_rest(client, label)
        return outs
    finally:
        client.stop_heartbeat()
        try:
            client.control_release()
        except (InputError, RtUnavailableError):
            pass        # still moving, not ours, or gone: control lapses with the heartbeat
        client.close()


def _wait_at_rest(client, label: str, timeout_s: float = 10.0) -> None:
    """The next program is refused while one still runs: wait until the RT process says the
    motion is over (the recording is committed only then, so this is short)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        st = client.status()
        if st.get("phase_name") not in ("approach", "play", "return"):
            return
        time.sleep(POLL_S)
    raise HardwareError(f"the robot did not come to rest after the {label} excitation")
