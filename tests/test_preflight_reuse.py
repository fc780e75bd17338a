"""The RT service keeps a passing session_preflight for the same client's session_start
(rt.preflight_reuse): reused only when the key matches exactly and nothing it depended on
changed; each invalidation tested on an RtService with a real loop (not running) and a
counting session factory. The end-to-end path (reply, recording metadata) is in
tests/test_rt_sessions.py."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from rt.errors import ProtocolValidationError
from rt.ipc.messages import PatientArgs
from rt.preflight_reuse import POSE_TOLERANCE_M, PreflightKey, canonical_sha256
from rt.safety.events import Reaction, SafetyEvent
from rt.service import RtConfig, RtService, build_rt_loop

DOC = {"name": "sine", "kind": "sine_fz", "cycles": 3, "amplitude_n": 20.0}
PATIENT = {"id": "P-001", "weight_kg": 70.0, "limits": {}}


@dataclass
class FakePrepared:
    name: str = "sine"
    kind: str = "sine_fz"
    program: Any = field(default_factory=lambda: SimpleNamespace(duration_s=3.0))
    protocol_limits: Any = None
    metadata: dict = field(default_factory=dict)
    preflight: dict = field(default_factory=lambda: {"duration_s": 3.0})
    start_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    data_ok: bool = True

    def inputs_unchanged(self) -> bool:
        return self.data_ok


class CountingSessions:
    def __init__(self) -> None:
        self.calls = 0

    def prepare(self, protocol: dict, patient: Any, context: Any) -> FakePrepared:
        self.calls += 1
        if protocol.get("refuse"):
            raise ProtocolValidationError("refused by pre-flight: beyond the patient's ROM")
        return FakePrepared()


@pytest.fixture(scope="module")
def loop():
    pl, tap = build_rt_loop(RtConfig(loop_mode="fast"))
    return pl, tap


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture()
def service(loop):
    pl, tap = loop
    pl.graph.component("encoders").outputs["q"].data[:] = 0.05   # wherever: a known place
    svc = RtService(pl, RtConfig(loop_mode="fast", preflight_reuse_s=300.0), tap,
                    sessions=CountingSessions())  # type: ignore[arg-type]
    clock = Clock()
    svc._now = clock  # type: ignore[method-assign]
    svc.clock = clock  # type: ignore[attr-defined]
    return svc


def preflight(svc: RtService, client: str = "gui", doc: dict | None = None,
              patient: dict | None = None) -> dict:
    deferred = svc.session_preflight(client, dict(DOC if doc is None else doc),
                                     PatientArgs(**(PATIENT if patient is None else patient)))
    end = time.monotonic() + 10.0
    while time.monotonic() < end:
        out = deferred.poll()
        if out is not None:
            return out
        time.sleep(0.005)
    raise AssertionError("pre-flight did not answer")


def verdict(svc: RtService, client: str = "gui", doc: dict | None = None,
            patient: dict | None = None) -> str | None:
    return svc.preflight_reuse(client, dict(DOC if doc is None else doc),
                               PatientArgs(**(PATIENT if patient is None else patient)))


def test_a_passing_preflight_is_kept_for_the_same_client_protocol_and_patient(service):
    out = preflight(service)
    assert out["kept_for_s"] == 300.0 and out["preflight_id"].startswith("P")
    assert service.preflights.kept is not None and service.preflights.kept.id == out[
        "preflight_id"]
    assert verdict(service) is None
    # The same document with its keys in another order is the same document.
    assert verdict(service, doc=dict(reversed(list(DOC.items())))) is None
    # The patient as the clinical record sends it (every limit written out, defaults
    # included) is the same patient as the form's empty limits.
    from rt.safety.limits import PatientLimits
    full = {**PATIENT, "limits": PatientLimits().model_dump()}
    assert verdict(service, patient=full) is None


@pytest.mark.parametrize("change, part", [
    ({"doc": {**DOC, "cycles": 4}}, "protocol"),
    ({"doc": {**DOC, "amplitude_n": 20.000001}}, "protocol"),
    ({"doc": {**DOC, "cycles": 3.0}}, "protocol"),            # 3 and 3.0: not the same JSON
    ({"patient": {**PATIENT, "weight_kg": 71.0}}, "patient"),
    ({"patient": {**PATIENT, "id": "P-002"}}, "patient"),
    ({"patient": {**PATIENT, "limits": {"roll_max_deg": 10.0}}}, "patient"),
])
def test_a_different_protocol_or_patient_is_never_reused(service, change, part):
    preflight(service)
    why = verdict(service, **change)
    assert why is not None and f"another {part}" in why


def test_another_robot_description_or_start_state_is_never_reused(service):
    preflight(service)
    kept = service.preflights.kept
    assert kept is not None
    real = kept.key
    kept.key = PreflightKey(real.protocol, real.patient, canonical_sha256("other robot"),
                            real.start)
    assert "another robot" in (verdict(service) or "")
    kept.key = PreflightKey(real.protocol, real.patient, real.robot, canonical_sha256("x"))
    assert "another start" in (verdict(service) or "")
    kept.key = real
    assert verdict(service) is None


def test_only_the_client_that_asked_reuses_it(service):
    preflight(service, client="gui")
    assert "another client" in (verdict(service, client="cli") or "")


def test_it_expires(service):
    preflight(service)
    service.clock.t += 299.0
    assert verdict(service) is None
    service.clock.t += 2.0
    assert "expired" in (verdict(service) or "")


def test_another_preflight_replaces_it_and_a_refused_one_leaves_none(service):
    first = preflight(service)
    second = preflight(service, doc={**DOC, "cycles": 5})
    assert service.preflights.kept.id == second["preflight_id"] != first["preflight_id"]
    assert "another protocol" in (verdict(service) or "")
    with pytest.raises(ProtocolValidationError):
        preflight(service, doc={**DOC, "refuse": True})
    assert service.preflights.kept is None
    assert "refused" in (verdict(service, doc={**DOC, "cycles": 5}) or "")


def test_a_change_of_owner_drops_it_but_the_askers_own_take_over_does_not(service):
    preflight(service, client="gui")
    service.control_acquire("gui", "clinician")      # the GUI's flow: check, take control
    assert verdict(service) is None
    service.control_release("gui")
    assert "released" in (verdict(service) or "")

    preflight(service, client="gui")
    service.control_acquire("other", "engineer")
    assert "taken by 'engineer'" in (verdict(service) or "")
    service.control_release("other")


def test_a_fault_or_failover_since_the_preflight_drops_it(service):
    pl = service.pl
    for kind in ("warn", "fault", "failover"):
        preflight(service)
        pl.events.append(SafetyEvent(t=1.0, kind=kind, cause="test_cause",
                                     reaction=Reaction.SOFT_STOP if kind == "fault"
                                     else Reaction.WARN, message="injected"))
        why = verdict(service)
        if kind == "warn":
            assert why is None              # a warning changes nothing the pre-flight used
        else:
            assert why is not None and f"a {kind} (test_cause)" in why


def test_the_robot_moved_away_drops_it(service):
    q = service.pl.graph.component("encoders").outputs["q"].data
    preflight(service)
    q[1] += 0.9 * POSE_TOLERANCE_M                  # within: encoder jitter, nothing moved
    assert verdict(service) is None
    q[1] += 0.2 * POSE_TOLERANCE_M
    why = verdict(service) or ""
    assert "the robot moved 0.55 mm" in why


def test_gains_or_a_motion_program_drop_it(service, monkeypatch):
    service.control_acquire("gui", "clinician")
    preflight(service)
    # The loop is not running here: the gains are taken as if at the next boundary.
    monkeypatch.setattr(service.pl.loop, "set_params",
                        lambda slot, **v: SimpleNamespace(result=lambda timeout: None))
    service.set_gains("gui", service.pl.controller.name, {})
    assert "gains changed" in (verdict(service) or "")
    preflight(service)
    epoch = service.pl.reference.epoch
    service.pl.reference.epoch = epoch + 1         # a program ran (e.g. from another path)
    try:
        assert "a motion ran" in (verdict(service) or "")
    finally:
        service.pl.reference.epoch = epoch
    assert verdict(service) is None
    service.preflights.drop("test")
    service.control_release("gui")


def test_reuse_disabled_keeps_nothing(loop):
    pl, tap = loop
    svc = RtService(pl, RtConfig(loop_mode="fast", preflight_reuse_s=0.0), tap,
                    sessions=CountingSessions())  # type: ignore[arg-type]
    assert preflight(svc)["kept_for_s"] == 0.0
    assert svc.preflights.kept is None and "disabled" in (verdict(svc) or "")


def test_session_start_takes_it_once(service, tmp_path):
    """The decision is made when session_start is received; the kept pre-flight is taken
    (a start moves the robot) whether or not it was used."""
    service.control_acquire("gui", "clinician")
    preflight(service)
    from rt.ipc.messages import RecordArgs
    service._start = lambda s, prep: (_ for _ in ()).throw(  # type: ignore[method-assign]
        ProtocolValidationError("stop here: no loop running"))
    service.session_start("gui", dict(DOC), PatientArgs(**PATIENT), RecordArgs(dir=str(tmp_path)))
    assert service.preflights.kept is None
    assert "taken by a session start" in (verdict(service) or "")
    assert service.sessions.calls == 1           # the start did not pre-flight again
    end = time.monotonic() + 5.0
    while service.session is not None and time.monotonic() < end:
        time.sleep(0.01)
    service.control_release("gui")


def test_session_start_pre_flights_again_when_its_data_file_changed(service, tmp_path):
    service.control_acquire("gui", "clinician")
    preflight(service)
    kept = service.preflights.kept
    kept.prepared.data_ok = False
    seen: list[Any] = []
    from rt.ipc.messages import RecordArgs

    def start(s, prep):
        seen.append((s.preflight_run, s.not_reused))
        raise ProtocolValidationError("stop here")
    service._start = start  # type: ignore[method-assign]
    service.session_start("gui", dict(DOC), PatientArgs(**PATIENT), RecordArgs(dir=str(tmp_path)))
    end = time.monotonic() + 5.0
    while not seen and time.monotonic() < end:
        time.sleep(0.01)
    run, why = seen[0]
    assert service.sessions.calls == 2 and run["reused"] is False
    assert "data file" in why and run["id"] != kept.id
    while service.session is not None and time.monotonic() < end:
        time.sleep(0.01)
    service.control_release("gui")


def test_key_digest_is_canonical_json():
    assert canonical_sha256({"a": 1, "b": [1, 2]}) == canonical_sha256({"b": [1, 2], "a": 1})
    assert canonical_sha256({"a": 1}) != canonical_sha256({"a": 1.0})
    with pytest.raises(ValueError):
        canonical_sha256({"a": float("nan")})
    assert canonical_sha256(np.arange(3)) == canonical_sha256([0, 1, 2])
