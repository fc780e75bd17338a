"""Identification through the RT process: the ``identify_excitation`` program checks the whole
trajectory against the limits in force before anything moves, plays it under the supervisor,
records it (MCAP); ``talus identify fit`` on the recordings writes the description, and the
identified model predicts the validation trajectory's forces within 5 % RMS of the peak."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_rt_process import start_rt, stop_rt

from rt.control.base import Reference
from rt.control.experiment import benchmark_reference
from rt.errors import InputError
from rt.identification.excitation import (
    MAX_EXCURSION_M,
    N_HARMONICS,
    FourierExcitation,
    benchmark_excitation,
    optimize_excitation,
)
from rt.identification.program import (
    PROGRAM_NAME,
    ExcitationProgram,
    ExcitationSpec,
    check_trajectory,
    excitation_table,
)
from rt.ipc.client import RtClient
from rt.model import RobotModel
from rt.model.description import load_description
from rt.references.program import ReferenceOutput
from rt.safety.limits import PatientLimits, RobotLimits, effective

DT = 1e-3


def _limits(model: RobotModel, **patient):
    return effective(model.description.limits.stroke, RobotLimits(), PatientLimits(**patient))


def test_benchmark_excitation_is_the_benchmark_trajectory():
    exc = benchmark_excitation(0.2)
    ref = Reference()
    f = benchmark_reference(0.2)
    for t in (0.0, 0.37, 3.9, 12.25, 19.999):
        f(t, ref)
        q, qd, qdd = exc.evaluate(np.array([t]))
        np.testing.assert_allclose(q[0], ref.q, atol=1e-12)
        np.testing.assert_allclose(qd[0], ref.qd, atol=1e-12)
        np.testing.assert_allclose(qdd[0], ref.qdd, atol=1e-12)


def test_program_plays_the_table_and_holds_its_last_sample():
    exc = benchmark_excitation(0.2)
    table = excitation_table(exc, 2.0, DT)
    prog = ExcitationProgram(table, DT)
    assert prog.duration_s == pytest.approx(2.0)
    out = ReferenceOutput()
    for _ in range(prog.n_samples + 5):
        status = prog.update(out)
    assert status == 1 and out.done
    q, _qd, qdd = exc.evaluate(np.array([2.0]))
    np.testing.assert_allclose(out.q_ref, q[0], atol=1e-12)
    np.testing.assert_allclose(out.qdd_ref, qdd[0], atol=1e-12)


def test_trajectories_outside_the_limits_are_refused_naming_the_limit():
    model = RobotModel.load()
    lim = _limits(model)
    good = optimize_excitation(model, evaluations=30)
    check_trajectory(excitation_table(good, 10.0, DT), model.kin, lim, DT)   # accepted
    _lo, hi = model.description.limits.stroke
    # The whole excitation shifted to the stroke's end: ruckig would go there, we refuse.
    shifted = FourierExcitation(good.a, good.b, hi - 0.5 * MAX_EXCURSION_M, good.f0_hz)
    with pytest.raises(InputError, match="stroke"):
        check_trajectory(excitation_table(shifted, 10.0, DT), model.kin, lim, DT)
    # The same path traced k times faster: speeds × k (accelerations × k²), beyond the limit.
    k = 1.5 * lim.max_slider_speed_m_s / good.peaks()[1]
    fast = FourierExcitation(k * good.a, k * good.b, good.q0, k * good.f0_hz)
    with pytest.raises(InputError, match="speed"):
        check_trajectory(excitation_table(fast, 10.0, DT), model.kin, lim, DT)
    # A patient's narrower ROM (5°) refuses the excitation's tilts (≈ 15°).
    narrow = _limits(model, roll_min_deg=-5, roll_max_deg=5, pitch_min_deg=-5, pitch_max_deg=5)
    with pytest.raises(InputError, match="roll|pitch"):
        check_trajectory(excitation_table(good, 10.0, DT), model.kin, narrow, DT)
    a = np.zeros((3, N_HARMONICS))
    with pytest.raises(InputError, match="3 × K"):
        ExcitationSpec(a=a[:2].tolist(), b=a[:2].tolist(), q0=0.2, f0_hz=0.1).excitation()
    bad = a.copy()
    bad[0, 0] = math.inf
    with pytest.raises(InputError, match="finite"):
        ExcitationSpec(a=bad.tolist(), b=a.tolist(), q0=0.2, f0_hz=0.1).excitation()


def _config(tmp_path: Path) -> str:
    """The tests' tolerant RT config (tests/test_rt_process.tolerant_config) with the loop in
    fast mode: the twin runs back to back in simulated time, so a late cycle on a loaded
    machine cannot hold a command and change the data. The heartbeat timeout is the config's
    largest (5 s): a loop running back to back holds the GIL most of the time, and under load
    the RT process saw a live client's heartbeat 1.005 s late (a soft stop mid-excitation)."""
    path = tmp_path / "rt.yaml"
    path.write_text("schema_version: 1\nheartbeat_timeout_s: 5.0\nloop_mode: fast\n"
                    "robot_limits:\n  deadline_overruns: 1000\n  max_tracking_error_m: 0.05\n")
    return str(path)


@pytest.fixture(scope="module")
def rt_twin(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rtident")
    proc, endpoint, _ = start_rt("--config", _config(tmp))
    try:
        yield endpoint, tmp
    finally:
        stop_rt(proc)


def _talus(*args: str, timeout: float = 900.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "talus", *args], check=False,
                          capture_output=True, text=True, timeout=timeout)


def test_identification_through_the_rt_process_and_fit_of_its_recordings(rt_twin):
    endpoint, tmp = rt_twin
    out = tmp / "identified.yaml"
    proc = _talus("identify", "run", "--backend", "rt", "--endpoint", endpoint,
                  "--record-dir", str(tmp), "--out", str(out), "--seconds", "20", "--json")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    result = json.loads(proc.stdout)
    rec, val = (Path(result["recordings"][k]) for k in ("excitation", "validation"))
    assert rec.is_file() and val.is_file()
    desc = load_description(out)
    RobotModel.from_description(desc)                   # loadable with --robot
    v = result["validation"]
    # The target: predicted vs measured actuator forces on the second trajectory.
    assert v["identified"]["rms_pct_of_peak"] <= 5.0, v
    assert v["identified"]["rms_pct_of_peak"] < v["nominal"]["rms_pct_of_peak"]
    assert result["twin_truth"]                           # the twin recorded its truth
    assert all(b["sigma"] >= 0.0 for b in result["base"])
    # `identify fit` on the same recordings writes the same description (a round trip).
    refit = tmp / "refit.yaml"
    proc = _talus("identify", "fit", "--recording", str(rec), "--validation", str(val),
                  "--out", str(refit), "--json", timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert load_description(refit).model_dump() == desc.model_dump()
    # Outputs are never overwritten, and a recording cannot be its own output.
    before = out.read_bytes()
    proc = _talus("identify", "fit", "--recording", str(rec), "--out", str(out), timeout=300)
    assert proc.returncode == 2 and "exists" in proc.stdout
    assert out.read_bytes() == before
    proc = _talus("identify", "fit", "--recording", str(rec), "--out", str(rec), "--force",
                  timeout=300)
    assert proc.returncode == 2 and "input" in proc.stdout
    # A recording that is not an identification one is refused by name.
    with RtClient(endpoint, client_id="test-ident-refuse", timeout_s=5.0) as client:
        client.control_acquire("test")
        exc = optimize_excitation(RobotModel.load(), evaluations=30)
        shifted = FourierExcitation(exc.a, exc.b, 0.45, exc.f0_hz)
        spec = ExcitationSpec.of(shifted).model_dump()
        target = tmp / "refused.mcap"
        with pytest.raises(InputError, match="stroke"):
            client.run(PROGRAM_NAME, {"excitation": spec, "duration_s": 10.0,
                                      "out": str(target)})
        assert not target.exists()                         # refused before anything moved
        with pytest.raises(InputError, match="exists"):
            client.run(PROGRAM_NAME, {"excitation": ExcitationSpec.of(exc).model_dump(),
                                      "duration_s": 10.0, "out": str(rec)})
        with pytest.raises(InputError, match="unknown parameter"):
            client.run(PROGRAM_NAME, {"excitation": spec, "duration_s": 10.0,
                                      "out": str(target), "speed": 2})
        st = client.status()
        assert st["phase_name"] in ("rest", "stopped") and st["state"] != "fault"
        client.control_release()
