"""Trial runners on the digital twin.

* :class:`TwinTrialRunner` — the robot twin presses the twin plate through its ATI sensor under
  the product's force control (the protocol loop of ``rt.position_loop``: hybrid explicit
  force in z, angles held), at simulated time. The plate is the twin's ``plate`` environment
  (a stiff one-sided contact at the plate's height); the plate's channels are computed from
  the true contact wrench by :class:`calibration.twin_plate.TwinPlate` on the plate's own
  clock. The plate is moved between sites (the operator's move, simulated with a random
  placement error) and registered by the chosen method.
* :class:`DirectTrialRunner` — no robot: the commanded load at the site feeds the twin plate
  and an ideal ATI (plus its noise). Fast; for the fit's unit tests.
"""
from __future__ import annotations

import math

import numpy as np

from calibration import registration as reg
from calibration.operator import MoveTolerance, Operator, SimulatedOperator, confirm_move
from calibration.plan import Plan, ProfileKind
from calibration.plate import PlateDescription
from calibration.push import (
    TOOL_LENGTH_M,
    ForceTableGenerator,
    tool_plate,
)
from calibration.trial import TrialData, TrialRunner
from calibration.twin_plate import PlateTruth, TwinPlate, draw_truth
from rt.components.blocks import SignalTap
from rt.engine import Array, Component
from rt.errors import HardwareError, InputError, SafetyTrip
from rt.model import RobotModel
from rt.position_loop import build_protocol_loop, sim_devices
from rt.safety.events import Reaction
from rt.safety.limits import PatientLimits, RobotLimits
from rt.twin.environment import ForcePlateContact
from rt.twin.realism import RigImperfections
from rt.twin.twin import SimClock, Twin

RATE_HZ = 1000.0
#: Gap between the tool tip and the plate at the held pose before loading (m).
START_GAP_M = 0.5e-3
#: Forward kinematics is evaluated every this many cycles and interpolated in between.
FK_DECIMATION = 20
#: The operator's placement scatter when moving the plate between sites (1 σ).
PLACEMENT_SIGMA_M = 2.0e-3
PLACEMENT_SIGMA_YAW_RAD = math.radians(0.3)
#: Camera frames averaged per registration.
CAMERA_FRAMES = 4


class ContactTruthTap(Component):
    """Ports: in ``q``: float64[3] (only to run after the encoders, i.e. after the physics).

    Records the twin's true contact wrench (sensor frame) and slider positions each cycle into
    a preallocated ring: the plate's side of the experiment, which the loop never sees.
    """

    def __init__(self, name: str, twin: Twin, capacity: int) -> None:
        super().__init__(name)
        self.twin = twin
        self.q = self.declare_input("q", Array(3))
        self.ring = np.zeros((capacity, 10))
        self.written = 0

    def update(self, t: float, dt: float) -> int:
        if self.written < self.ring.shape[0]:
            row = self.ring[self.written]
            row[0] = t
            row[1:7] = self.twin.plant.wrench_s
            row[7:10] = self.twin.plant.q
            self.written += 1
        return 0


PROFILE_WORDS = frozenset({*(p.value for p in ProfileKind), "hold"})


def site_name(trial_id: str) -> str:
    """The site of a trial id (``<site>-<profile>[-k]``, :func:`calibration.plan.expand`;
    ``<site>-hold`` for a verification's)."""
    parts = trial_id.split("-")
    for k, part in enumerate(parts[1:], start=1):
        if part in PROFILE_WORDS:
            return "-".join(parts[:k])
    return trial_id


def sensor_poses(model: RobotModel, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p_BS (n,3), R_BS (n,9)) from slider positions (n,3), FK every ``FK_DECIMATION``."""
    n = len(q)
    idx = np.unique(np.r_[np.arange(0, n, FK_DECIMATION), n - 1])
    s = np.array(model.description.sensor.offset_m)
    ps, rs = [], []
    for k in idx:
        c = model.kin.fk(q[k], check=False)
        R = np.array(c.rotation).reshape(3, 3)
        ps.append(np.array([c.x, c.y, c.z]) + R @ s)
        rs.append(R.ravel())
    ps_a, rs_a = np.array(ps), np.array(rs)
    p = np.column_stack([np.interp(np.arange(n), idx, ps_a[:, k]) for k in range(3)])
    R_all = np.column_stack([np.interp(np.arange(n), idx, rs_a[:, k]) for k in range(9)])
    return p, R_all


def tip_points_B(p_BS: np.ndarray, R_BS: np.ndarray, tool_length_m: float) -> np.ndarray:
    """The tool tip in B: S's origin plus ``tool_length`` along S's z (3rd column of R_BS)."""
    return p_BS + tool_length_m * R_BS[:, [2, 5, 8]]


def plate_above_tool_tip(model: RobotModel, z_m: float) -> ForcePlateContact:
    """The plate (:func:`calibration.push.tool_plate`) ``START_GAP_M`` above the tool tip at
    the level pose of height ``z_m``: where a campaign at that height puts it
    (:meth:`TwinTrialRunner.run`)."""
    p, R = sensor_poses(model, np.array([model.kin.ik(z_m, 0.0, 0.0).q]))
    return tool_plate(float(tip_points_B(p, R, TOOL_LENGTH_M)[0][2]) + START_GAP_M)


class _SiteMoves:
    """The operator moving the plate between sites (simulated: a placement error drawn per
    move), then its registration, checked against the planned pose when the camera registers
    (:func:`calibration.operator.confirm_move`)."""

    def __init__(self, method: str, seed: int, level_sigma_rad: float | None,
                 operator: Operator | None = None, tolerance: MoveTolerance | None = None,
                 placement_sigma_m: float = PLACEMENT_SIGMA_M,
                 placement_sigma_yaw_rad: float = PLACEMENT_SIGMA_YAW_RAD) -> None:
        self.method = method
        self.level_sigma_rad = level_sigma_rad
        self.rng = np.random.default_rng(seed)
        self.rig = reg.MarkerRig()
        self.operator: Operator = operator or SimulatedOperator()
        self.tolerance = tolerance or MoveTolerance()
        self.placement_sigma_m = placement_sigma_m
        self.placement_sigma_yaw_rad = placement_sigma_yaw_rad
        self.T_BF_centre: np.ndarray | None = None
        self.current: tuple[tuple[float, float], np.ndarray, reg.Registration] | None = None

    def place(self, tip_B: np.ndarray, site: tuple[float, float], name: str = ""
              ) -> tuple[np.ndarray, reg.Registration]:
        if self.current is not None and self.current[0] == site:
            return self.current[1], self.current[2]
        if self.T_BF_centre is None:
            self.T_BF_centre = reg.nominal_T_BF(tip_B, (0.0, 0.0))
        T_centre = self.T_BF_centre
        planned = reg.nominal_T_BF(tip_B, site)
        true = [planned]

        def move() -> None:        # the operator's hand: a placement error per move
            error = reg.transform(reg.rot_z(self.rng.normal(0.0, self.placement_sigma_yaw_rad)),
                                  np.r_[self.rng.normal(0.0, self.placement_sigma_m, 2), 0.0])
            true[0] = planned @ error

        def register() -> reg.Registration:
            if self.method != "camera":
                return reg.nominal(tip_B, site)
            registered = reg.average_registrations([
                reg.camera_registration(reg.render_rig(self.rig, true[0], T_centre, self.rng),
                                        self.rig, self.rig.T_B_R(T_centre))
                for _ in range(CAMERA_FRAMES)])
            return reg.with_level_prior(registered, self.level_sigma_rad)

        registered = confirm_move(self.operator, name or f"{site}", site, planned, move,
                                  register, self.tolerance if self.method == "camera" else None)
        self.current = (site, true[0], registered)
        return true[0], registered


class TwinTrialRunner(TrialRunner):
    """The robot twin pressing the twin plate (module docstring)."""

    def __init__(self, plate: PlateDescription, twin_plate: TwinPlate,
                 registration: str = "camera", seed: int = 0,
                 model: RobotModel | None = None,
                 level_sigma_rad: float | None = math.radians(0.1),
                 moves: _SiteMoves | None = None,
                 imperfections: RigImperfections | None = None,
                 force_gains: dict | None = None) -> None:
        """``imperfections``: the robot twin's rig effects (None: the default twin's);
        ``force_gains``: the explicit-force law's gains (None: its defaults,
        ``rt.control.force.ExplicitForceGains``)."""
        self.plate = plate
        self.imperfections = imperfections
        self.force_gains = force_gains
        self.twin_plate = twin_plate
        self.model = model or RobotModel.load()
        self.seed = seed
        self.moves = moves or _SiteMoves(registration, seed, level_sigma_rad)
        self.robot_time_s = 0.0
        self._t_offset = 0.0      # robot clock across trials (s)

    def run(self, trial_id: str, site_xy_m: tuple[float, float], pose: tuple[float, float, float],
            profile_n: np.ndarray, dt: float, tilt_rad: np.ndarray | None = None) -> TrialData:
        model = self.model
        z0, roll, pitch = pose
        q0 = np.array(model.kin.ik(z0, roll, pitch).q)
        # The plate's height is the same for every pose: set by the level pose's tool tip.
        p_lvl, R_lvl = sensor_poses(model, np.array([model.kin.ik(z0, 0.0, 0.0).q]))
        tip_lvl = tip_points_B(p_lvl, R_lvl, TOOL_LENGTH_M)[0]
        T_true, registered = self.moves.place(tip_lvl, site_xy_m, site_name(trial_id))
        height = float(tip_lvl[2]) + START_GAP_M
        env = tool_plate(height)
        clock = SimClock()
        twin = Twin(model.description, env, seed=self.seed + len(trial_id), clock=clock,
                    imperfections=self.imperfections)
        twin.place(q0)
        gen = ForceTableGenerator(trial_id, profile_n, pose, dt, model.kin, tilt_rad)
        report = gen.validate()
        if not report.ok:
            raise SafetyTrip(f"trial {trial_id}: " + "; ".join(report.violations))
        n = int((report.duration_s + 8.0) / dt)
        tap = SignalTap("cal", [("wrench", 6), ("q", 3), ("force", 3), ("phase", 1)],
                        capacity=n)
        truth = ContactTruthTap("truth", twin, n)
        # No patient on the platform: the "patient" limits are the calibration's, up to what
        # the robot tolerates.
        limits = PatientLimits(max_force_n=RobotLimits().max_platform_force_n,
                               roll_min_deg=-10.0, roll_max_deg=10.0, pitch_min_deg=-10.0,
                               pitch_max_deg=10.0)
        pl = build_protocol_loop(sim_devices(twin, clock), gen, model, 1.0 / dt, "fast",
                                 patient_limits=limits, force_gains=self.force_gains,
                                 extra_blocks=[tap, truth],
                                 extra_connections=[("force.wrench", "cal.wrench"),
                                                    ("encoders.q", "cal.q"),
                                                    ("reference.force", "cal.force"),
                                                    ("reference.phase", "cal.phase"),
                                                    ("encoders.q", "truth.q")])
        published = 0                 # tap rows handed to ``samples`` so far
        t_first: float | None = None  # the ATI's first reading: the trial file's t = 0

        def live() -> None:
            """The rows written since the last call, on the trial file's clock."""
            nonlocal published, t_first
            if self.samples is None:
                return
            new = tap.ring[published:tap.written]
            published = tap.written
            if t_first is None:          # as trial_from_rows: from the first finite reading
                finite = np.isfinite(new[:, 1:7]).all(axis=1)
                if not finite.any():
                    return
                new = new[int(np.argmax(finite)):]
                t_first = float(new[0, 0])
            self.publish(trial_id, new[:, 0] - t_first + self._t_offset, new[:, 10], new[:, 3])

        try:
            t = 0.0
            while t < report.duration_s + 8.0:
                pl.loop.run(seconds=0.5)
                t += 0.5
                live()
                if pl.supervisor.reaction >= Reaction.SOFT_STOP:
                    ev = [e for e in pl.events.snapshot() if e.reaction >= Reaction.SOFT_STOP]
                    cause = f"{ev[0].cause}: {ev[0].message} at t = {ev[0].t:.3f} s {getattr(ev[0], 'data', '')}" if ev else "stopped"
                    raise SafetyTrip(f"trial {trial_id}: the supervisor stopped the robot "
                                     f"({cause})")
                if tap.written and tap.ring[tap.written - 1, -1] >= 4:
                    break
        finally:
            pl.graph.stop()
        rows = tap.ring[:tap.written]
        true_rows = truth.ring[:truth.written]
        m = min(len(rows), len(true_rows))
        data = trial_from_rows(trial_id, model, rows[:m], true_rows[:m], T_true, registered,
                               self.twin_plate, self._t_offset)
        self.robot_time_s += float(data.t_robot[-1] - data.t_robot[0])
        self._t_offset = float(data.t_robot[-1]) + 2.0     # the operator's pause between trials
        return data


def trial_from_rows(trial_id: str, model: RobotModel, rows: np.ndarray, true_rows: np.ndarray,
                    T_true: np.ndarray, registered: reg.Registration, twin_plate: TwinPlate,
                    t_offset: float) -> TrialData:
    """A trial's recording from the loop's rows (t, ATI wrench 6, q 3, force reference 3,
    phase) and the twin's true contact at the same instants (t, wrench 6, q 3): the robot side
    as recorded, the plate side through the twin plate on its own clock; the robot clock starts
    at ``t_offset``."""
    # The ATI reads NaN until its first sample arrives: start the recording there.
    finite = np.isfinite(rows[:, 1:7]).all(axis=1)
    if not finite.any():
        raise HardwareError(f"trial {trial_id}: the ATI sensor gave no reading")
    first = int(np.argmax(finite))
    rows, true_rows = rows[first:], true_rows[first:]
    if not np.isfinite(rows[:, 1:7]).all():
        raise HardwareError(f"trial {trial_id}: the ATI sensor's readings stopped during "
                            "the trial (NaN); repeat it")
    t_robot = rows[:, 0] - rows[0, 0] + t_offset
    p_BS, R_BS = sensor_poses(model, rows[:, 7:10])
    # The plate's side: true load (on the plate = minus the environment's on the platform).
    p_true, R_true = sensor_poses(model, true_rows[:, 7:10])
    tip_B = tip_points_B(p_true, R_true, TOOL_LENGTH_M)
    R_FB = T_true[:3, :3].T
    force_B = -np.einsum("nij,nj->ni", R_true.reshape(-1, 3, 3), true_rows[:, 1:4])
    force_F = force_B @ R_FB.T
    point_F = (tip_B - T_true[:3, 3]) @ R_FB.T
    point_F[:, 2] = 0.0          # the tip stays on the surface while it presses
    t_plate, channels = twin_plate.sample(t_robot, force_F, point_F)
    return TrialData(trial_id, t_robot, rows[:, 1:7].copy(), p_BS, R_BS, rows[:, 10].copy(),
                     t_plate, channels, registered.T_BF, registered.sigma_translation_m,
                     registered.sigma_rotation_rad, TOOL_LENGTH_M)


class DirectTrialRunner(TrialRunner):
    """The commanded load, exactly at the site, with no robot (module docstring).

    ``misalignment_rad`` tilts the true load's direction per site (a rotation vector per site
    name in a dict, or one for every site), as a real load cell mounted out of square would.
    """

    def __init__(self, plate: PlateDescription, twin_plate: TwinPlate,
                 ati_noise: tuple[float, ...] = (0.125, 0.125, 0.25, 0.0075, 0.0075, 0.0075),
                 misalignment_rad: dict[tuple[float, float], np.ndarray] | None = None,
                 tilted_shear: bool = True, seed: int = 0) -> None:
        self.plate = plate
        self.twin_plate = twin_plate
        self.ati_noise = np.array(ati_noise)
        self.misalignment = misalignment_rad or {}
        self.rng = np.random.default_rng(seed)
        self.tilted_shear = tilted_shear
        self.robot_time_s = 0.0
        self._t_offset = 0.0

    def run(self, trial_id: str, site_xy_m: tuple[float, float], pose: tuple[float, float, float],
            profile_n: np.ndarray, dt: float, tilt_rad: np.ndarray | None = None) -> TrialData:
        if tilt_rad is not None:
            raise InputError(f"trial {trial_id}: the direct runner has no robot to tilt under "
                             "load (shear pushes need the twin or the RT process)")
        n = len(profile_n)
        t_robot = np.arange(n) * dt + self._t_offset
        # S placed so its tool tip is at the site, S axes tilted by the pose's roll/pitch; the
        # load along S's z (a push along the tool's axis: shear in F when tilted).
        _, roll, pitch = pose
        R_BS = reg.small_rotation(np.array([roll, pitch, 0.0]))
        T_BF = reg.transform(np.eye(3), np.array([0.1 - site_xy_m[0], -site_xy_m[1], 0.7]))
        tip_B = T_BF[:3, :3] @ np.array([site_xy_m[0], site_xy_m[1], 0.0]) + T_BF[:3, 3]
        p_BS = tip_B - TOOL_LENGTH_M * R_BS[:, 2]
        axis = R_BS[:, 2] if self.tilted_shear else np.array([0.0, 0.0, 1.0])
        force_B = np.outer(profile_n, axis)
        tilt = self.misalignment.get(tuple(site_xy_m), np.zeros(3))  # type: ignore[arg-type]
        force_true_B = force_B @ reg.small_rotation(tilt).T
        # ATI: environment on the platform = minus the load, in S axes, about S's origin.
        lever = tip_B - p_BS
        f_S = -force_B @ R_BS
        m_S = np.cross(lever @ R_BS, f_S)
        ati = np.hstack([f_S, m_S]) + self.rng.normal(0.0, 1.0, (n, 6)) * self.ati_noise
        point_F = np.tile([site_xy_m[0], site_xy_m[1], 0.0], (n, 1))
        t_plate, channels = self.twin_plate.sample(t_robot, force_true_B, point_F)
        # Computed at once (no robot to wait for); handed over in the twin's 0.5 s blocks.
        block = max(1, round(0.5 / dt))
        for i in range(0, n, block):
            self.publish(trial_id, t_robot[i:i + block], profile_n[i:i + block],
                         ati[i:i + block, 2])
        self.robot_time_s += n * dt
        self._t_offset = float(t_robot[-1]) + 2.0
        return TrialData(trial_id, t_robot, ati, np.tile(p_BS, (n, 1)),
                         np.tile(R_BS.ravel(), (n, 1)), np.asarray(profile_n, float), t_plate,
                         channels, T_BF, 0.0, 0.0, TOOL_LENGTH_M)


def make_runner(backend: str, plate: PlateDescription, seed: int, registration: str,
                level_sigma_rad: float | None = math.radians(0.1), plan: Plan | None = None,
                endpoint: str | None = None, plate_daq: str | None = None,
                operator: Operator | None = None, camera: str | None = None,
                tolerance: MoveTolerance | None = None, trials: list | None = None,
                client_id: str | None = None) -> tuple[TrialRunner, PlateTruth | None]:
    """The runner named ``backend``: ``twin`` (the robot twin in this process), ``direct`` (no
    robot) or ``rt`` (the RT process at ``endpoint`` plays each trial; ``plan`` is the
    campaign's plan, sent with each trial; ``trials`` the ones it may run, default the plan's).

    The plate: the twin plate drawn from ``seed`` (its truth returned), unless ``plate_daq``
    (``rt`` only) names a real DAQ's file (:mod:`calibration.plate_daq`): then the client
    acquires that plate, ``operator`` moves it between sites and ``camera`` (``opencv[:N]``,
    a registry camera backend) confirms each move; no truth. ``plate_daq="twin"``: the twin
    plate behind the same driver (:mod:`calibration.twin_plate_daq`), moves simulated.
    ``client_id`` (``rt`` only): the RT process's client the runner acts as (a GUI's, whose
    control it borrows: :class:`calibration.rt_runner.RtTrialRunner`)."""
    if backend not in ("twin", "direct", "rt"):
        raise InputError(f"unknown backend {backend!r}: use twin, direct or rt")
    if client_id is not None and backend != "rt":
        raise InputError("a client id goes with the rt backend (the twin and direct backends "
                         "do not talk to an RT process)")
    if plate_daq is not None and backend != "rt":
        raise InputError("--plate-daq goes with --backend rt (the twin and direct backends "
                         "simulate the plate in this process)")
    if backend == "rt":
        from calibration.rt_runner import RtTrialRunner
        from rt.ipc.messages import DEFAULT_ENDPOINT

        if plan is None:
            raise InputError("the rt backend needs the campaign's plan")
        ep = endpoint or DEFAULT_ENDPOINT
        if plate_daq is not None and plate_daq != "twin":
            return _real_plate_runner(plate, plan, ep, plate_daq, registration, level_sigma_rad,
                                      operator, camera, tolerance, trials, client_id), None
    truth = draw_truth(plate, seed=seed)
    twin_plate = TwinPlate(plate, truth, seed=seed + 1)
    if backend == "direct":
        return DirectTrialRunner(plate, twin_plate, seed=seed), truth
    if backend == "rt":
        assert plan is not None            # checked above
        moves = _SiteMoves(registration, seed, level_sigma_rad, operator, tolerance)
        model = RobotModel.load()
        daq = None
        if plate_daq == "twin":
            from calibration.twin_plate_daq import TwinPlateDaq

            daq = TwinPlateDaq(plate, twin_plate, model, TOOL_LENGTH_M)
        try:
            return RtTrialRunner(plate, twin_plate, plan, ep, registration, seed, model=model,
                                 level_sigma_rad=level_sigma_rad, daq=daq, moves=moves,
                                 trials=trials, client_id=client_id), truth
        except BaseException:
            if daq is not None:
                daq.close()
            raise
    return TwinTrialRunner(plate, twin_plate, registration=registration, seed=seed,
                           level_sigma_rad=level_sigma_rad,
                           moves=_SiteMoves(registration, seed, level_sigma_rad, operator,
                                            tolerance)), truth


def _real_plate_runner(plate: PlateDescription, plan: Plan, endpoint: str, daq_file: str,
                       registration: str, level_sigma_rad: float | None,
                       operator: Operator | None, camera: str | None,
                       tolerance: MoveTolerance | None, trials: list | None,
                       client_id: str | None = None) -> TrialRunner:
    """A real plate's DAQ and camera, the RT process pushing (``make_runner``)."""
    from calibration.plate_daq import load_daq_config, open_plate_device
    from calibration.rt_runner import RtTrialRunner
    from calibration.site_moves import CameraSiteMoves
    from rt.devices import registry

    if operator is None:
        raise InputError("a real plate needs an operator to move it between sites")
    cam = None
    device = open_plate_device(load_daq_config(daq_file), plate.n_channels)
    try:
        if registration == "camera":
            name, _, source = (camera or "opencv").partition(":")
            kw = {"source": int(source) if source.isdigit() else source} if source else {}
            cam = registry.create("camera", name, **kw)
        moves = CameraSiteMoves(operator, cam, registration, level_sigma_rad, tolerance)
        return RtTrialRunner(plate, None, plan, endpoint, registration, daq=device,
                             moves=moves, trials=trials, level_sigma_rad=level_sigma_rad,
                             client_id=client_id)
    except BaseException:
        device.close()
        if cam is not None:
            cam.close()
        raise
