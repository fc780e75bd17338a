"""Faults injected on the twin for what the robot cannot fix (issue 15), twin figures in fast
(simulated-time) mode, deterministic:

* ``pull_in_stop``: 700 kg land on the fault matrix's 200 N force hold on the strapped foot;
  the stops follow (``pulling`` soft, ``force_limit`` hard) and the brakes hold the foot pulled
  by ≈ 1.7 kN. The alarm is raised once, PULL_IN_STOP_S after the first stop (within that bound
  after the hard stop), stays in ``Supervisor.alarms()`` while the pull lasts and escalates
  nothing; at 565 kg the stop's compliant hold ends the pull within 0.3 s: never raised.
* ``contact_lost``: the foot goes away (twin fault ``contact_removed``) under the same hold;
  the force law chases upwards and the supervisor soft-stops on ``contact_lost`` before the
  slider-speed check would, the platform's rise bounded.

Each run's supervisor inputs are recorded and replayed through the compiled and the interpreted
supervisor: the same events bit for bit (``test_supervisor_compiled``'s replay)."""
from __future__ import annotations

import numpy as np
import pytest
from test_supervisor_compiled import ATTR, PORTS, _block, _event

from protocols.session_figures import _alarms
from rt.model import RobotModel
from rt.model.dynamics import Payload
from rt.position_loop import PositionLoop, build_protocol_loop, sim_devices
from rt.safety import supervisor_kernel as sk
from rt.safety.events import EventLog, Reaction
from rt.safety.fault_matrix import FORCE_HOLD_Z_M, ForceHold
from rt.safety.limits import PatientLimits, RobotLimits, effective
from rt.safety.supervisor import InterpretedSupervisor, Supervisor, supervisor_physics
from rt.twin.environment import patient_foot
from rt.twin.twin import SimClock, Twin

DT = 1e-3


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel.load()


def _hold(model: RobotModel) -> tuple[Twin, PositionLoop]:
    """The fault matrix's force hold: 200 N up on the strapped foot at the level pose, 3 s in."""
    clock = SimClock()
    twin = Twin(None, patient_foot(model.kin, FORCE_HOLD_Z_M, 0.0, 0.0), seed=0, clock=clock)
    twin.place(model.kin.ik(FORCE_HOLD_Z_M, 0.0, 0.0).q)
    pl = build_protocol_loop(sim_devices(twin, clock),
                             ForceHold(model.kin, FORCE_HOLD_Z_M, 200.0, 60.0, DT), model)
    pl.loop.run(seconds=3.0)
    assert [e.cause for e in pl.events.snapshot() if e.kind == "fault"] == []
    return twin, pl


def _run(pl: PositionLoop, twin: Twin, seconds: float) -> dict[str, np.ndarray]:
    """Run ``seconds`` cycle by cycle: the supervisor block's inputs, its force-control flag,
    the true sliders' mean and the true push, the alarms' count."""
    blk = pl.graph.component("supervisor")
    rows: dict[str, list] = {name: [] for name in (*PORTS, "state", "fc", "t", "dt", "h",
                                                   "push", "alarms", "speed")}
    t_last = pl.loop.stats().t
    for _ in range(round(seconds / DT)):
        pl.loop.run(cycles=1)
        t = pl.loop.stats().t
        for name in PORTS:
            rows[name].append(np.array(getattr(blk, ATTR.get(name, name)).data))
        rows["state"].append(blk.state_in.data.buf.copy())
        rows["fc"].append(pl.supervisor.force_control)
        rows["t"].append(t)
        rows["dt"].append(t - t_last)
        t_last = t
        rows["h"].append(float(twin.plant.q.mean()))
        rows["push"].append(-float(twin.plant.wrench_s[2]))
        rows["alarms"].append(len(pl.supervisor.alarms()))
        rows["speed"].append(float(np.abs(twin.plant.qd).max()))
    return {name: np.array(v) for name, v in rows.items()}


def _replay(model: RobotModel, rec: dict[str, np.ndarray]) -> list[list[tuple]]:
    """The recorded inputs through a compiled and an interpreted supervisor (fresh, with the
    loop's physics and limits); their events, each asserted equal cycle by cycle."""
    lim = effective(model.description.limits.stroke, RobotLimits(), PatientLimits())
    phys = supervisor_physics(model.description)
    sups = [cls(lim, DT, EventLog(), **phys) for cls in (Supervisor, InterpretedSupervisor)]
    blocks = [_block(sup, rec) for sup in sups]
    for k in range(len(rec["t"])):
        for sup, (blk, bufs) in zip(sups, blocks, strict=True):
            sup.force_control = bool(rec["fc"][k])
            for name in PORTS:
                bufs[name][:] = rec[name][k]
            bufs["state"].buf[:] = rec["state"][k]
            bufs["state"].buffer_filled()
            blk.update(float(rec["t"][k]), float(rec["dt"][k]))
        assert sups[0].reaction == sups[1].reaction, k
        assert sups[0].alarms() == sups[1].alarms(), k
        (bc, _), (bi, _) = blocks
        assert np.array_equal(bc.volts.data, bi.volts.data, equal_nan=True), k
    events = [[_event(e) for e in sup.log.snapshot()] for sup in sups]
    assert events[0] == events[1]
    return events


def test_a_pull_beyond_the_drives_raises_pull_in_stop_after_the_hard_stop(model) -> None:
    twin, pl = _hold(model)
    t0 = pl.loop.stats().t
    twin.plant.set_payload(Payload(700.0, (0.0, 0.0, 0.10)))
    rec = _run(pl, twin, 1.3)
    ev = [e for e in pl.events.snapshot() if e.t > t0]
    first_stop = next(e for e in ev if e.kind == "fault")
    hard = next(e for e in ev if e.kind == "fault" and e.reaction == Reaction.HARD_STOP)
    alarm = [e for e in ev if e.cause == "pull_in_stop"]
    assert first_stop.cause == "pulling" and hard.cause == "force_limit"
    assert len(alarm) == 1 and alarm[0].kind == "warn" and alarm[0].reaction == Reaction.WARN
    a = alarm[0]
    # Counted from the first cycle the stop is latched, 1 s of an uninterrupted pull: raised
    # PULL_IN_STOP_S after the first stop (+ one cycle: the latch), so within that bound after
    # the hard stop (twin: soft stop +54 ms, hard +139 ms, alarm +1055 ms after the landing).
    assert a.t - first_stop.t == pytest.approx(sk.PULL_IN_STOP_S + DT, abs=1.5 * DT)
    assert 0.0 < a.t - hard.t <= sk.PULL_IN_STOP_S
    assert a.values["since_t"] == pytest.approx(first_stop.t + DT, abs=1e-9)
    # The pull it names is the brakes' (true push −1.73 kN; the ATI within 20 N of it).
    assert -1800.0 < a.values["fz_n"] < -1600.0
    assert abs(a.values["fz_n"] - rec["push"][round((a.t - t0) / DT) - 1]) < 20.0
    # No escalation and nothing else after the hard stop but the alarm: the brakes hold.
    assert [e.cause for e in ev if e.t > hard.t + 0.02] == ["pull_in_stop"]
    assert pl.supervisor.reaction == Reaction.HARD_STOP
    # Kept in the RT status's alarms from the warning to the end (the pull persists).
    k_alarm = round((a.t - t0) / DT) - 1
    assert not rec["alarms"][:k_alarm].any() and rec["alarms"][k_alarm:].all()
    (now,) = pl.supervisor.alarms()
    assert now["cause"] == "pull_in_stop" and abs(now["fz_n"] - rec["push"][-1]) < 20.0
    # The session's summary carries it, still raised at the end.
    (summary,) = _alarms([e.as_dict() for e in ev])
    assert summary["ended_t"] is None and summary["fz_n"] == a.values["fz_n"]
    # Compiled = interpreted on this stream.
    events = _replay(model, rec)
    assert [e[2] for e in events[0] if e[2] == "pull_in_stop"] == ["pull_in_stop"]


def test_a_pull_the_hold_ends_raises_nothing(model) -> None:
    twin, pl = _hold(model)
    t0 = pl.loop.stats().t
    twin.plant.set_payload(Payload(565.0, (0.0, 0.0, 0.10)))
    rec = _run(pl, twin, 1.5)
    ev = [e for e in pl.events.snapshot() if e.t > t0]
    assert ev[0].cause != "pull_in_stop" and any(e.cause == "pulling" for e in ev)
    assert not any(e.cause == "pull_in_stop" for e in ev) and not rec["alarms"].any()
    assert rec["push"][-500:].min() > -5.0              # the compliant hold ended the pull
    assert not any(e[2] == "pull_in_stop" for e in _replay(model, rec)[0])


def test_the_foot_going_away_under_force_control_stops_on_contact_lost(model) -> None:
    twin, pl = _hold(model)
    t0 = pl.loop.stats().t
    h0 = float(twin.plant.q.mean())
    twin.faults.schedule("contact_removed", twin.plant.t)
    rec = _run(pl, twin, 0.5)
    stops = [e for e in pl.events.snapshot() if e.t > t0 and e.kind == "fault"]
    assert stops[0].cause == "contact_lost" and stops[0].reaction == Reaction.SOFT_STOP
    # Twin: the chase is 1 mm above the last loaded height 17 ms after the removal; the
    # slider-speed soft stop (0.2 m/s), the only net before, came at 23 ms with 4.1 mm.
    latency = stops[0].t - t0
    assert latency <= 0.020, latency
    assert not any(e.cause.startswith("speed_") for e in stops)
    assert stops[0].values["rise_m"] > sk.CONTACT_LOST_RISE_M
    # The rise of the true sliders above where they stood when the foot went (its 2 mm of
    # heel pad released included): bounded (twin 2.3 mm), and the platform brought to rest.
    rise = rec["h"].max() - h0
    assert 0.001 < rise < 0.003, rise
    assert rec["speed"].max() < 0.2 and rec["speed"][-100:].max() < 1e-3
    assert pl.supervisor.reaction == Reaction.SOFT_STOP
    events = _replay(model, rec)
    assert next(e[2] for e in events[0] if e[1] == "fault") == "contact_lost"


def test_an_offset_sensor_after_the_lost_contact_neither_raises_the_hold_nor_alarms(model
                                                                                   ) -> None:
    """The foot goes away and the force sensor has drifted since its tare: the empty platform
    reads a 3 N pull (twin drift bound ±4 N). The stop's compliant hold must not take that for
    the strap (it rose its whole 20 mm towards where the foot had been, and ``pull_in_stop``
    told the staff to release a strap pulling nothing: ``sequencer_kernel.YIELD_START_PULL_N``,
    ``PULL_IN_STOP_FZ_N``)."""
    twin, pl = _hold(model)
    h0 = float(twin.plant.q.mean())
    # The push (−Fz) reads −3 N with nothing on it.
    pl.graph.component("force").tare.offset[2] -= 3.0
    twin.faults.schedule("contact_removed", twin.plant.t)
    rec = _run(pl, twin, 2.5)
    stops = [e.cause for e in pl.events.snapshot() if e.kind == "fault"]
    assert stops == ["contact_lost"]
    # The empty platform really reads the offset's pull throughout the hold.
    push = -np.array([w[2] for w in rec["wrench"]])
    assert -4.5 < float(np.median(push[-1000:])) < -1.5
    # Where the offset-free run rests (twin: 2.3 mm above, the chase before the stop).
    assert rec["h"].max() - h0 < 0.003
    assert rec["alarms"].max() == 0 and pl.supervisor.alarms() == []


def test_the_recording_and_the_session_report_carry_the_alarm(tmp_path) -> None:
    """The alarm's events, recorded as the RT process records every safety event
    (``/safety/events``), reach the session's figures (``alarms``: raised, the pull, how it
    ended) and its report (a table the staff's action is named in)."""
    from test_reports import clock, pdftext

    from reports.session_data import session_input_from_recording
    from reports.session_report import render_session_report
    from rt.recording.writer import SessionRecorder

    path = tmp_path / "pulled.mcap"
    rec = SessionRecorder(path, {"protocol_name": "Hold", "protocol_version": "1",
                                 "parameters": {"kind": "sine_fz"}, "patient_id": "P-0007",
                                 "robot_description": "nominal"})
    for k in range(1500):
        t = k * 1e-3
        rec.publish("/robot/state", {"t": t, "q": [0.2] * 3, "qd": [0.0] * 3,
                                     "q_ref": [0.2] * 3, "tau": [100.0] * 3, "volts": [0.0] * 3})
        rec.wrench(t, 0.0, 0.0, -200.0 if k < 200 else 1733.0, 0.0, 0.0, 0.0)
        rec.reference(t, [0.0, 0.0, 200.0], phase="play")
        if k % 500 == 0:
            import time
            time.sleep(0.05)     # let the writer thread drain its bounded queue
    for e in ({"t": 0.139, "kind": "fault", "cause": "force_limit", "reaction": "hard_stop",
               "message": "platform force beyond the limit", "values": {"force_n": 812.0},
               "id": 1},
              {"t": 1.055, "kind": "warn", "cause": "pull_in_stop", "reaction": "warn",
               "message": "the foot is still pulled (-1733 N) 1.0 s into the stop: ...",
               "values": {"fz_n": -1733.0, "since_t": 0.055, "for_s": 1.0}, "id": 2},
              {"t": 1.4, "kind": "alarm_end", "cause": "pull_in_stop", "reaction": "none",
               "message": "the pull in the stop has ended",
               "values": {"how": "pull_ended", "fz_n": 3.0, "since_t": 0.055,
                          "lasted_s": 1.345}, "id": 3}):
        rec.event(e)
    assert rec.close()["dropped_total"] == 0
    inp = session_input_from_recording(path)
    assert inp.figures is not None
    assert inp.figures["alarms"] == [{"t": 1.055, "cause": "pull_in_stop", "fz_n": -1733.0,
                                      "message": "the foot is still pulled (-1733 N) 1.0 s "
                                                 "into the stop: ...",
                                      "ended_t": 1.4, "how": "pull_ended"}]
    assert [s["cause"] for s in inp.figures["stops"]] == ["force_limit"]   # not a stop
    pdf = tmp_path / "pulled.pdf"
    render_session_report(inp, pdf, clock=clock)
    text = " ".join(pdftext(pdf).split())
    assert "Alarms to the staff" in text and "1733 N" in text and "ended at 1.400 s" in text
    assert "release the strap" in text


@pytest.mark.parametrize("name", ["gait_replay.yaml", "sine_fz.yaml"])
def test_legitimate_force_sessions_neither_stop_nor_alarm(tmp_path, name) -> None:
    """The library's force sessions on the twin (the gait replay's 1 s unloaded rests between
    stances at F_d = 0, the sine's 200-400 N): completed, no stop, no alarm, and far from
    ``contact_lost``: the sliders' mean never stood more than 0.05 mm above where the contact
    was last held while reading ≤ CONTACT_HELD_N (twin: 0.000 and 0.007 mm; the threshold is
    1 mm). The rule replayed offline on the session's recording."""
    from protocols.library import LIBRARY_DIR
    from protocols.session import SessionSetup, run_session
    from rt.recording.reader import read_recording

    record = tmp_path / "s.mcap"
    s = run_session(SessionSetup(LIBRARY_DIR / name, patient_weight_kg=70.0), record)
    assert s["completed"] and s["stops"] == [] and s["alarms"] == [], (s["stops"], s["alarms"])
    r = read_recording(record)
    touch, worst, loaded, unloaded = np.nan, 0.0, 0, 0
    for st, w, ref in zip(r["/robot/state"], r["/robot/wrench"], r["/protocol/reference"],
                          strict=False):
        if ref.get("mode") != "force":
            touch = np.nan
            continue
        push = -w["fz"]
        h = sum(st["q"]) / 3.0
        if push > sk.CONTACT_HELD_N:
            touch, loaded = h, loaded + 1
        elif np.isfinite(touch):
            worst, unloaded = max(worst, h - touch), unloaded + 1
    assert loaded > 1000, loaded                       # force control, in contact
    if name == "gait_replay.yaml":
        assert unloaded > 1000, unloaded               # the rests were judged
    assert worst < 5e-5, worst


def test_the_session_cli_prints_the_alarm(capsys) -> None:
    """``talus session run`` prints a session's staff alarms with the stops."""
    from protocols.session_client import print_summary

    summary = {"protocol": "Hold", "kind": "sine_fz", "outcome": "stopped", "rt": None,
               "rms_error_pct": None, "peak_force_n": 812.0, "rom_deg": {}, "stops": [],
               "preflight": {"peak_actuator_force_n": 1500.0, "peak_slider_speed_m_s": 0.05},
               "alarms": [{"t": 1.055, "cause": "pull_in_stop", "fz_n": -1733.0,
                           "message": "the foot is still pulled (-1733 N)", "ended_t": None,
                           "how": None},
                          {"t": 9.0, "cause": "pull_in_stop", "fz_n": -400.0,
                           "message": "the foot is still pulled (-400 N)", "ended_t": 9.8,
                           "how": "pull_ended"}]}
    print_summary(summary)
    lines = [x for x in capsys.readouterr().out.splitlines() if "ALARM" in x]
    assert lines == [
        ("  ALARM             t=1.055 s pull_in_stop: the foot is still pulled (-1733 N); "
         "still raised at the end"),
        ("  ALARM             t=9.0 s pull_in_stop: the foot is still pulled (-400 N); "
         "ended t=9.8 s (pull_ended)")]
