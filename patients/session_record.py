"""A therapy session run for a patient and stored in the clinical record.

``run_for_patient`` is the glue ``talus session run --patient CODE`` calls: it opens the session
row (the protocol and the limits in force, snapshotted), hands the runner what the session
needs, and closes the row with the outcome, who or which fault stopped it, the summary and the
recording's path and sha256. A refused pre-flight, a crash or Ctrl-C close the row too: no
session stays "running" because of us.

The runner is ``runner(started, recording) -> summary`` where ``started`` is
``ClinicalRecord.start_session``'s dict and ``rt_patient(started)`` the RT process's
``session_start.patient`` (``{"id": code, "weight_kg", "limits"}``): the RT client
(``protocols.session_cli.run_remote``) or, for tests and benchmarks, ``twin_runner`` on the
in-process twin. The summary is ``protocols/session.py``'s dict (``completed``, ``stops``,
``recording: {path, sha256}``).
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from patients.errors import InputError
from patients.models import Outcome
from patients.service import LIMIT_FIELDS, Actor, ClinicalRecord
from rt.errors import ProtocolValidationError

Runner = Callable[[dict[str, Any], Path | None], dict[str, Any]]

#: Supervisor causes a person triggers (rt/safety/supervisor.py): who, for ``stopped_by``.
PERSON_CAUSES = {"hand_stop": "patient", "stop_client": "operator",
                 "estop_hardware": "operator"}


def rt_patient(started: dict[str, Any]) -> dict[str, Any]:
    """The RT process's ``session_start.patient`` for a started session: the pseudonymous code
    (it names the recording and goes in its metadata), the body mass and the limits in force."""
    out = {"id": started["patient"], "weight_kg": started["body_mass_kg"],
           "limits": {k: started["limits"][k] for k in LIMIT_FIELDS}}
    if started.get("ankle") is not None:
        out["ankle"] = started["ankle"]      # where the ankle centre is (rt.model.ankle)
    return out


def twin_runner(protocol_path: Path, **run_options: Any) -> Runner:
    """Run on the in-process twin (``protocols.session.run_session``) with the stored limits
    and body mass; ``run_options`` go to ``run_session``."""
    def run(started: dict[str, Any], recording: Path | None) -> dict[str, Any]:
        from protocols.session import SessionSetup, run_session
        from rt.model.ankle import AnkleSetup
        from rt.safety.limits import PatientLimits
        patient = rt_patient(started)
        ankle = patient.get("ankle")
        setup = SessionSetup(Path(protocol_path), patient_weight_kg=patient["weight_kg"],
                             patient_limits=PatientLimits(**patient["limits"]),
                             ankle=None if ankle is None else AnkleSetup(**ankle))
        return run_session(setup, recording, **run_options)
    return run


def outcome_of(summary: dict[str, Any]) -> tuple[Outcome, str | None]:
    """Outcome and ``stopped_by`` from a session summary (protocols/session.py's dict)."""
    stops = summary.get("stops") or []
    if summary.get("completed") and not stops:
        return Outcome.COMPLETED, None
    if summary.get("outcome") == "aborted" and not stops:
        # session_abort (anyone's soft stop of the session) or the RT process shutting down.
        return Outcome.STOPPED_BY_USER, f"operator: aborted by {summary.get('aborted_by')}"
    if not stops:
        return Outcome.STOPPED_BY_FAULT, "did not finish (no supervisor stop recorded)"
    first = stops[0]
    cause = str(first.get("cause", "unknown"))
    who = PERSON_CAUSES.get(cause) or ("operator" if cause.startswith("estop_") else None)
    if who is not None:
        return Outcome.STOPPED_BY_USER, f"{who}: {cause}"
    return Outcome.STOPPED_BY_FAULT, f"{cause}: {first.get('message', '')}".strip(": ")


def run_for_patient(record: ClinicalRecord, actor: Actor, code: str, protocol_path: Path,
                    recording: Path | None, runner: Runner,
                    plan_id: int | None = None) -> dict[str, Any]:
    """Run ``protocol_path`` for patient ``code`` with ``runner`` and store it; returns the
    stored session (``ClinicalRecord.get_session``'s dict without the YAML)."""
    try:
        text = Path(protocol_path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read {protocol_path}: {exc}") from None
    started = record.start_session(actor, code, text, plan_id=plan_id)
    uid = started["uid"]
    try:
        summary = runner(started, recording)
    except ProtocolValidationError as exc:
        record.finish_session(actor, uid, Outcome.REFUSED, stopped_by=f"pre-flight: {exc}"[:200])
        raise
    except KeyboardInterrupt:
        record.finish_session(actor, uid, Outcome.STOPPED_BY_USER,
                              stopped_by=f"operator: {actor.username} interrupted the program")
        raise
    except BaseException as exc:
        record.finish_session(actor, uid, Outcome.STOPPED_BY_FAULT,
                              stopped_by=f"software: {type(exc).__name__}: {exc}"[:200])
        raise
    outcome, stopped_by = outcome_of(summary)
    rec = summary.get("recording") or {}
    return record.finish_session(actor, uid, outcome, stopped_by=stopped_by, summary=summary,
                                 recording_path=rec.get("path"),
                                 recording_sha256=rec.get("sha256"))
