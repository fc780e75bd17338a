"""The ankle's live state in the RT process's telemetry (issue 17), for the GUI's Run page: the
last ``/ankle/state`` message rides on every telemetry sample of a session with an ankle
setup, and the GUI's Qt-free telemetry ring decodes it into SI columns. End to end: an
ankle-torque hold played by the RT process on its twin."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from test_rt_process import start_rt, stop_rt

from app.telemetry import TelemetryRing
from rt.ipc.client import RtClient, Subscriber
from rt.model import RobotModel
from rt.model.ankle import AnkleMonitor, AnkleSetup

SETUP = AnkleSetup(side="right", height_above_sole_m=0.07, offset_x_m=0.01)


def test_the_monitor_keeps_its_last_message_for_live_views() -> None:
    model = RobotModel.load()
    mon = AnkleMonitor(model.kin, SETUP, (0.63, 0.0, 0.0))
    assert mon.last is None
    q = model.kin.ik(0.63, 0.0, 0.0).q
    first = mon.message(0.0, q, [0.0, 0.0, 20.0, 0.0, 1.5, 0.0])
    # Hand statics: my about the ankle = 1.5 - (rz fx - rx fz) = 1.5 + 0.01 m · 20 N.
    assert mon.last is first and first["plantarflexion_torque_nm"] == pytest.approx(1.7)
    # No finite wrench: no message, and the last one stays.
    assert mon.message(0.02, q, [math.nan] * 6) is None and mon.last is first


def test_the_ring_decodes_the_ankle_in_si_and_nan_without_it() -> None:
    ring = TelemetryRing(4)
    ring.push({"t": 1.0, "pose": [0.63, 0.0, 0.1]})
    ring.push({"t": 1.1, "pose": [0.63, 0.0, 0.1], "ankle": {
        "plantarflexion_deg": -8.0, "inversion_deg": 2.0, "plantarflexion_torque_nm": 6.0,
        "inversion_torque_nm": -1.0, "centre_displacement_mm": [3.0, -4.0, 0.0]}})
    ring.push({"t": 1.2, "ankle": {"plantarflexion_deg": "bad", "centre_displacement_mm": 1}})
    _, cols = ring.snapshot()
    assert np.isnan(cols["ankle_dfpf"][0])
    assert cols["ankle_dfpf"][1] == pytest.approx(math.radians(-8.0))
    assert cols["ankle_inev"][1] == pytest.approx(math.radians(2.0))
    assert cols["ankle_torque_dfpf"][1] == 6.0
    assert cols["ankle_torque_inev"][1] == -1.0
    assert cols["ankle_displacement"][1] == pytest.approx(0.005)
    assert np.isnan(cols["ankle_dfpf"][2])
    assert cols["ankle_displacement"][2] == pytest.approx(0.001)   # a size is taken as is


HOLD = {"schema_version": 1, "kind": "isometric_hold", "name": "plantarflexion 5 N m",
        "pose": {"z_m": 0.63},
        "holds": [{"roll_deg": 0.0, "pitch_deg": 0.0, "hold_s": 2.0, "rest_s": 0.2,
                   "torque": {"direction": "plantarflexion", "target_nm": 5.0}}]}


def test_an_ankle_torque_hold_in_the_rt_process_streams_the_ankle_live(tmp_path) -> None:
    proc, endpoint, pub = start_rt("--fast", "--heartbeat-timeout", "1.0", "--recordings-dir",
                                   str(tmp_path / "recordings"))
    sub = Subscriber(pub, ["telemetry"])
    try:
        with RtClient(endpoint, timeout_s=2.0) as client:
            client.control_acquire("test")
            client.start_heartbeat(0.05)
            started = client.session_start(HOLD, {"id": "P-017", "weight_kg": 70.0,
                                                  "ankle": SETUP.model_dump()})
            sid = started["session_id"]
            assert started["preflight"]["ankle_torque_holds"][0]["target_nm"] == 5.0
            live: list[dict] = []
            targets: list[dict] = []
            end = time.monotonic() + 120.0
            summary = None
            while time.monotonic() < end:
                # Read telemetry as fast as it comes (60 Hz), asking for the status twice a
                # second: a slower reader falls behind the publisher's queue.
                poll = time.monotonic() + 0.5
                while time.monotonic() < poll:
                    msg = sub.recv(0.05)
                    if msg is not None and msg.get("session") == sid and msg.get("ankle"):
                        live.append(msg["ankle"])
                        if msg.get("ankle_target"):
                            targets.append(msg["ankle_target"])
                st = client.session_status()
                if st["session"] != sid:
                    summary = st["last_summary"]
                    break
    finally:
        sub.close()
        stop_rt(proc)
    assert summary is not None and summary["completed"], summary
    # Live: the clinical state of the last /ankle/state message during the session; at the
    # hold, the foot dorsiflexed until the twin's passive ankle gives 5 N m.
    assert len(live) > 5
    assert {"plantarflexion_deg", "inversion_deg", "plantarflexion_torque_nm",
            "inversion_torque_nm", "centre_displacement_mm"} <= set(live[-1])
    assert max(m["plantarflexion_torque_nm"] for m in live) == pytest.approx(5.0, abs=1.0)
    assert min(m["plantarflexion_deg"] for m in live) < -3.0
    # The hold's target rides along while it is regulated, ramps included.
    assert targets and all(t["direction"] == "plantarflexion" and t["target_nm"] == 5.0
                           and 0.0 <= t["now_nm"] <= 5.0 for t in targets)
    assert max(t["now_nm"] for t in targets) == 5.0
    # The RT process regulated the torque about the ankle centre to the target.
    (h,) = summary["ankle"]["torque_holds"]
    assert h["reported_mean_nm"] == pytest.approx(5.0, abs=0.4)
