"""The compiled supervisor against its interpreted reference (issue 16).

A cycle stream of the supervisor block's inputs is recorded from the position loop on the twin,
then faults are spliced in — every cause the kernel checks, each held long enough to latch,
with stop requests, a lost heartbeat and reset tickets (refused while the cause persists,
taken once it is gone) — and the stream is replayed through a ``SupervisorBlock`` on the
compiled :class:`Supervisor` and one on the :class:`InterpretedSupervisor`. Both must log the
same events (kind, cause, reaction, message, values, time, id), latch the same causes, answer
the same tickets and write the same outputs (volts, enable, mode) every cycle: bit for bit.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from rt.components.safety_blocks import SupervisorBlock
from rt.model import RobotModel
from rt.model.dynamics import State
from rt.position_loop import build_sim_position_loop
from rt.safety import supervisor_kernel as sk
from rt.safety.events import EventLog, Reaction
from rt.safety.limits import PatientLimits, RobotLimits, effective
from rt.safety.supervisor import InterpretedSupervisor, Supervisor, supervisor_physics

DT = 1e-3
CYCLES = 5800
#: Inputs of the supervisor block: name → width.
PORTS = {"q": 3, "est_status": 1, "qd": 3, "qdd": 3, "fk_ok": 1, "q_ref": 3, "qd_ref": 3,
         "tau": 3, "wrench": 6, "wrench_flags": 2, "inputs": 2, "drive_failed": 1}
ATTR = {"inputs": "stops"}


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel.load()


@pytest.fixture(scope="module")
def recorded(model) -> dict[str, np.ndarray]:
    """The supervisor block's inputs per cycle, from the loop on the twin (fast mode)."""
    pl = build_sim_position_loop("paden_panja", duration_s=3.0, model=model)
    blk = pl.graph.component("supervisor")
    rows: dict[str, list] = {name: [] for name in PORTS}
    rows["state"] = []
    for _ in range(600):
        pl.loop.run(cycles=1)
        for name in PORTS:
            rows[name].append(np.array(getattr(blk, ATTR.get(name, name)).data))
        rows["state"].append(blk.state_in.data.buf.copy())
    pl.graph.stop()
    return {name: np.array(v) for name, v in rows.items()}


def _stream(recorded: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """CYCLES cycles: the recording played four times over, with every fault spliced in."""
    reps = -(-CYCLES // len(recorded["q"]))
    s = {name: np.concatenate([v] * reps)[:CYCLES].copy() for name, v in recorded.items()}
    lim = effective((0.0, 0.4), RobotLimits(), PatientLimits())
    q, q_ref, w = s["q"], s["q_ref"], s["wrench"]
    s["dt"] = np.full(CYCLES, DT)
    s["wrench"][:, :] = np.where(np.isnan(w), 0.0, w)
    s["wrench_flags"][:] = 0.0
    s["drive_failed"][:] = 0.0
    s["fk_ok"][:] = 1.0
    s["est_status"][:] = 0.0
    q_ref[:] = q                                     # no tracking error unless spliced
    s["qdd"][:] = np.clip(s["qdd"], -1.0, 1.0)
    s["qd"][:] = np.clip(s["qd"], -0.1, 0.1)
    s["tau"][:] = np.clip(s["tau"], -1500.0, 1500.0)
    st = s["state"]
    # Splices: (first cycle, last cycle) → a fault held over it.
    q_ref[100:130, 0] += 1.5 * lim.max_tracking_error_m          # tracking soft …
    q_ref[130:140, 0] += 4.0 * lim.max_tracking_error_m          # … escalating to hard
    q[200:210, 1] = 0.003                                        # stroke margin
    q_ref[200:210, 1] = 0.003
    q[210:215, 1] = 0.401                                        # beyond the stroke
    q_ref[210:215, 1] = 0.401
    s["qd"][300:310, 2] = 0.25                                   # slider speed
    s["qdd"][320:330, 0] = 6.0                                   # acceleration: warn
    s["tau"][340:345, 1] = 2100.0                                # actuator force: warn
    s["est_status"][400] = -3.0                                  # encoder jump
    s["fk_ok"][420:425] = 0.0                                    # FK failed
    st[500:530, 24:27] = 0.0                                     # still (rates 0) …
    st[500:520, 11] = lim.roll_max + 0.5 * lim.rom_tolerance     # … roll at its ROM end
    st[520:530, 11] = lim.roll_max + lim.rom_tolerance + 0.01    # beyond it
    st[540:550, 24:27] = (0.5, -0.5, 0.0)                        # tilting fast: roll …
    st[550:560, 24:27] = (0.5, 0.5, -1.0)                        # … and pitch rates
    st[560:570, 10] = lim.pitch_min - lim.rom_tolerance - 0.01   # pitch beyond its ROM
    w[600:610, 2] = -0.95 * lim.max_force_n                      # force reaching the limit
    w[610:615, 2] = -1.05 * lim.max_force_n                      # beyond it
    w[620:625, :] = math.nan                                     # implausible (force control)
    s["wrench_flags"][640:650, 0] = 1.0                          # stale
    s["wrench_flags"][660:670, 1] = 1.0                          # saturated
    w[700:760, 2] = 5.0                                          # pulling (force control)
    s["inputs"][800:805, 0] = 1.0                                # hardware e-stop
    s["inputs"][820:825, 1] = 1.0                                # hand-held stop
    s["drive_failed"][840:845] = 1.0                             # both DAC cards
    s["dt"][900:910] = 3.0 * DT                                  # deadline overruns
    # A frozen encoder: the count stands still under a command far from the carried force.
    q[1000:1200, 2] = q[1000, 2]
    s["tau"][1000:1200, 2] = np.linspace(0.0, 4000.0, 200)
    s["qd_ref"][1000:1200, 2] = 0.01
    # The force balance's inputs (issue 15): a contact's wrench rising and falling on a
    # moving platform (its share, the sensor-lag allowance, the contact hysteresis); a command
    # beyond the drives' limit (the balance takes the applied, saturated force: 6 V × 80 N/V
    # here); a braking (|q̈| large, then quasi-static again: the carried load's gate, m·q̈, its
    # slew) ending in a still count.
    w[1300:1400, 2] = -np.r_[np.linspace(0.0, 900.0, 50), np.linspace(900.0, 0.0, 50)]
    w[1300:1400, 0] = np.linspace(0.0, 80.0, 100)
    w[1300:1400, 4] = np.linspace(0.0, -12.0, 100)
    s["tau"][1400:1430, 0] = 1450.0
    s["tau"][1430:1460, 0] = -1450.0
    s["qdd"][1460:1490, 1] = np.linspace(-9.0, 0.0, 30)
    s["tau"][1460:1490, 1] = -1450.0
    q[1490:1560, 1] = q[1490, 1]
    # Sustained drive saturation (issue 15): axis 2's command beyond the drive's limit 3/4 of
    # each 36 ms (a 28 Hz limit cycle's duty, both signs) from cycle 1570 to 1970: more than
    # half of the 0.5 s window from ≈ 1904 on.
    on = (np.arange(1570, 1970) % 36) < 27
    s["tau"][1570:1970, 2] = np.where(on, np.where(np.arange(400) % 2 == 0, 1450.0, -1450.0),
                                      100.0)
    q[1570:1970, 2] += 1e-4 * np.sin(2.0 * np.pi * 28.0 * DT * np.arange(400))   # it moves
    q_ref[1570:1970, 2] = q[1570:1970, 2]
    # ... and axis 0's from 2150 to 2650 in a 0.3 s window (set at 2100): soft stop past
    # 0.15 s, still saturated 0.3 s into it → hard stop.
    s["tau"][2150:2650, 0] = np.where(np.arange(500) % 2 == 0, 1450.0, -1450.0)
    q[2150:2650, 0] += 1e-4 * np.sin(2.0 * np.pi * 28.0 * DT * np.arange(500))
    q_ref[2150:2650, 0] = q[2150:2650, 0]
    # An unmeasured load change (issue 15: a payload landing): axis 1 moves one count a cycle
    # carrying −200 N, then a load stops it: still while its command rises 40 → 180 N (240-380
    # N from the carried load, beyond the 225 N band; within 140 N of itself: a constant load
    # holds it); it breaks away and moves under 180 N; then its encoder freezes under a
    # command running away to the drive's limit (480 N here).
    q[2800:3250, 1] = 0.2 + 2e-5 * np.arange(450)
    q[2900:2960, 1] = q[2900, 1]
    q[2960:3000, 1] = q[2900, 1] + 2e-5 * np.arange(1, 41)
    q[3000:3250, 1] = q[2999, 1]
    q_ref[2800:3250, 1] = q[2800:3250, 1]
    s["qdd"][2800:3250, 1] = 0.0
    s["qd_ref"][2800:3250, 1] = 0.0
    s["tau"][2800:2900, 1] = -200.0
    s["tau"][2900:2960, 1] = np.linspace(40.0, 180.0, 60)
    s["tau"][2960:3000, 1] = 180.0
    s["tau"][3000:3250, 1] = np.minimum(np.linspace(180.0, 680.0, 250), 480.0)
    # A lost contact (issue 15, force control from 3300): the foot held at 50 N with the
    # sliders at 0.2 m, then nothing read while they rise 8 mm: contact_lost once the mean
    # is 5 mm above where the contact was last held.
    q[3300:3400, :] = 0.2
    q[3330:3360, :] = 0.2 + np.linspace(0.0, 0.008, 30)[:, None]
    q[3360:3400, :] = 0.208
    q_ref[3300:3400, :] = q[3300:3400, :]
    w[3300:3330, 2] = -50.0
    w[3330:3400, 2] = 0.0
    # A pull that persists in a (client's) stop from 3500: 80 N for 1.1 s (a stale sample
    # and a stall in it) → pull_in_stop raised; a sample of no pull at 4600 ends it; the pull
    # again from 4650 → raised again; a reset of the stop at 5700 ends it.
    w[3500:5800, 2] = 80.0
    w[4600:4650, 2] = -20.0
    s["wrench_flags"][4000:4003, 0] = 1.0
    s["dt"][4100:4103] = 5.0 * DT
    return s


#: Cycle → client action (before the cycle): estop/stop requests, resets, heartbeat on/off.
ACTIONS = {150: "reset", 160: "reset", 205: "reset", 250: "reset", 450: "reset", 460: "estop",
           470: "reset", 580: "reset", 615: "force_control_on", 680: "reset",
           770: "force_control_off", 780: "reset", 810: "reset", 830: "reset", 850: "reset",
           870: "stop", 880: "reset", 920: "heartbeat", 950: "reset", 960: "heartbeat_off",
           970: "reset", 1100: "reset", 1250: "reset", 1300: "stop", 1301: "estop",
           1310: "reset", 1500: "limits", 1510: "reset", 1930: "reset", 2100: "window",
           2110: "reset", 2760: "reset", 3260: "reset", 3300: "force_control_on",
           3400: "force_control_off", 3410: "reset", 3500: "stop", 5700: "reset"}


def _block(sup: Supervisor, stream: dict[str, np.ndarray]) -> tuple[SupervisorBlock, dict]:
    """A supervisor block outside a graph: inputs are read-only views (as a graph binds them)
    of buffers the replay fills; outputs its own."""
    blk = SupervisorBlock("supervisor", sup, 80.0)
    bufs = {}
    for name, n in PORTS.items():
        buf = np.zeros(n)
        view = buf.view()
        view.flags.writeable = False
        getattr(blk, ATTR.get(name, name)).data = view
        bufs[name] = buf
    state = State()
    blk.state_in.data = state
    bufs["state"] = state
    blk.volts.data = np.zeros(3)
    blk.enable.data = np.ones(1)
    blk.mode.data = np.zeros(1)
    return blk, bufs


def _event(e) -> tuple:
    return (e.t, e.kind, e.cause, e.reaction, e.message, e.values, e.id)


def test_compiled_supervisor_matches_the_interpreted_one(recorded, model) -> None:
    s = _stream(recorded)
    phys = supervisor_physics(model.description)
    lim = effective(model.description.limits.stroke, RobotLimits(), PatientLimits())
    sups = [cls(lim, DT, EventLog(), **phys) for cls in (Supervisor, InterpretedSupervisor)]
    assert sups[0].compiled and not sups[1].compiled
    blocks = [_block(sup, s) for sup in sups]
    age = [0.0]
    tickets: list[list] = [[], []]
    for k in range(CYCLES):
        t = (k + 1) * DT
        action = ACTIONS.get(k)
        for j, sup in enumerate(sups):
            if action == "reset":
                tickets[j].append(sup.request_reset())
            elif action == "estop":
                sup.request_estop("gui")
            elif action == "stop":
                sup.request_stop()
            elif action in ("force_control_on", "force_control_off"):
                sup.force_control = action.endswith("on")
            elif action == "heartbeat":
                sup.heartbeat_required = True
                sup.heartbeat_age = lambda: age[0]
            elif action == "heartbeat_off":
                sup.heartbeat_required = False
            elif action == "limits":
                sup.limits = effective(model.description.limits.stroke, RobotLimits(),
                                       PatientLimits(max_force_n=100.0))
            elif action == "window":        # another window: it starts afresh
                sup.limits = effective(model.description.limits.stroke,
                                       RobotLimits(saturation_window_s=0.3),
                                       PatientLimits(max_force_n=100.0))
        age[0] = 0.5 if 930 <= k < 940 else 0.01
        for blk, bufs in blocks:
            for name in PORTS:
                bufs[name][:] = s[name][k]
            st = bufs["state"]
            st.buf[:] = s["state"][k]
            st.buffer_filled()
            blk.update(t, float(s["dt"][k]))
        (bc, _), (bi, _) = blocks
        for port in ("volts", "enable", "mode"):
            a, b = getattr(bc, port).data, getattr(bi, port).data
            assert np.array_equal(a, b, equal_nan=True), (k, port, a, b)
        assert sups[0].reaction == sups[1].reaction, k
        assert sups[0].causes == sups[1].causes, k
        assert sups[0].latched_ids == sups[1].latched_ids, k
        assert sups[0].carry_force_n == pytest.approx(sups[1].carry_force_n, nan_ok=True,
                                                      rel=0.0, abs=0.0), k
        # The force balance's state: the share, how long quasi-static, the applied limit.
        mem, ref = sups[0]._mem, sups[1]
        assert isinstance(ref, InterpretedSupervisor)
        assert mem[sk.M_SHARE:sk.M_SHARE + 3].tolist() == pytest.approx(
            ref._share, nan_ok=True, rel=0.0, abs=0.0), k
        assert mem[sk.M_QUIET:sk.M_QUIET + 3].tolist() == ref._quiet, k
        assert mem[sk.M_CONTACT_UNTIL] == ref._contact_until, k
        assert sups[0].applied_force_max_n == sups[1].applied_force_max_n == 480.0, k
        assert sups[0].saturated_peak_s == sups[1].saturated_peak_s, k
        for m, r in ((sk.M_STILL_LO, ref._still_lo), (sk.M_STILL_HI, ref._still_hi)):
            assert mem[m:m + 3].tolist() == pytest.approx(r, nan_ok=True, rel=0.0, abs=0.0), k
        assert sups[0].alarms() == sups[1].alarms(), k
        if k == 2799:
            assert sups[0].reaction == Reaction.NONE          # the load-change splice runs
    events = [[_event(e) for e in sup.log.snapshot()] for sup in sups]
    assert events[0] == events[1]
    for tc, ti in zip(*tickets, strict=True):
        assert tc.done and ti.done
        assert (tc.cleared, tc.refused, tc.still_latched) == \
            (ti.cleared, ti.refused, ti.still_latched)
    # The stream exercised every cause the kernel checks, faults and warnings, and resets
    # both refused and taken.
    from rt.safety.supervisor import CAUSES
    logged = {e[2] for e in events[0]}
    axis_free = {c.rstrip("012") for c in CAUSES}
    assert axis_free <= {c.rstrip("012") for c in logged}, axis_free - logged
    assert {"estop_gui", "stop_client", "heartbeat_lost"} <= logged
    kinds = {e[1] for e in events[0]}
    assert kinds == {"fault", "warn", "reset", "reset_refused", "alarm_end"}
    # … at both reactions where a cause has two.
    reactions = {(e[2], e[3]) for e in events[0]}
    for cause in ("tracking_0", "rom_roll", "force_limit", "drive_saturated_0"):
        assert {(cause, Reaction.SOFT_STOP), (cause, Reaction.HARD_STOP)} <= reactions, cause
    # The sustained saturation: tripped once its window held more than half of 0.5 s
    # saturated; a reset refused while it did, taken once the window changed (restarted).
    sat = [e for e in events[0] if e[2] == "drive_saturated_2" and e[1] == "fault"]
    assert [e[3] for e in sat] == [Reaction.SOFT_STOP, Reaction.HARD_STOP]
    # The hard stop: a whole window (0.5 s) after the soft stop then latched (another cause's,
    # latched before the saturation began), the saturation still beyond half of it.
    stop_at = next(e[0] for e in events[0] if e[1] == "fault" and e[3] >= Reaction.SOFT_STOP
                   and e[0] > max(r[0] for r in events[0] if r[1] == "reset" and r[0] < sat[0][0]))
    assert stop_at < sat[0][0] and round((sat[1][0] - stop_at) / DT) in (501, 502)
    t_trip, values = sat[0][0], sat[0][5]
    assert values["window_s"] == 0.5 and values["limit_n"] == 480.0
    on = (np.arange(1570, 1970) % 36) < 27
    k_trip = round(t_trip / DT) - 1
    # Every saturated cycle since 1570 is inside the window at the trip: their time.
    held = on[:k_trip - 1570 + 1].sum() * DT
    assert values["saturated_s"] == pytest.approx(held, abs=1e-9)
    assert 0.25 - 1e-9 <= held <= 0.25 + DT, held
    # At 1930 the window still holds more than 0.25 s: refused; at 2110 it would too (1610-
    # 1970 holds 0.27 s), but the window changed at 2100 and started afresh: taken.
    refused = [e for e in events[0] if e[1] == "reset_refused" and "drive_saturated_2" in e[2]]
    assert [round(e[0] / DT) - 1 for e in refused] == [1930]
    resets = [e for e in events[0] if e[1] == "reset" and "drive_saturated_2" in e[2]]
    assert [round(e[0] / DT) - 1 for e in resets] == [2110]
    # Axis 0, saturated every cycle from 2150 in the 0.3 s window: soft stop once it held
    # more than 0.15 s, hard stop 0.3 s into that soft stop (it did not end it).
    soft, hard = [[round(e[0] / DT) - 1 for e in events[0] if e[2] == "drive_saturated_0"
                   and e[3] == r] for r in (Reaction.SOFT_STOP, Reaction.HARD_STOP)]
    # (± one cycle: 150 float steps of 1 ms sum to a hair above or below 0.15 s)
    assert len(soft) == len(hard) == 1, (soft, hard)
    assert abs(soft[0] - (2150 + 150)) <= 1 and hard[0] - soft[0] in (301, 302), (soft, hard)
    assert sups[0].saturated_peak_s[0] == pytest.approx(0.3, abs=0.01)
    # The unmeasured load change: the stall under a command 240-380 N from the carried load
    # is not a frozen encoder (it moved within 140 N: a constant load holds it); the encoder
    # frozen after it is, once its command (2 N a cycle) left the band of where it stood at
    # the freeze (180 N + 225 N: cycle 3112) and the excess carried the axis' 207 kg over 4
    # counts (x = J T / 2m with a ramp's J: ≈ 32 cycles more).
    frozen = [round(e[0] / DT) - 1 for e in events[0] if e[2] == "encoder_frozen_1"
              and e[1] == "fault" and e[0] > 2800 * DT]
    assert len(frozen) == 1 and 3112 < frozen[0] < 3160, frozen
    # The lost contact: when the sliders' mean first stood more than 5 mm above 0.2 m.
    lost = [(round(e[0] / DT) - 1, e[5]) for e in events[0] if e[2] == "contact_lost"
            and e[1] == "fault"]
    k_lost = 3330 + int(np.argmax(np.linspace(0.0, 0.008, 30) > sk.CONTACT_LOST_RISE_M))
    assert [k for k, _ in lost] == [k_lost], lost
    assert lost[0][1]["touch_q_m"] == pytest.approx(0.2, abs=1e-15) and lost[0][1]["fz_n"] == 0.0
    # The pull in the stop: raised once per pull, 1 s of it counted (the stale samples not,
    # the stall's 5 ms as 2), ended by a sample of no pull, then by the stop's reset.
    pull = [(e[1], round(e[0] / DT) - 1, e[5]) for e in events[0] if e[2] == "pull_in_stop"]
    assert [(kind, k) for kind, k, _ in pull] == [
        # counted from 3501 (the stop latched in 3500): 1000 cycles' worth, the 3 stale
        # ones not counted, the 3 stalled ones as 2 periods each
        ("warn", 3501 + 1000 + 3 - 3 - 1), ("alarm_end", 4600),
        ("warn", 4650 + 1000 - 1), ("alarm_end", 5701)], pull
    assert pull[0][2]["fz_n"] == -80.0 and pull[0][2]["since_t"] == pytest.approx(3502 * DT)
    assert pull[1][2]["how"] == "pull_ended" and pull[1][2]["fz_n"] == 20.0
    assert pull[3][2]["how"] == "stop_reset" and pull[3][2]["fz_n"] == -80.0


def test_steady_cycles_run_no_python_side(recorded, model, monkeypatch) -> None:
    """Cycles in which nothing new trips and nothing is requested never reach the Python side
    (naming, logging, latching): the compiled call is the whole cycle."""
    s = _stream(recorded)
    sup = Supervisor(effective(model.description.limits.stroke, RobotLimits(), PatientLimits()),
                     DT, EventLog(), **supervisor_physics(model.description))
    calls = []
    original = sup._after_checks
    monkeypatch.setattr(sup, "_after_checks", lambda *a: (calls.append(a), original(*a)))
    blk, bufs = _block(sup, s)
    for k in range(60):                              # the recording's first, healthy cycles
        for name in PORTS:
            bufs[name][:] = s[name][k]
        bufs["state"].buf[:] = s["state"][k]
        bufs["state"].buffer_filled()
        blk.update((k + 1) * DT, DT)
    assert calls == [] and sup.log.snapshot() == []
    assert blk.enable.data[0] == 1.0 and blk.mode.data[0] == 0.0
    assert np.array_equal(blk.volts.data, np.clip(s["tau"][59] * (1.0 / 80.0), -6.0, 6.0))
    sup.request_stop()
    blk.update(61 * DT, DT)
    assert len(calls) == 1 and blk.mode.data[0] == 2.0 and "stop_client" in sup.causes


def test_the_loop_runs_the_compiled_supervisor(model) -> None:
    """The position loop's supervisor is the compiled one, and its block compiles nothing in
    a cycle (the kernels were compiled for the port views' types at construction)."""
    from rt.safety import supervisor_kernel as sk

    pl = build_sim_position_loop("paden_panja", duration_s=1.0, model=model)
    assert pl.supervisor.compiled
    before = [len(k.signatures) for k in (sk.check, sk.block_cycle, sk.outputs)]
    pl.loop.run(cycles=50)
    pl.supervisor.request_estop("cli")
    pl.loop.run(cycles=5)
    pl.graph.stop()
    assert "estop_cli" in pl.supervisor.causes
    assert float(pl.graph.output("supervisor.enable")[0]) == 0.0
    assert [len(k.signatures) for k in (sk.check, sk.block_cycle, sk.outputs)] == before
