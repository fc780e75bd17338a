"""Pre-flight's verdict does not depend on how the loop runs its cycle (issue 16).

Pre-flight runs the session's own loop as fast as possible: the fused cycle
(``rt.components.fused``: the middle blocks in one compiled call) where it covers the cycle,
the blocks' ``update`` elsewhere. Its verdict must be the per-block loop's to the last bit: the
same stop or none, the same peak forces and speeds, the same ``at_robot_limit`` moments.
ankle_rom (one repetition) is a position protocol (the fused chain runs almost every cycle); gait_replay is a
force protocol (the chain stops before the controller in force mode and the blocks finish the
cycle), so both hand-over paths are exercised.

The compiled driver (``rt.preflight.driver``: the steady cycles in one compiled loop, handing
back to the loop where a cycle needs Python) is held to the loop's fused cycle and to every
block's ``update``: the same tap rows, every signal of every cycle, to the bit.
"""
from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from protocols import session
from protocols.library import load_protocol
from protocols.schema import validate_protocol_data
from rt.components.fused import ENV_FLAG
from rt.model import RobotModel
from rt.model.ankle import AnkleSetup
from rt.preflight import driver as driver_mod
from rt.references.program import Mode
from rt.safety.limits import RobotLimits
from rt.sessions import COLUMNS

LIBRARY = Path(__file__).resolve().parent.parent / "protocols" / "library"


def _bits(x: object) -> object:
    """Every float as its hex (exact equality, NaN equal to NaN)."""
    if isinstance(x, float):
        return "nan" if math.isnan(x) else x.hex()
    if isinstance(x, dict):
        return {k: _bits(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_bits(v) for v in x]
    return x


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel.load()


@pytest.mark.parametrize("protocol", ["ankle_rom.yaml", "gait_replay.yaml"])
def test_the_fused_preflight_gives_the_per_block_verdict(protocol, model, monkeypatch):
    program = load_protocol(LIBRARY / protocol)
    if protocol == "ankle_rom.yaml":     # one repetition of each motion: 40 s → 14 s
        program = program.model_copy(update={"repetitions": 1})
    setup = session.SessionSetup(protocol=program, base_dir=LIBRARY, patient_weight_kg=70.0)
    build = session.build_twin_session
    loops = []

    def keep(*args, **kwargs):
        out = build(*args, **kwargs)
        loops.append(out[3])
        return out
    monkeypatch.setattr(session, "build_twin_session", keep)
    verdicts = {}
    for fused in ("1", "0"):
        monkeypatch.setenv(ENV_FLAG, fused)
        verdicts[fused] = session.preflight(setup, model)
    # Each path ran as asked: the fused one ran the chain, the other every block's update.
    assert [pl.graph.fused for pl in loops] == [True, False]
    assert verdicts["1"]["ok"] and verdicts["1"]["predicted"]["duration_s"] > 5.0
    assert _bits(verdicts["1"]) == _bits(verdicts["0"])


# ---------------------------------------------------------------- the compiled driver
#: The real C3D files: $TALUS_C3D_DIR, else ../shared/data/c3d beside the repository (as
#: tests/test_gait_real_files.py finds them).
C3D_DIR = next((str(d) for d in (os.environ.get("TALUS_C3D_DIR"),
                                 Path(__file__).parents[2] / "shared/data/c3d")
                if d and (Path(d) / "type2_vicon.c3d").is_file()), None)


def _preflight_rows(setup: session.SessionSetup, monkeypatch, *, driver: bool, fused: bool,
                    model: RobotModel | None = None) -> tuple[object, np.ndarray, object]:
    """One pre-flight, with a fresh model unless ``model`` is given: (verdict or the refusal's
    message, the session tap's rows, the driver or None)."""
    monkeypatch.setenv(ENV_FLAG, "1" if fused else "0")
    monkeypatch.setenv(session.PREFLIGHT_DRIVER_ENV, "1" if driver else "0")
    kept: dict = {}
    build = session.build_twin_session
    make = driver_mod.PreflightDriver

    def keep(*args, **kwargs):
        out = build(*args, **kwargs)
        kept["pl"], kept["tap"] = out[3], out[4]
        return out

    def keep_driver(*args, **kwargs):
        kept["driver"] = make(*args, **kwargs)
        return kept["driver"]
    monkeypatch.setattr(session, "build_twin_session", keep)
    monkeypatch.setattr(driver_mod, "PreflightDriver", keep_driver)
    try:
        verdict: object = session.preflight(setup, model or RobotModel.load())
    except session.ProtocolValidationError as exc:
        verdict = str(exc)
    tap = kept["tap"]
    rows = tap.ring[:tap.written].copy()
    truth = session.truth_tap(kept["pl"])
    if truth is not None:          # an ankle setup: the twin ankle's true torque, same cycles
        assert truth.written == tap.written
        rows = np.hstack([rows, truth.ring[:truth.written]])
    return verdict, rows, kept.get("driver")


def _ankle_rom(amplitude_deg: float) -> dict:
    """A short ankle ROM about the ankle (``tests/test_ankle_session.py``'s)."""
    return {"schema_version": 1, "kind": "ankle_rom", "name": "rom",
            "pose": {"z_m": 0.63}, "sequence": ["dorsi_plantar", "inversion_eversion"],
            "amplitude_deg": {"dorsiflexion": amplitude_deg, "plantarflexion": amplitude_deg,
                              "inversion": amplitude_deg, "eversion": amplitude_deg},
            "speed_deg_s": 20.0, "hold_s": 0.3, "max_acceleration_deg_s2": 200.0,
            "max_jerk_deg_s3": 4000.0}


def _setups() -> list:
    rom = load_protocol(LIBRARY / "ankle_rom.yaml").model_copy(update={"repetitions": 1})
    cases = [
        pytest.param(session.SessionSetup(protocol=rom, base_dir=LIBRARY,
                                          patient_weight_kg=70.0), True, id="ankle_rom"),
        pytest.param(session.SessionSetup(LIBRARY / "sine_fz.yaml"), True, id="sine_fz"),
        pytest.param(session.SessionSetup(LIBRARY / "gait_replay.yaml",
                                          patient_weight_kg=70.0), True, id="gait_replay"),
        # An ankle setup: the twin ankle's truth block and its tap after the session tap.
        pytest.param(session.SessionSetup(protocol=validate_protocol_data(_ankle_rom(8.0)),
                                          ankle=AnkleSetup(side="left",
                                                           height_above_sole_m=0.07,
                                                           offset_x_m=0.01)),
                     True, id="ankle_setup"),
        # A run the supervisor stops: the drives limited to 0.5 V saturate (the kernel's
        # supervisor latches the stop: a hand-back inside a cycle), then 0.6 s at rest.
        pytest.param(session.SessionSetup(LIBRARY / "sine_fz.yaml",
                                          robot_limits=RobotLimits(max_command_v=0.5)),
                     False, id="sine_fz_saturating"),
    ]
    return cases


@pytest.mark.parametrize("setup,accepted", _setups())
def test_the_compiled_driver_gives_the_loops_tap_rows_and_verdict(setup, accepted,
                                                                  monkeypatch):
    """The driver's pre-flight (steady cycles in one compiled loop, hand-backs to the loop)
    against the same pre-flight through the loop's fused cycle and through every block's
    ``update``: every tap row (every signal of every cycle) and the verdict equal to the bit,
    and the driver really ran most cycles."""
    v_drv, rows_drv, drv = _preflight_rows(setup, monkeypatch, driver=True, fused=True)
    v_fused, rows_fused, none = _preflight_rows(setup, monkeypatch, driver=False, fused=True)
    v_block, rows_block, _ = _preflight_rows(setup, monkeypatch, driver=False, fused=False)
    assert none is None and drv is not None and drv.why_not == ""
    assert rows_drv.shape == rows_fused.shape == rows_block.shape
    assert rows_drv.view(np.int64).tolist() == rows_fused.view(np.int64).tolist()
    assert rows_drv.view(np.int64).tolist() == rows_block.view(np.int64).tolist()
    assert _bits(v_drv) == _bits(v_fused) == _bits(v_block)
    assert isinstance(v_drv, dict) == accepted
    if not accepted:
        assert "drive_saturated" in str(v_drv)
    assert drv.cycles_compiled + drv.cycles_python == len(rows_drv)
    # Nine cycles in ten were the driver's, a stopped run's compliant hold after its force
    # control ended included (the hold's cycles are compiled: hold9; they were Python's).
    assert drv.cycles_python < 0.1 * len(rows_drv)
    if not accepted:
        in_force = np.flatnonzero(rows_drv[:, COLUMNS["ctrl_mode"].start] == float(Mode.FORCE))
        hold = len(rows_drv) - int(in_force[-1]) - 1
        assert hold > 500 and drv.cycles_python < 30, (hold, drv.cycles_python)


@pytest.mark.skipif(C3D_DIR is None, reason="the real C3D files (../shared/data/c3d beside "
                    "the repository, or $TALUS_C3D_DIR) are not present")
def test_the_compiled_driver_on_a_real_c3d_gait(monkeypatch, tmp_path):
    """A gait replay of a real C3D force plate (type2_vicon, plate 0: ``bench/gait_files.py``'s
    protocol) through the driver and through the loop: the same tap rows and verdict, bit
    for bit."""
    import importlib.util

    assert C3D_DIR is not None
    spec = importlib.util.spec_from_file_location(
        "bench_gait_files", Path(__file__).parents[1] / "bench" / "gait_files.py")
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = bench
    spec.loader.exec_module(bench)
    case = next(c for c in bench.CASES if c.file == "type2_vicon.c3d" and c.plate == 0)
    path = tmp_path / "gait.yaml"
    path.write_text(bench.protocol_text(case, Path(C3D_DIR)))
    setup = session.SessionSetup(path, patient_weight_kg=bench.PATIENT_KG)
    v_drv, rows_drv, drv = _preflight_rows(setup, monkeypatch, driver=True, fused=True)
    v_loop, rows_loop, _ = _preflight_rows(setup, monkeypatch, driver=False, fused=True)
    assert drv is not None and drv.cycles_compiled > 0.9 * len(rows_drv)
    assert rows_drv.view(np.int64).tolist() == rows_loop.view(np.int64).tolist()
    assert _bits(v_drv) == _bits(v_loop) and isinstance(v_drv, dict)


def test_a_model_that_ran_a_preflight_gives_the_next_one_the_same_cycles(monkeypatch):
    """The model's FK keeps its last solution as the next Newton start; a loop built on it
    starts from the nominal rod angles again (``Kinematics.reset_warm_start``), so a second
    pre-flight of the same protocol on the same model object is the first one to the bit (it
    differed by up to 5e-12 in the torque and volts columns of its first rows before)."""
    setup = session.SessionSetup(LIBRARY / "gait_replay.yaml", patient_weight_kg=70.0)
    model = RobotModel.load()
    runs = [_preflight_rows(setup, monkeypatch, driver=True, fused=True, model=model)
            for _ in range(2)]
    fresh = _preflight_rows(setup, monkeypatch, driver=True, fused=True)
    assert runs[0][0] == runs[1][0] == fresh[0]
    for _verdict, rows, _driver in (runs[1], fresh):
        assert rows.shape == runs[0][1].shape
        assert np.array_equal(rows.view(np.int64), runs[0][1].view(np.int64))
