"""The amplifiers' input offsets compensated where newtons become volts (issue 15).

An amplifier adds its input offset o to every command while the drives are enabled, so a
command of V volts delivers (V + o) × force per volt. The supervisor's outputs write
τ·k − o (``rt.safety.supervisor_kernel.outputs``, its interpreted twin in
``SupervisorBlock._update_interpreted``) with o the description's believed
``drive.amplifier_offset_v``: then the drive delivers the commanded τ. A hard stop writes
exactly 0 V; every check stays on τ. With zero offsets (every default description) the outputs
are the previous ones bit for bit (``tests/test_fused_cycle.py``, ``test_compiled_cycle.py``,
``test_supervisor*.py``, ``test_twin_golden.py`` pass unchanged).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

# The rich trajectory's exact forces, as commands the amplifiers add the offsets to.
from test_identification import _synthetic as synthetic_data

from rt.components.safety_blocks import SupervisorBlock
from rt.errors import ConfigurationError
from rt.model import RobotModel
from rt.model.description import RobotDescription, description_from_dict, load_description
from rt.model.dynamics import State
from rt.position_loop import build_sim_position_loop
from rt.safety import supervisor_kernel as sk
from rt.safety.events import EventLog, Reaction
from rt.safety.limits import PatientLimits, RobotLimits, effective
from rt.safety.supervisor import InterpretedSupervisor, Supervisor, supervisor_physics
from rt.twin.realism import RigImperfections

DT = 1e-3
NOMINAL = load_description()
K = NOMINAL.drive.force_per_volt_n                  # 339.3 N/V
#: Offsets of the kernel tests (V): one large enough to move a command through the clamp.
OFFSETS_V = (0.012, -0.9, 0.0004)
#: The signature's twin: only the amplifiers' offsets of the unmodelled effects, a ±50 mV
#: draw (the default seed: −26.2 / −42.7 / −14.3 mV, i.e. −8.9 / −14.5 / −4.8 N) so that the
#: smallest is 3× the hold's resolution (below).
IMP = RigImperfections(**{**RigImperfections.none().model_dump(), "amplifier_offset_v": 0.05})
TWIN_OFFSETS_V = IMP.amplifier_offsets_v()
#: How close the mean steady command of a still axis comes to its static load (N): the
#: DAC's LSB is 4.88 mV (1.66 N) and one encoder count is 0.8 N of Paden-Panja's stiffness,
#: so the hold dithers by a count and a code; averaged over 0.8 s the mean lands within
#: 0.6 N (twin figures: 0.35 / 0.16 / 0.04 N compensated; uncompensated 0.55 / 0.19 / 0.13 N
#: from −oK).
HOLD_TOL_N = 1.0


def _with_offsets(desc: RobotDescription, offsets_v, name: str) -> RobotDescription:
    data = desc.model_dump()
    data["drive"]["amplifier_offset_v"] = [float(v) for v in offsets_v]
    return description_from_dict(data, name)


def _frictionless(desc: RobotDescription) -> RobotDescription:
    """``desc`` without Coulomb or static friction (viscous kept): a still axis then rests
    where its forces balance. With stiction it would rest anywhere within its 75 N band,
    which hides a 5-15 N offset."""
    data = desc.model_dump()
    fr = data["friction"]
    fr.update(coulomb_n=0.0, static_n=0.0, coulomb_per_axis_n=None, static_per_axis_n=None)
    return description_from_dict(data, f"{desc.name}-frictionless")


def _steady_hold(model: RobotModel, truth: RobotDescription, imp: RigImperfections,
                 cycles: int = 1500, tail: int = 800) -> dict[str, np.ndarray]:
    """Paden-Panja holding where the twin starts (no program), ``cycles`` at 1 kHz; over the
    last ``tail`` cycles: the mean command less the model's gravity at the mean position (the
    command's error: the static load is the gravity alone, friction is zero at rest), the
    mean written volts and command."""
    pl = build_sim_position_loop("paden_panja", model=model, truth=truth, imperfections=imp,
                                 start_program=False)
    try:
        pl.loop.run(cycles=cycles)
        rows, _ = pl.recorder.drain(0)
        assert pl.events.snapshot() == [], pl.events.snapshot()
        assert pl.supervisor.reaction == Reaction.NONE
        r = rows[-tail:]
        q = r[:, 1:4].mean(axis=0)
        tau = r[:, 10:13].mean(axis=0)
        gravity = model.dyn.gravity(model.dyn.state(tuple(q)))
        return {"error_n": tau - gravity, "tau": r[:, 10:13], "volts": r[:, 13:16],
                "offset_v": np.array(pl.supervisor.amplifier_offset_v),
                "fused": bool(pl.graph.fused)}
    finally:
        pl.graph.stop()


# --------------------------------------------------------------------------- the kernel


def _par(offsets_v=OFFSETS_V, limit_v: float = 6.0) -> np.ndarray:
    par = np.zeros(sk.PAR_SIZE)
    par[sk.P_MAX_COMMAND_V] = limit_v
    par[sk.P_AMP_OFFSET:sk.P_AMP_OFFSET + 3] = offsets_v
    return par


def test_outputs_subtract_the_offset_while_enabled_and_write_zero_when_stopped():
    k = 1.0 / K
    tau = np.array([120.0, 5.5 * K, -7.0 * K])   # axis 1 pushed past the clamp by −0.9 V
    for reaction, mode in ((sk.R_NONE, 0.0), (sk.R_WARN, 0.0), (sk.R_SOFT, 2.0)):
        volts, enable, m = np.full(3, 9.0), np.zeros(1), np.full(1, 7.0)
        sk.outputs(_par(), reaction, tau, k, volts, enable, m)
        # τ·k − o, then the clamp on what is written: ±max_command_v reaches the DAC at most.
        assert volts[0] == 120.0 * k - 0.012
        assert volts[1] == 6.0 and volts[2] == -6.0
        assert enable[0] == 1.0 and m[0] == mode
    # Inside the clamp the compensation is exact: what the amplifier adds back gives τ·k.
    volts = np.zeros(3)
    sk.outputs(_par(), sk.R_NONE, np.array([-300.0, 0.0, 1000.0]), k, volts, np.zeros(1),
               np.zeros(1))
    np.testing.assert_allclose(volts + OFFSETS_V, [-300.0 * k, 0.0, 1000.0 * k],
                               rtol=0.0, atol=1e-15)
    # A hard stop: exactly 0 V (not −o: the drives are disabled, the amplifier adds nothing,
    # the DAC refuses a non-zero command on a disabled drive) and the drives disabled.
    volts, enable, m = np.full(3, 9.0), np.ones(1), np.zeros(1)
    sk.outputs(_par(), sk.R_HARD, tau, k, volts, enable, m)
    assert volts.tolist() == [0.0, 0.0, 0.0] and not np.signbit(volts).any()
    assert enable[0] == 0.0 and m[0] == 3.0
    # A NaN command stays NaN (the drive refuses it) whatever the offset.
    volts = np.zeros(3)
    sk.outputs(_par(), sk.R_NONE, np.array([math.nan, 0.0, 0.0]), k, volts, np.zeros(1),
               np.zeros(1))
    assert math.isnan(volts[0])


def _outputs_before(par, reaction, tau, volts_per_n):
    """The outputs' arithmetic before the compensation (main at 15092d3)."""
    if reaction >= sk.R_HARD:
        return [0.0, 0.0, 0.0]
    limit = par[sk.P_MAX_COMMAND_V]
    out = []
    for i in range(3):
        x = tau[i] * volts_per_n
        out.append(limit if x > limit else (-limit if -limit > x else x))  # noqa: FURB136
    return out


def test_zero_offsets_leave_the_outputs_bit_for_bit():
    rng = np.random.default_rng(7)
    par = _par((0.0, 0.0, 0.0))
    specials = [np.array([-0.0, 0.0, math.nan]), np.array([5e-324, -5e-324, 1e308]),
                np.array([-math.inf, math.inf, 6.0 * K])]
    for tau in specials + [rng.normal(0.0, 1500.0, 3) for _ in range(200)]:
        for reaction in (sk.R_NONE, sk.R_SOFT, sk.R_HARD):
            volts = np.zeros(3)
            sk.outputs(par, reaction, tau, 1.0 / K, volts, np.zeros(1), np.zeros(1))
            want = np.array(_outputs_before(par, reaction, tau, 1.0 / K))
            assert np.array_equal(volts, want, equal_nan=True), (tau, volts, want)
            assert np.array_equal(np.signbit(volts), np.signbit(want)), (tau, volts)


# ------------------------------------------------------- compiled = interpreted, with offsets

PORTS = {"q": 3, "est_status": 1, "qd": 3, "qdd": 3, "fk_ok": 1, "q_ref": 3, "qd_ref": 3,
         "tau": 3, "wrench": 6, "wrench_flags": 2, "inputs": 2, "drive_failed": 1}
ATTR = {"inputs": "stops"}


def _block(sup: Supervisor) -> tuple[SupervisorBlock, dict]:
    """A supervisor block outside a graph, its inputs read-only views of buffers the replay
    fills (as in ``tests/test_supervisor_compiled.py``)."""
    blk = SupervisorBlock("supervisor", sup, K)
    bufs: dict = {}
    for name, n in PORTS.items():
        buf = np.zeros(n)
        view = buf.view()
        view.flags.writeable = False
        getattr(blk, ATTR.get(name, name)).data = view
        bufs[name] = buf
    bufs["state"] = blk.state_in.data = State()
    blk.volts.data = np.zeros(3)
    blk.enable.data = np.ones(1)
    blk.mode.data = np.zeros(1)
    return blk, bufs


def test_compiled_and_interpreted_outputs_compensate_alike():
    """The loop's inputs recorded on the twin, replayed through the compiled and the
    interpreted supervisor block with offsets: the same volts every cycle, bit for bit,
    through the clamp (a splice of 2.2-2.5 kN commands), a soft stop and a hard stop."""
    model = RobotModel.from_description(_with_offsets(NOMINAL, OFFSETS_V, "offsets"))
    pl = build_sim_position_loop("paden_panja", duration_s=1.0, model=model)
    src = pl.graph.component("supervisor")
    rec: dict[str, list] = {name: [] for name in (*PORTS, "state")}
    for _ in range(400):
        pl.loop.run(cycles=1)
        for name in PORTS:
            rec[name].append(np.array(getattr(src, ATTR.get(name, name)).data))
        rec["state"].append(src.state_in.data.buf.copy())
    pl.graph.stop()
    assert pl.supervisor.amplifier_offset_v == OFFSETS_V       # from the description
    phys = supervisor_physics(model.description)
    assert phys["amplifier_offset_v"] == OFFSETS_V
    lim = effective(model.description.limits.stroke, RobotLimits(), PatientLimits())
    sups = [cls(lim, DT, EventLog(), **phys) for cls in (Supervisor, InterpretedSupervisor)]
    blocks = [_block(s) for s in sups]
    seen = set()
    for k in range(400):
        for sup in sups:
            if k == 250:
                sup.request_stop()
            elif k == 300:
                sup.request_estop("gui")
        for blk, bufs in blocks:
            for name in PORTS:
                bufs[name][:] = rec[name][k]
            if 100 <= k < 103:                       # the clamp, both ways
                bufs["tau"][:] = (2200.0, -2500.0, -2200.0)
            bufs["state"].buf[:] = rec["state"][k]
            bufs["state"].buffer_filled()
            blk.update((k + 1) * DT, DT)
        (bc, _), (bi, _) = blocks
        for port in ("volts", "enable", "mode"):
            a, b = getattr(bc, port).data, getattr(bi, port).data
            assert np.array_equal(a, b, equal_nan=True), (k, port, a, b)
        tau = rec["tau"][k] if not 100 <= k < 103 else np.array([2200.0, -2500.0, -2200.0])
        v = bc.volts.data
        if sups[0].reaction >= Reaction.HARD_STOP:
            assert v.tolist() == [0.0, 0.0, 0.0] and bc.enable.data[0] == 0.0
            seen.add("hard")
        else:
            want = np.clip(tau / K - np.array(OFFSETS_V), -6.0, 6.0)
            np.testing.assert_allclose(v, want, rtol=0.0, atol=1e-12)
            seen.add("soft" if bc.mode.data[0] == 2.0 else "run")
            if 100 <= k < 103:
                assert v.tolist() == [6.0, -6.0, -6.0]
                seen.add("clamp")
    assert seen == {"run", "clamp", "soft", "hard"}


# ------------------------------------------------------------------------------ refusals


@pytest.mark.parametrize(("offsets", "why"), [
    ((0.0, 2.0, 0.0), "amplifier_offset_v\\[1\\] = 2.0 V"),
    ((-1.5, 0.0, 0.0), "amplifier_offset_v\\[0\\]"),
    ((0.0, 0.0, math.nan), "amplifier_offset_v\\[2\\]"),
    ((0.0, math.inf, 0.0), "amplifier_offset_v\\[1\\]"),
    ((0.0, 0.0), "one offset per axis"),
    (("a", 0.0, 0.0), "amplifier_offset_v must be 3 numbers"),
    (None, "amplifier_offset_v must be 3 numbers"),
    ("123", "amplifier_offset_v must be 3 numbers"),
])
def test_bad_offsets_are_refused_by_name_and_change_nothing(offsets, why):
    lim = effective(NOMINAL.limits.stroke, RobotLimits(), PatientLimits())
    with pytest.raises(ConfigurationError, match=why):
        Supervisor(lim, DT, EventLog(), amplifier_offset_v=offsets)
    sup = Supervisor(lim, DT, EventLog(), amplifier_offset_v=OFFSETS_V)
    with pytest.raises(ConfigurationError, match="amplifier_offset_v"):
        sup.amplifier_offset_v = offsets
    assert sup.amplifier_offset_v == OFFSETS_V          # the compensation in use is kept


def test_a_robot_file_with_an_absurd_offset_is_refused_by_name(tmp_path):
    """What ``--robot FILE`` loads (``RobotModel.load``) refuses 1.5 V by the field's name:
    no loop is built from it."""
    data = NOMINAL.model_dump()
    data["drive"]["amplifier_offset_v"] = [0.0, 1.5, 0.0]
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigurationError, match="amplifier_offset_v"):
        RobotModel.load(path)


# ------------------------------------------------------------------ the signature on the twin


def test_a_still_axis_holds_with_the_offset_in_its_command_unless_compensated(monkeypatch):
    """An axis at rest in position hold (Paden-Panja, exact masses, no stiction, only the
    amplifiers' offsets as unmodelled effect): without compensation its steady command falls
    short of its static load by the offset's force (the amplifier adds o·K: the command
    settles at G − o·K); compensated, the command is the static load, and the written volts
    are the command's less the offset."""
    truth = _frictionless(NOMINAL)
    offsets_n = TWIN_OFFSETS_V * K
    assert np.all(np.abs(offsets_n) > 4.5)                  # the signature is ≥ 4.5× the tol
    # The reference: the same hold on a twin without offsets.
    ideal = _steady_hold(RobotModel.from_description(NOMINAL), truth, RigImperfections.none())
    np.testing.assert_allclose(ideal["error_n"], 0.0, atol=HOLD_TOL_N)
    without = _steady_hold(RobotModel.from_description(NOMINAL), truth, IMP)
    np.testing.assert_allclose(without["error_n"], -offsets_n, atol=HOLD_TOL_N)
    believed = _with_offsets(NOMINAL, TWIN_OFFSETS_V, "offsets known")
    comp = _steady_hold(RobotModel.from_description(believed), truth, IMP)
    np.testing.assert_allclose(comp["offset_v"], TWIN_OFFSETS_V, rtol=0.0, atol=0.0)
    np.testing.assert_allclose(comp["error_n"], 0.0, atol=HOLD_TOL_N)
    # Every cycle: volts = τ/K − o (well inside the clamp here).
    np.testing.assert_allclose(comp["volts"], comp["tau"] / K - TWIN_OFFSETS_V, rtol=0.0,
                               atol=1e-12)
    # The loop ran the fused cycle (its supervisor stage reads the offsets from the same
    # bound buffer); the per-block cycle writes the same volts, bit for bit.
    monkeypatch.setenv("TALUS_FUSED_CYCLE", "0")
    per_block = _steady_hold(RobotModel.from_description(believed), truth, IMP)
    assert comp["fused"] and not per_block["fused"]
    assert np.array_equal(per_block["volts"], comp["volts"])
    assert np.array_equal(per_block["tau"], comp["tau"])


def test_identified_offsets_reach_the_compensation_through_the_robot_file(tmp_path):
    """identify → the written description → ``--robot`` (``RobotModel.load``) → the loop's
    supervisor compensates them. The fit is ``talus identify``'s (``rt.identification.cli.
    identify`` with offsets) on the exact forces of a rich trajectory less the twin's offsets
    (what its amplifiers add), believing the truth's masses (the offsets are then
    identifiable: ``estimate.py``'s docstring 5.); the file is written as the command
    writes it. On a twin with those offsets, a still axis' command is its static load."""
    from rt.identification.cli import _write_description, identify
    from rt.twin.realism import default_truth

    offsets_n = TWIN_OFFSETS_V * K
    truth = default_truth()
    ident, result = identify(synthetic_data(0.0, offsets_n=offsets_n), None, truth,
                             offsets=True)
    out = tmp_path / "identified.yaml"
    _write_description(ident, out, force=False)
    loaded = RobotModel.load(out)                            # what --robot FILE loads
    written = np.array(loaded.description.drive.amplifier_offset_v)
    assert written.tolist() == result["amplifier_offsets"]["written_v"]
    np.testing.assert_allclose(written, TWIN_OFFSETS_V, rtol=0.0, atol=1e-6)
    hold = _steady_hold(loaded, _frictionless(loaded.description), IMP)
    np.testing.assert_allclose(hold["offset_v"], written, rtol=0.0, atol=0.0)
    np.testing.assert_allclose(hold["error_n"], 0.0, atol=HOLD_TOL_N)
