"""Campaign trials run by the RT process (``talus calibrate run --backend rt``).

The client's side of :mod:`calibration.rt_program`: it takes control of the robot, heartbeats,
and for each trial sends ``run calibration_push {plan, trial, out}``; the RT process plays the
force-controlled push under its supervisor and writes the trial's rows to ``out`` (a temporary
folder of this runner, on the file system both share, as session recordings are). The runner
turns them into a :class:`~calibration.trial.TrialData`: the ATI and encoders as the loop saw
them, and the plate's channels either

* from the twin's true contact the RT process recorded, through the twin plate on the plate's
  own clock, exactly as the in-process twin runner does
  (:func:`calibration.twin_runner.trial_from_rows`; the default on the twin), or
* from the plate's DAQ, which this client reads on a thread of its own on the plate's clock
  while the RT process pushes (:mod:`calibration.plate_daq`; :func:`trial_from_acquisition`):
  a real plate's comedi card on the rig, or the twin plate behind the same driver
  (:mod:`calibration.twin_plate_daq`). The robot's rows then stay on the RT loop's clock,
  continuous over the campaign, so that the clock model's offset and drift (cross-correlation,
  :mod:`calibration.alignment`) relate two real clocks.

Before a site's first trial the plate is moved there: by the operator on the rig (the CLI
waits; the camera confirms the pose, :mod:`calibration.operator`), simulated on the twin.
"""
from __future__ import annotations

import json
import math
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from calibration.plan import Plan, Trial, expand, force_profile
from calibration.plate import PlateDescription
from calibration.plate_daq import PlateAcquisition
from calibration.registration import Registration
from calibration.rt_program import PLATE_DAQ_CLIENT, PROGRAM_NAME, profile_digest
from calibration.site_moves import SiteMoves
from calibration.trial import TrialData, TrialRunner
from calibration.twin_plate import TwinPlate
from calibration.twin_plate_daq import TwinPlateDaq
from calibration.twin_runner import (
    TOOL_LENGTH_M,
    _SiteMoves,
    sensor_poses,
    site_name,
    tip_points_B,
    trial_from_rows,
)
from rt.devices.interfaces import ForcePlate
from rt.errors import HardwareError, InputError, SafetyTrip
from rt.ipc.client import RtUnavailableError
from rt.model import RobotModel

#: Heartbeat period of the runner's client (s): well inside the RT process's timeout.
HEARTBEAT_S = 0.05
#: How long the move to a trial's pose holds it before the push (s): the robot settles.
MOVE_HOLD_S = 0.3
#: How often the runner looks for the trial file (s).
POLL_S = 0.1
#: Beyond the program's duration, how long the runner waits for the trial file (s): the
#: approach and the return at the sequencer's limits, plus the RT process's own margin.
WAIT_MARGIN_S = 45.0


class RtTrialRunner(TrialRunner):
    """Trials as ``calibration_push`` programs of the RT process at ``endpoint``.

    The plate's channels come from one of (module docstring):

    * ``daq`` None: the RT process's twin records the true contact; the twin plate turns it
      into channels here (twin only);
    * ``daq`` a :class:`calibration.twin_plate_daq.TwinPlateDaq`: the twin plate behind the
      comedi driver, acquired here on the plate's clock (the rig's path, on the twin);
    * ``daq`` a real ``ForcePlate`` device: the rig's plate DAQ, acquired here; the operator
      moves the plate (``operator``) and ``camera`` confirms each move.

    ``trials``: the trials that may be run (default: the plan's; a verification passes its
    own).

    ``client_id``: act as that client of the RT process (a GUI connected to it runs its
    calibration through this runner under its own id): when that client already controls the
    robot the runner borrows its control (no ``control_acquire``, which would rename the owner,
    and no ``control_release`` at the end: the client keeps what it had); otherwise the runner
    takes control under that id and gives it back when it closes, as it does under its own.
    Either way it heartbeats while it runs (the borrowed owner's own heartbeat may be a GUI's,
    which stops when that GUI stalls; the runner's thread keeps the robot's owner present while
    its trials move it).
    """

    def __init__(self, plate: PlateDescription, twin_plate: TwinPlate | None, plan: Plan,
                 endpoint: str, registration: str = "camera", seed: int = 0,
                 model: RobotModel | None = None,
                 level_sigma_rad: float | None = math.radians(0.1),
                 timeout_s: float = 5.0, daq: ForcePlate | TwinPlateDaq | None = None,
                 moves: SiteMoves | None = None,
                 trials: list[Trial] | None = None, client_id: str | None = None,
                 name: str = "talus calibrate run") -> None:
        from rt.ipc.client import RtClient, default_client_id

        if daq is None and twin_plate is None:
            raise InputError("the rt backend needs the plate's DAQ (--plate-daq) unless the "
                             "RT process's twin records the plate")
        self.plate = plate
        self.twin_plate = twin_plate
        self.plan = plan
        self.trials: dict[str, Trial] = {t.id: t for t in (
            trials if trials is not None else expand(plan, plate.size_m))}
        self.model = model or RobotModel.load()
        self.moves: SiteMoves = moves or _SiteMoves(registration, seed, level_sigma_rad)
        self.robot_time_s = 0.0
        self._t_offset = 0.0
        self.daq = daq
        self.acquisition: PlateAcquisition | None = None
        if daq is not None:
            device = daq.device if isinstance(daq, TwinPlateDaq) else daq
            clock = daq.clock if isinstance(daq, TwinPlateDaq) else time.monotonic
            self.acquisition = PlateAcquisition(device, plate.n_channels, plate.sample_rate_hz,
                                                clock)
        self.folder = Path(tempfile.mkdtemp(prefix="talus-calibration-"))
        self.client = RtClient(endpoint, client_id=client_id or default_client_id("calibrate"),
                               timeout_s=timeout_s)
        #: True when the runner took control (and gives it back on close); False when it
        #: borrowed the control its ``client_id`` already had.
        self.took_control = True
        try:
            if client_id is not None and _owner_id(self.client.status()) == client_id:
                self.took_control = False
            else:
                self.client.control_acquire(name)
        except RtUnavailableError:
            self.close(release=False)
            raise RtUnavailableError(f"no RT process answers at {endpoint}; start one with "
                                     "`talus rt serve` (on the twin) first") from None
        except BaseException:
            self.close(release=False)
            raise
        self.client.start_heartbeat(HEARTBEAT_S)

    def run(self, trial_id: str, site_xy_m: tuple[float, float], pose: tuple[float, float, float],
            profile_n: np.ndarray, dt: float, tilt_rad: np.ndarray | None = None) -> TrialData:
        # The RT process recomputes the force and the tilt from the plan (IPC messages are
        # bounded); the force's digest is checked, the tilt is the same function's.
        trial = self.trials.get(trial_id)
        if trial is None:
            raise InputError(f"trial {trial_id!r} is not in the plan {self.plan.name!r}")
        out = self.folder / f"{trial_id}.npz"
        out.unlink(missing_ok=True)
        expected = profile_digest(force_profile(self.plan, trial, dt))
        if profile_digest(profile_n) != expected:
            raise InputError(f"trial {trial_id}: its profile is not the plan's")
        model = self.model
        p_lvl, R_lvl = sensor_poses(model, np.array([model.kin.ik(pose[0], 0.0, 0.0).q]))
        tip_lvl = tip_points_B(p_lvl, R_lvl, TOOL_LENGTH_M)[0]
        # The operator moves the plate to the site (the robot resting clear below it since the
        # last trial), and the camera confirms the move, before the robot comes to the pose.
        T_true, registered = self.moves.place(tip_lvl, site_xy_m, site_name(trial_id))
        self._move_to(trial_id, pose)
        params: dict[str, object] = {"plan": self.plan.model_dump(mode="json"),
                                     "trial": trial.model_dump(mode="json"), "out": str(out)}
        acq = self.acquisition
        if acq is not None:
            params["plate_daq"] = PLATE_DAQ_CLIENT
            if isinstance(self.daq, TwinPlateDaq):
                self.daq.place(T_true)
                params["twin_contact_shm"] = self.daq.wire_name
            acq.start(len(profile_n) * dt + 2.0 * WAIT_MARGIN_S)
        # Subscribed before the program starts (a PUB/SUB subscription takes a moment to reach
        # the server), only when someone watches the trial live.
        live = _LiveTelemetry(self, trial_id, loop_clock=acq is not None, dt=dt,
                              steps=len(profile_n) - 1) if self.samples is not None else None
        try:
            started = self.client.run(PROGRAM_NAME, params)
            if live is not None:
                live.started()
            deadline = time.monotonic() + float(started["duration_s"]) + WAIT_MARGIN_S
            while not out.exists():
                if time.monotonic() > deadline:
                    raise HardwareError(f"trial {trial_id}: the RT process wrote no recording "
                                        f"within {started['duration_s'] + WAIT_MARGIN_S:.0f} s")
                if live is not None:
                    live.pump(POLL_S)
                else:
                    time.sleep(POLL_S)
        except BaseException:
            if acq is not None and acq.running:
                try:
                    acq.stop()
                except HardwareError:
                    pass      # the trial failed already; that failure is the one to report
            raise
        finally:
            if live is not None:
                live.close()
        plate_scans = acq.stop() if acq is not None else None
        with np.load(out, allow_pickle=False) as z:
            robot, contact = z["robot"], z["contact"]
            meta = json.loads(str(z["meta"]))
        out.unlink()
        if meta["outcome"] != "completed":
            causes = ", ".join(meta.get("causes", [])) or "no cause recorded"
            events = "; ".join(f"{e.get('cause')}: {e.get('message')}"
                               for e in meta.get("events", [])
                               if e.get("reaction") in ("soft_stop", "hard_stop"))
            raise SafetyTrip(f"trial {trial_id}: {meta['outcome']} in the RT process "
                             f"({causes}{'; ' + events if events else ''}); reset the faults "
                             "(talus rt reset) and run the remaining trials into a new folder")
        if abs(float(meta["dt"]) - dt) > 1e-12:
            raise HardwareError(f"trial {trial_id}: the RT process's loop runs at "
                                f"{1.0 / float(meta['dt']):g} Hz; campaigns are recorded at "
                                f"{1.0 / dt:g} Hz (rate_hz in its config)")
        if meta["profile_sha256"] != expected:
            raise HardwareError(f"trial {trial_id}: the RT process played another profile")
        if plate_scans is not None:
            data = trial_from_acquisition(trial_id, model, robot, plate_scans[0],
                                          plate_scans[1], registered, dt)
        else:
            assert self.twin_plate is not None
            rows, true_rows = _common_instants(trial_id, robot, contact)
            data = trial_from_rows(trial_id, model, rows, true_rows, T_true, registered,
                                   self.twin_plate, self._t_offset)
            self._t_offset = float(data.t_robot[-1]) + 2.0
        self.robot_time_s += float(data.t_robot[-1] - data.t_robot[0])
        return data

    def _move_to(self, trial_id: str, pose: tuple[float, float, float]) -> None:
        """Bring the robot to the trial's pose (position control) and wait until it rests
        there: the push starts from rest at its pose, the plate above the tool."""
        z, roll, pitch = pose
        started = self.client.run("move", {"z": z, "roll": roll, "pitch": pitch,
                                           "hold_s": MOVE_HOLD_S})
        t0 = time.monotonic()
        deadline = t0 + float(started["duration_s"]) + WAIT_MARGIN_S
        seen = False      # the loop takes the request at its next cycle boundary
        while True:
            time.sleep(POLL_S)
            st = self.client.status()
            if st["state"] != "run":
                # The failed blocks with their reasons: a ``component_failed`` stop names
                # only its cause in ``latched``.
                failed = "".join(f"; {name}: {why}"
                                 for name, why in (st.get("failed_blocks") or {}).items())
                raise SafetyTrip(f"trial {trial_id}: the robot stopped moving to the trial's "
                                 f"pose ({', '.join(st['causes']) or st['state']}: "
                                 f"{json.dumps(st.get('latched'))}{failed})")
            if st["phase_name"] != "rest":
                seen = True
            elif seen or time.monotonic() - t0 > float(started["duration_s"]) + 2.0:
                return
            if time.monotonic() > deadline:
                raise HardwareError(f"trial {trial_id}: the robot did not reach the trial's "
                                    "pose in time")

    def close(self, release: bool = True) -> None:
        """Stop heartbeating and give control back (``release``, and only when the runner
        took it: a borrowed control stays with its client); the temporary folder, the DAQ
        and the site moves are closed."""
        try:
            if release:
                self.client.stop_heartbeat()
                if self.took_control:
                    try:
                        self.client.control_release()
                    except (InputError, RtUnavailableError):
                        pass    # still moving or gone: control lapses with the heartbeat
        finally:
            try:
                self.client.close()
            finally:
                shutil.rmtree(self.folder, ignore_errors=True)
                if self.acquisition is not None and self.acquisition.running:
                    try:
                        self.acquisition.stop()
                    except HardwareError:
                        pass          # closing: the trial that used it reported already
                if self.daq is not None:
                    self.daq.close()
                close_moves = getattr(self.moves, "close", None)
                if close_moves is not None:
                    close_moves()


def _owner_id(status: dict) -> str | None:
    """The client id of the robot's owner in a ``status`` reply (None: nobody)."""
    owner = status.get("owner")
    client = owner.get("client") if isinstance(owner, dict) else None
    return client if isinstance(client, str) else None


def _common_instants(trial_id: str, robot: np.ndarray, contact: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The robot's rows while the program played, and the contact at those instants (both are
    sampled by the same loop; interpolation only bridges a row the tap's ring skipped)."""
    if len(contact) < 10 or len(robot) < 10:
        raise HardwareError(f"trial {trial_id}: the RT process recorded too little "
                            f"({len(robot)} loop rows, {len(contact)} contact rows)")
    inside = (robot[:, 0] >= contact[0, 0] - 1e-9) & (robot[:, 0] <= contact[-1, 0] + 1e-9)
    rows = robot[inside]
    if len(rows) < 0.9 * len(contact):
        raise HardwareError(f"trial {trial_id}: the loop's rows cover {len(rows)} of the "
                            f"{len(contact)} cycles played (the session tap overflowed?)")
    true_rows = np.column_stack([rows[:, 0]] + [np.interp(rows[:, 0], contact[:, 0],
                                                          contact[:, k]) for k in range(1, 10)])
    return rows, true_rows


#: The longest gap tolerated between the loop's recorded rows (s): a late loop skips cycles
#: (92 ms seen at a load of 14; the fit drops blocks across such gaps,
#: ``dataset.MAX_ROBOT_GAP_S``); beyond this, rows are missing (the session tap overflowed).
MAX_ROW_GAP_S = 0.5


def trial_from_acquisition(trial_id: str, model: RobotModel, robot: np.ndarray,
                           t_plate: np.ndarray, channels: np.ndarray,
                           registered: Registration, dt: float) -> TrialData:
    """A trial from the loop's rows (t, ATI wrench 6, q 3, force reference 3, phase) on the RT
    loop's clock and the plate's scans on the plate's clock, as acquired: the clocks are
    related later, by cross-correlation over the campaign (:mod:`calibration.alignment`)."""
    finite = np.isfinite(robot[:, 1:7]).all(axis=1) if len(robot) else np.zeros(0, bool)
    if not finite.any():
        raise HardwareError(f"trial {trial_id}: the ATI sensor gave no reading")
    rows = robot[int(np.argmax(finite)):]
    if not np.isfinite(rows[:, 1:7]).all():
        raise HardwareError(f"trial {trial_id}: the ATI sensor's readings stopped during "
                            "the trial (NaN); repeat it")
    gaps = np.diff(rows[:, 0])
    if len(rows) < 10 or np.any(gaps <= 0.0) or float(gaps.max()) > max(MAX_ROW_GAP_S, 5 * dt):
        raise HardwareError(f"trial {trial_id}: the RT process's rows are incomplete (a gap of "
                            f"{float(gaps.max()) if len(gaps) else 0.0:.3f} s: the loop stalled "
                            "or its session tap overflowed); repeat the trial")
    if len(t_plate) < 10:
        raise HardwareError(f"trial {trial_id}: the plate DAQ recorded {len(t_plate)} scans")
    p_BS, R_BS = sensor_poses(model, rows[:, 7:10])
    return TrialData(trial_id, rows[:, 0].copy(), rows[:, 1:7].copy(), p_BS, R_BS,
                     rows[:, 10].copy(), np.asarray(t_plate, float),
                     np.asarray(channels, float), registered.T_BF,
                     registered.sigma_translation_m, registered.sigma_rotation_rad,
                     TOOL_LENGTH_M)


class _LiveTelemetry:
    """A running trial's samples as the RT process's telemetry shows them (≈ 60 per second),
    handed to the runner's :attr:`~calibration.trial.TrialRunner.samples` block by block on the
    runner's thread while the trial runs; the trial's file, written at its end, is the record.

    On the file's clock, within one telemetry period (≈ 17 ms): with the plate's DAQ the file
    keeps the loop's own clock (:func:`trial_from_acquisition`), and so do these samples; on
    the twin plate the file starts at the program's first played cycle with the runner's
    offset added (:func:`_common_instants`, ``trial_from_rows``), and these samples are placed
    on it by the program's progress: the first telemetry of the played phase may come late (the
    publisher's thread waits for the loop's lock; 0.14 s seen at load), so its loop time is not
    the first played cycle's. With ``progress`` = k / ``steps`` (``reference.progress``: k
    samples played, the first on the cycle that ended the approach), that cycle's loop time is
    the message's minus (k − 1) periods."""

    def __init__(self, runner: RtTrialRunner, trial_id: str, loop_clock: bool, dt: float,
                 steps: int) -> None:
        self.runner = runner
        self.trial_id = trial_id
        self.loop_clock = loop_clock
        self.dt = dt
        self.steps = max(1, steps)
        self.sub = runner.client.subscribe(["telemetry"])
        self._running = False
        self._t_first: float | None = None

    def started(self) -> None:
        """The program was requested: samples from now on are the trial's."""
        while self.sub.recv(0.0) is not None:      # what was published before it
            pass
        self._running = True

    def pump(self, seconds: float) -> None:
        """Receive for ``seconds``, then publish what arrived as one block."""
        end = time.monotonic() + seconds
        t, ref, fz = [], [], []
        while True:
            msg = self.sub.recv(max(0.0, end - time.monotonic()))
            if msg is None:
                break
            force_n, t_loop = msg.get("force_n"), msg.get("t")
            if not self._running or force_n is None or t_loop is None:
                continue                          # the ATI has no reading yet
            if not self.loop_clock and msg.get("phase") != "play":
                continue                          # the twin plate's file holds the play only
            if self._t_first is None:
                played = round(float(msg.get("progress") or 0.0) * self.steps)
                self._t_first = float(t_loop) - max(0, played - 1) * self.dt
            t.append(float(t_loop) if self.loop_clock
                     else float(t_loop) - self._t_first + self.runner._t_offset)
            ref.append(float(msg.get("force_ref_n") or 0.0))
            fz.append(-float(force_n))            # the ATI's S-axis z (force_n is −Fz)
        if t:
            self.runner.publish(self.trial_id, np.array(t), np.array(ref), np.array(fz))

    def close(self) -> None:
        self.sub.close()
