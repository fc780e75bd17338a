"""The protocols package's side of a session in the RT process (``rt.sessions``): validate the
protocol document a client sent, build its generator, pre-flight it on the twin, and give the
RT process what it needs to run, record and summarize it.

All of that is CPU-heavy (a 60 s protocol's pre-flight simulates it on the twin through the
whole loop: tens of seconds of CPU; its references are compiled, milliseconds): it runs in a worker *process* (spawned once, kept warm), never in a
thread of the RT process, whose loop would then share the GIL with it and miss its deadlines.
The validated generator comes back pickled, its arrays (a 60 s protocol's reference table is
2 MB) in shared memory (:func:`to_shared` / :func:`from_shared`) and its robot kinematics by
reference (the RT process has the same, built from the description it sent): unpickled in the
RT process they cost a page mapping, not copies and 65 pydantic models rebuilt with the GIL
held (13 ms measured under load, a stall of the loop; ``bench/session_transfer.py``).

Data files a protocol names (a gait record, a playback CSV) resolve in the protocol library
directory when relative; a client that loaded its protocol from elsewhere sends them absolute
(:func:`protocol_document`).
"""
from __future__ import annotations

import contextlib
import hashlib
import io
import mmap
import multiprocessing
import os
import pickle
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path, PurePath
from typing import Any

from protocols.generators import make_generator
from protocols.library import LIBRARY_DIR, load_protocol
from protocols.reference_kernels import warm_up
from protocols.schema import GaitReplay, PositionPlayback, ProtocolModel, validate_protocol_data
from protocols.session import (
    SessionFigures,
    SessionSetup,
    preflight,
    protocol_limits_of,
    start_pose,
)
from rt.errors import InputError, ProtocolValidationError
from rt.model import RobotModel
from rt.model.ankle import AnkleSetup
from rt.references.program import Program
from rt.safety.limits import ProtocolLimits
from rt.sessions import PatientInfo, SessionContext

#: Where a session_start's protocol is said to come from in messages.
DOCUMENT_SOURCE = "session_start.protocol"
#: The worker's nice value. 0: the RT process's threads run above every ordinary process
#: (``rt.engine.rt_hygiene.gil_peer``), so the worker's seconds at 100 % of a core cannot
#: delay them whatever its nice; a positive nice would only starve the pre-flight on a busy
#: machine (measured: nice 10 at load 19 took a 12 s sine's pre-flight past 70 s and a
#: session_start past its 120 s). Whatever the RT process's own policy, the worker starts as
#: an ordinary process (SCHED_RESET_ON_FORK, ``ordinary_process_priority``).
WORKER_NICE = 0


def _data_field(protocol: ProtocolModel) -> str | None:
    """The name of the field holding a data file's path, if the kind has one."""
    if isinstance(protocol, GaitReplay):
        return "source"
    if isinstance(protocol, PositionPlayback):
        return "file"
    return None


def protocol_document(path: str | Path) -> dict[str, Any]:
    """A protocol file as the JSON object ``session_start`` sends: validated here first (errors
    name the file and the line), its data file's path made absolute."""
    protocol = load_protocol(path)
    doc = protocol.model_dump(mode="json")
    name = _data_field(protocol)
    if name is not None and not PurePath(doc[name]).is_absolute():
        base = Path(path).resolve().parent
        doc[name] = str(base / doc[name])
    return doc


def _sha256(path: Path) -> str | None:
    try:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
        return h.hexdigest()
    except OSError:
        return None


@dataclass
class ProtocolSession:
    """A prepared protocol session (``rt.sessions.PreparedSession``). ``model`` is the RT
    process's (set after the session came back from the worker process)."""

    protocol: ProtocolModel
    program: Program
    preflight: dict[str, Any]
    start_pose: tuple[float, float, float]
    metadata: dict[str, Any] = field(default_factory=dict)
    model: RobotModel | None = None

    @property
    def name(self) -> str:
        return self.protocol.name

    @property
    def kind(self) -> str:
        return self.protocol.kind

    @property
    def protocol_limits(self) -> ProtocolLimits | None:
        return protocol_limits_of(self.protocol)

    def inputs_unchanged(self) -> bool:
        """The data file this session was prepared from (a gait record, a playback CSV) still
        has the sha256 it had then: a kept pre-flight (``rt.preflight_reuse``) of a file
        edited since must not be reused."""
        data = self.metadata.get("data_file")
        if not data:
            return True
        return _sha256(Path(data["path"])) == data["sha256"]

    def figures(self, preload_n: float) -> SessionFigures:
        assert self.model is not None
        ankle = self.metadata.get("ankle")
        return SessionFigures.for_protocol(
            self.protocol, self.model, preload_n, info=self.metadata.get("source"),
            ankle=None if ankle is None else AnkleSetup.model_validate(ankle))


class ProtocolSessions:
    """The RT process's session factory (``rt.sessions.SessionFactory``): each ``prepare``
    runs :func:`prepare_session` in the worker process."""

    def __init__(self, base_dir: Path = LIBRARY_DIR, in_process: bool = False,
                 worker_nice: int = WORKER_NICE):
        self.base_dir = base_dir
        self.in_process = in_process
        self.worker_nice = int(worker_nice)
        self._pool: ProcessPoolExecutor | None = None
        self._lock = threading.Lock()

    def _worker(self) -> ProcessPoolExecutor:
        with self._lock:
            if self._pool is None:
                # spawn: a fresh interpreter, nothing inherited from the RT process's threads.
                self._pool = ProcessPoolExecutor(
                    max_workers=1, mp_context=multiprocessing.get_context("spawn"),
                    initializer=_worker_init, initargs=(os.getpid(), self.worker_nice))
            return self._pool

    def warm(self, description: Any) -> None:
        """Start the worker process and build its model now, so the first session's pre-flight
        does not pay for it (returns at once)."""
        if not self.in_process:
            self._worker().submit(_warmed, description)

    def prepare(self, protocol: dict[str, Any], patient: PatientInfo,
                context: SessionContext) -> ProtocolSession:
        args = (protocol, patient, context.model.description, context.robot_limits,
                context.rate_hz, self.base_dir)
        if self.in_process:
            session = prepare_session(*args)
        else:
            session = from_shared(self._worker().submit(_prepare_shared, *args).result(),
                                  {KINEMATICS_REF: context.model.kin})
        session.model = context.model
        return session

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)


#: How often the worker looks whether the RT process is still its parent (s).
PARENT_POLL_S = 0.5


def _worker_init(parent_pid: int, nice: int) -> None:
    """The worker's initializer: an ordinary process at ``nice`` whatever it inherited, and
    ended with its RT process (:func:`_end_with_parent`)."""
    from rt.engine.rt_hygiene import ordinary_process_priority

    ordinary_process_priority(nice)
    _end_with_parent(parent_pid)


def _end_with_parent(parent_pid: int) -> None:
    """The worker's initializer: end the worker when the RT process is gone.

    Why: a killed RT process (SIGKILL, a crash) never shuts its pool down, and a spawned worker
    blocked on its call queue would live on as an orphan holding a robot model (≈ 250 MB).
    ``prctl(PR_SET_PDEATHSIG)`` would follow the spawning *thread*, not the process, so the
    worker polls its parent instead (an orphan is re-parented to init or a subreaper)."""
    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        os._exit(0)                            # nothing to flush: the work was for the parent

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


# ------------------------------------------------------------------ the transfer
#: Arrays smaller than this travel inside the pickle (a segment per session is not worth it).
SHARED_MIN_BYTES = 64 * 1024
_SHM_DIR = Path("/dev/shm")
_ALIGN = 64


@dataclass(frozen=True)
class SharedPayload:
    """A pickled object (protocol 5) whose large buffers wait in one POSIX shared-memory
    segment: ``spans`` are each out-of-band buffer's (offset, length) in ``segment``, in the
    pickle's order; ``segment`` is None when no buffer was large enough."""

    pickled: bytes
    segment: str | None
    size: int
    spans: tuple[tuple[int, int], ...]
    #: Names of the objects sent by reference (the receiver supplies them).
    references: tuple[str, ...] = ()


class _Pickler(pickle.Pickler):
    def __init__(self, file: io.BytesIO, refs: dict[int, str], **kw: Any) -> None:
        super().__init__(file, protocol=5, **kw)
        self._refs = refs
        self.used: set[str] = set()

    def persistent_id(self, obj: Any) -> str | None:
        name = self._refs.get(id(obj))
        if name is not None:
            self.used.add(name)
        return name


class _Unpickler(pickle.Unpickler):
    def __init__(self, file: io.BytesIO, refs: dict[str, Any], **kw: Any) -> None:
        super().__init__(file, **kw)
        self._refs = refs

    def persistent_load(self, pid: Any) -> Any:
        try:
            return self._refs[pid]
        except (KeyError, TypeError):
            raise pickle.UnpicklingError(f"the receiver has no object {pid!r} to stand for "
                                         "the sender's") from None


def to_shared(obj: Any, min_bytes: int = SHARED_MIN_BYTES,
              references: dict[str, Any] | None = None) -> SharedPayload:
    """Pickle ``obj`` with its large contiguous buffers (numpy arrays) copied into a new
    shared-memory segment, which :func:`from_shared` maps and removes, and each object in
    ``references`` (name → object) sent as its name only. Run in the worker."""
    from multiprocessing import resource_tracker, shared_memory

    buffers: list[pickle.PickleBuffer] = []

    def out_of_band(buf: pickle.PickleBuffer) -> bool:
        if buf.raw().nbytes < min_bytes:
            return True                         # in band: inside the pickle
        buffers.append(buf)
        return False
    out = io.BytesIO()
    pickler = _Pickler(out, {id(v): k for k, v in (references or {}).items()},
                       buffer_callback=out_of_band)
    pickler.dump(obj)
    pickled, used = out.getvalue(), tuple(sorted(pickler.used))
    if not buffers:
        return SharedPayload(pickled, None, 0, (), used)
    spans, offset = [], 0
    for buf in buffers:
        n = buf.raw().nbytes
        spans.append((offset, n))
        offset += -(-n // _ALIGN) * _ALIGN
    shm = shared_memory.SharedMemory(create=True, size=max(offset, 1))
    try:
        target = shm.buf
        assert target is not None
        for buf, (start, n) in zip(buffers, spans, strict=True):
            target[start:start + n] = buf.raw().cast("B")
        # The RT process unlinks it once mapped: the worker's resource tracker must not.
        resource_tracker.unregister(shm._name, "shared_memory")  # type: ignore[attr-defined]
        name = shm.name
    except BaseException:
        shm.close()
        shm.unlink()
        raise
    shm.close()
    return SharedPayload(pickled, name, offset, tuple(spans), used)


def from_shared(payload: SharedPayload, references: dict[str, Any] | None = None) -> Any:
    """The object :func:`to_shared` sent, its large arrays views of the mapped segment (no
    copy), the segment's name removed at once (the mapping lives as long as the arrays), and
    the objects it sent by reference taken from ``references`` (name → this side's object)."""
    refs = references or {}
    missing = sorted(set(payload.references) - set(refs))
    if missing:
        discard_shared(payload)
        raise InputError(f"the prepared session refers to {missing}, which the RT process did "
                         "not supply")
    if payload.segment is None:
        return _Unpickler(io.BytesIO(payload.pickled), refs).load()
    path = _SHM_DIR / payload.segment.lstrip("/")
    fd = os.open(path, os.O_RDWR)
    try:
        mapped = mmap.mmap(fd, payload.size)
    finally:
        os.close(fd)
        os.unlink(path)
    view = memoryview(mapped)
    return _Unpickler(io.BytesIO(payload.pickled), refs,
                      buffers=[view[start:start + n] for start, n in payload.spans]).load()


def discard_shared(payload: SharedPayload) -> None:
    """Remove a payload's segment without reading it (a refused or abandoned transfer)."""
    if payload.segment is not None:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(_SHM_DIR / payload.segment.lstrip("/"))


#: The name the worker's kinematics travels under (the RT process supplies its own).
KINEMATICS_REF = "kinematics"


def _prepare_shared(protocol: dict[str, Any], patient: PatientInfo, description: Any,
                    *rest: Any) -> SharedPayload:
    """:func:`prepare_session` in the worker, sent back through shared memory, the robot's
    kinematics by reference."""
    session = prepare_session(protocol, patient, description, *rest)
    return to_shared(session, references={KINEMATICS_REF: _model_for(description).kin})


_MODELS: dict[str, RobotModel] = {}


def _model_for(description: Any) -> RobotModel:
    """The worker's model of ``description`` (built once per description)."""
    key = hashlib.sha256(description.model_dump_json().encode()).hexdigest()
    if key not in _MODELS:
        _MODELS[key] = RobotModel.from_description(description)
    return _MODELS[key]


def _warmed(description: Any) -> str:
    model = _model_for(description)
    # The compiled reference generation, loaded before the first protocol needs it.
    warm_up(model.kin.geom, model.kin.limits_array)
    return "ready"


def prepare_session(protocol: dict[str, Any], patient: PatientInfo, description: Any,
                    robot_limits: Any, rate_hz: float, base_dir: Path) -> ProtocolSession:
    """Validate, build, pre-flight (in the worker process); raises ProtocolValidationError."""
    model = _model_for(description)
    model_obj = validate_protocol_data(protocol, DOCUMENT_SOURCE)
    ankle = getattr(patient, "ankle", None)
    setup = SessionSetup(patient_weight_kg=patient.weight_kg, patient_limits=patient.limits,
                         robot_limits=robot_limits, protocol=model_obj, base_dir=base_dir,
                         ankle=ankle)
    pre = preflight(setup, model)
    gen = make_generator(model_obj, dt=1.0 / rate_hz, kinematics=model.kin,
                         patient_weight_kg=patient.weight_kg, base_dir=base_dir, ankle=ankle)
    report = gen.validate()
    if not report.ok:  # cannot differ from pre-flight's; kept as the program's own check
        raise ProtocolValidationError(f"{DOCUMENT_SOURCE}: " + "; ".join(report.violations))
    parameters = model_obj.model_dump(mode="json")
    meta: dict[str, Any] = {"protocol_name": model_obj.name,
                            "protocol_version": int(getattr(model_obj, "schema_version", 1)),
                            "parameters": parameters}
    name = _data_field(model_obj)
    if name is not None:
        data = Path(parameters[name])
        data = data if data.is_absolute() else base_dir / data
        meta["data_file"] = {"path": str(data), "sha256": _sha256(data)}
    if getattr(gen, "info", None):
        meta["source"] = gen.info          # traceability of a replayed record
    if ankle is not None:
        meta["ankle"] = ankle.model_dump()
    return ProtocolSession(model_obj, gen, pre["predicted"], start_pose(gen), meta)
