"""The calibration wizard's steps (Qt-free; each runs on a worker): plan → register the plate
with the camera → run (on the twin, the plate alone, or through the RT process the GUI is
connected to) → fit → verify → certificate, over the ``calibration`` package as ``talus
calibrate`` drives it.

Everything goes into a new work folder (``campaign/``, ``calibration_record.json``,
``verification/``); the certificate goes where the engineer chooses, never over a file. Each
step refuses to run before the one it needs.

What the wizard draws is computed here, as arrays: the camera's frame with the detected ArUco
markers and the registered plate outline drawn into it (:meth:`CalibrationFlow.register`), and
each trial's vertical force as the ATI reference and the plate (through its nominal matrix)
measured it (:func:`trial_series`, read back from the trial files the campaign just wrote).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rt.errors import InputError

#: (trial index, trial count, trial id) while trials run
Progress = Callable[[int, int, str], None]
#: Live plots: one trial's forces (:class:`TrialSeries`) as soon as its file is written.
TrialDone = Callable[["TrialSeries"], None]
#: Live plots: the running trial's samples as the robot measures them, block by block
#: (``calibration.trial.LiveSamples``, decimated to :data:`PLOT_RATE_HZ`).
SamplesLive = Callable[[Any], None]
#: The live plot keeps about this many points per second of trial (the trials are recorded at
#: 1 kHz; 50 Hz shows a step or a 1 Hz sine faithfully and keeps a 6-minute campaign at
#: ~20 000 points per curve).
PLOT_RATE_HZ = 50.0
#: BGR colours drawn into the camera frame: detected markers, the registered plate outline.
MARKER_BGR = (0, 200, 0)
OUTLINE_BGR = (0, 0, 230)
#: The backends the wizard offers: the robot twin (realistic, minutes), the plate driven
#: directly with the planned forces (no robot dynamics; seconds — a dry run of the workflow),
#: or the RT process the GUI is connected to (``rt``: its loop plays each trial under its
#: supervisor, on its twin or on the rig; :class:`calibration.rt_runner.RtTrialRunner`).
BACKENDS = ("twin", "direct", "rt")


@dataclass(frozen=True)
class TrialSeries:
    """One trial's vertical load on the plate, decimated for the live plot (N, s on the
    robot's clock): as the ATI reference measured it (rotated into the plate's frame, zeroed on
    the unloaded baselines: what the fit compares with) and as the plate's channels give it
    through its nominal matrix (zeroed the same way), put on the robot's clock by the trial's
    own cross-correlation lag (``calibration.alignment.trial_lag``; the plate's clock as
    recorded when the two do not line up, ``aligned`` False)."""

    trial_id: str
    index: int
    count: int
    t_ati_s: np.ndarray
    ati_fz_n: np.ndarray
    t_plate_s: np.ndarray
    plate_fz_n: np.ndarray
    aligned: bool


@dataclass(frozen=True)
class CameraView:
    """The registration step's result: the camera frame (BGR, uint8, the camera's size) with
    every detected marker outlined (:data:`MARKER_BGR`, ids written) and the plate outline
    where the registration puts it (:data:`OUTLINE_BGR`); what was detected and registered.

    ``offset_mm``/``yaw_deg``: the registered placement against the planned one (what the
    operator's placement missed by); ``error_mm``: against the twin's true placement (the
    registration's own error, known only on the twin)."""

    image_bgr: np.ndarray
    marker_ids: tuple[int, ...]
    expected_ids: tuple[int, ...]
    outline_px: np.ndarray
    offset_mm: tuple[float, float]
    yaw_deg: float
    sigma_translation_mm: float
    sigma_rotation_deg: float
    error_mm: float

    @property
    def markers(self) -> int:
        return len(self.marker_ids)


def _decimate(t: np.ndarray, y: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Every k-th sample for about ``rate_hz`` points a second (the last sample kept)."""
    if len(t) < 2:
        return t.copy(), y.copy()
    dt = float(np.median(np.diff(t)))
    k = max(1, round(1.0 / (rate_hz * dt))) if dt > 0 else 1
    idx = np.r_[np.arange(0, len(t) - 1, k), len(t) - 1]
    return t[idx], y[idx]


def trial_series(campaign: Path, trial_id: str, index: int, count: int,
                 rate_hz: float = PLOT_RATE_HZ) -> TrialSeries:
    """The live plot's data of trial ``trial_id`` from its file in ``campaign`` (the
    campaign's own copy of the plate description; :class:`TrialSeries`)."""
    from calibration import dataset
    from calibration.alignment import ClockAlignmentError, trial_lag
    from calibration.campaign import PLATE_COPY
    from calibration.plate import load_plate
    from calibration.trial import TRIALS_DIR, TrialData

    plate = load_plate(campaign / PLATE_COPY)
    d = TrialData.load(campaign / TRIALS_DIR / f"{trial_id}.npz")
    w, _ = dataset.reference_in_plate(d, np.array(plate.origin_m))
    plate_fz = dataset.nominal_fz(plate, dataset.zeroed_channels(d))
    try:
        lag = trial_lag(trial_id, d.t_robot, w[:, 2], d.t_plate, plate_fz).lag_s
        aligned = True
    except ClockAlignmentError:
        lag, aligned = 0.0, False
    t_a, fz_a = _decimate(d.t_robot, w[:, 2], rate_hz)
    t_p, fz_p = _decimate(d.t_plate - lag, plate_fz, rate_hz)
    return TrialSeries(trial_id, index, count, t_a, fz_a, t_p, fz_p, aligned)


class LiveDecimator:
    """Every k-th sample of a trial's blocks for about ``rate_hz`` points a second, the stride
    kept across blocks (a block's length need not be a multiple of k); a new trial starts
    with its first sample."""

    def __init__(self, sink: SamplesLive, rate_hz: float = PLOT_RATE_HZ,
                 dt_s: float = 1e-3) -> None:
        self.sink = sink
        self.k = max(1, round(1.0 / (rate_hz * dt_s)))
        self._trial = ""
        self._seen = 0

    def __call__(self, block: Any) -> None:
        from calibration.trial import LiveSamples

        if block.trial_id != self._trial:
            self._trial, self._seen = block.trial_id, 0
        n = len(block.t_robot)
        keep = (self._seen + np.arange(n)) % self.k == 0
        self._seen += n
        if keep.any():
            self.sink(LiveSamples(block.trial_id, block.t_robot[keep], block.force_ref[keep],
                                  block.ati_load[keep]))


@dataclass
class CalibrationFlow:
    """One calibration in ``folder`` (created empty) for the plate described in ``plate_file``.

    ``backend`` ``rt``: the trials are played by the RT process at ``endpoint`` as its client
    ``client_id`` (the GUI's own: the GUI's control of the robot is borrowed when it has it,
    else taken for the campaign and given back; ``calibration.rt_runner.RtTrialRunner``)."""

    folder: Path
    plate_file: Path
    backend: str = "twin"
    seed: int = 1
    operator: str = "talus GUI"
    endpoint: str | None = None
    client_id: str | None = None
    plan: Any = None
    trials: list[Any] = field(default_factory=list)
    record: dict[str, Any] | None = None
    verification: dict[str, Any] | None = None

    @property
    def campaign(self) -> Path:
        return self.folder / "campaign"

    @property
    def record_path(self) -> Path:
        return self.folder / "calibration_record.json"

    def make_plan(self, plan_text: str | None = None) -> dict[str, Any]:
        """Step 1: the loading plan (the default one, or YAML text) expanded on the plate.
        Returns the plate outline and the sites, in the plate's frame (m)."""
        import yaml

        from calibration.plan import Plan, default_plan, expand, sites
        from calibration.plate import load_plate

        if self.backend not in BACKENDS:
            raise InputError(f"unknown backend {self.backend!r}: one of {', '.join(BACKENDS)}")
        if self.backend == "rt" and not self.endpoint:
            raise InputError("the rt backend plays the trials in the RT process the GUI is "
                             "connected to: connect to one first (Settings: RT endpoint)")
        plate = load_plate(self.plate_file)
        if plan_text:
            try:
                data = yaml.safe_load(plan_text)
            except yaml.YAMLError as exc:
                raise InputError(f"plan: not valid YAML: {exc}") from None
            try:
                plan = Plan.model_validate(data)
            except ValueError as exc:
                raise InputError(f"plan: {exc}") from None
        else:
            plan = default_plan()
        try:
            self.trials = expand(plan, plate.size_m)
            site_list = sites(plan, plate.size_m)
        except ValueError as exc:
            raise InputError(f"plan: {exc}") from None
        self.plan = plan
        return {"plate": plate.name, "size_m": list(plate.size_m),
                "sites": [(s.name, s.x_m, s.y_m, s.held_out) for s in site_list],
                "trials": len(self.trials), "held_out": sum(t.held_out for t in self.trials),
                "loads_n": list(plan.loads_n)}

    def register(self) -> CameraView | None:
        """Step 2: the plate registered by the camera, as the trials will register each site
        (``calibration.registration``): the twin's camera frame of the plate placed at the
        central site by hand (the operator's placement scatter), its markers detected and the
        plate outline drawn where the registration puts it (:class:`CameraView`). None when
        the plan registers the plate nominally (placed to marks, no camera)."""
        import cv2

        from calibration import registration as reg
        from calibration.plate import load_plate
        from calibration.twin_runner import (
            CAMERA_FRAMES,
            PLACEMENT_SIGMA_M,
            PLACEMENT_SIGMA_YAW_RAD,
        )

        if self.plan is None:
            raise InputError("make the plan first")
        if self.plan.registration != "camera":
            return None
        plate = load_plate(self.plate_file)
        rig = reg.MarkerRig()
        rng = np.random.default_rng(self.seed)
        planned = reg.nominal_T_BF(self._tip_B(), (0.0, 0.0))
        true = planned @ reg.transform(reg.rot_z(rng.normal(0.0, PLACEMENT_SIGMA_YAW_RAD)),
                                       np.r_[rng.normal(0.0, PLACEMENT_SIGMA_M, 2), 0.0])
        # As the trials register a site: CAMERA_FRAMES frames averaged, the tilt fused with
        # the levelled plate's prior; the first frame is the one shown.
        frames = [reg.render_rig(rig, true, planned, rng) for _ in range(CAMERA_FRAMES)]
        registered = reg.with_level_prior(reg.average_registrations(
            [reg.camera_registration(f, rig, rig.T_B_R(planned)) for f in frames]),
            self.plan.level_sigma_rad())
        frame = frames[0]
        # The detection drawn is the one the registration made (same detector, same frame).
        detector = cv2.aruco.ArucoDetector(
            cv2.aruco.getPredefinedDictionary(rig.plate_board.dictionary),
            cv2.aruco.DetectorParameters())
        grey = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        corners, ids, _ = detector.detectMarkers(grey)
        image = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
        found: tuple[int, ...] = () if ids is None else tuple(int(i) for i in ids.ravel())
        # Drawn thick (the frame is shown at about a third of its size): each detected
        # marker's outline and its id, as cv2.aruco.drawDetectedMarkers does at 1 px.
        for c, marker_id in zip(corners, found, strict=True):
            pts = np.rint(c.reshape(4, 2)).astype(np.int32)
            cv2.polylines(image, [pts], True, MARKER_BGR, 6)
            cv2.putText(image, str(marker_id), (int(pts[0, 0]), int(pts[0, 1]) - 10),
                        cv2.FONT_HERSHEY_SIMPLEX, 1.2, MARKER_BGR, 3, cv2.LINE_AA)
        # The plate's corners where the registration puts them, seen by the camera.
        T_CF = rig.T_C_B(planned) @ registered.T_BF
        rvec, _ = cv2.Rodrigues(T_CF[:3, :3])
        px, _ = cv2.projectPoints(plate.corners_F(), rvec, T_CF[:3, 3], rig.camera.K,
                                  rig.camera.dist_coeffs)
        outline = px.reshape(-1, 2)
        cv2.polylines(image, [np.rint(outline).astype(np.int32)], True, OUTLINE_BGR, 6)
        rel = reg.inverse(planned) @ registered.T_BF
        return CameraView(
            image, found, (*rig.plate_board.ids, *rig.robot_board.ids), outline,
            (float(rel[0, 3] * 1e3), float(rel[1, 3] * 1e3)),
            math.degrees(math.atan2(rel[1, 0], rel[0, 0])),
            registered.sigma_translation_m * 1e3, math.degrees(registered.sigma_rotation_rad),
            float(np.linalg.norm(registered.T_BF[:3, 3] - true[:3, 3]) * 1e3))

    def _tip_B(self) -> np.ndarray:
        """The tool tip at the plan's level pose in the robot's base (m), where the twin
        runner places the plate (``calibration.twin_runner``: the sensor's origin by forward
        kinematics, the tool along the sensor's z). Kinematics only: the dynamics model is
        not needed here and takes seconds to build."""
        from calibration.push import TOOL_LENGTH_M
        from rt.model import Kinematics, load_description

        assert self.plan is not None
        kin = Kinematics(load_description())
        c = kin.fk(kin.ik(self.plan.pose_z_m, 0.0, 0.0).q, check=False)
        R = np.array(c.rotation).reshape(3, 3)
        p_BS = np.array([c.x, c.y, c.z]) + R @ np.array(kin.description.sensor.offset_m)
        return p_BS + TOOL_LENGTH_M * R[:, 2]

    def run(self, progress: Progress | None = None,
            trial_done: TrialDone | None = None,
            samples: SamplesLive | None = None) -> dict[str, Any]:
        """Step 3: run every trial on the backend into ``folder/campaign``; ``samples`` gets
        the running trial's samples while it runs (commanded force and the ATI's load,
        decimated: :class:`LiveDecimator`), ``trial_done`` each trial's forces
        (:func:`trial_series`) once its file is written."""
        from calibration.campaign import run_campaign
        from calibration.plate import load_plate
        from calibration.twin_runner import make_runner

        if self.plan is None:
            raise InputError("make the plan first")
        self.folder.mkdir(parents=True, exist_ok=True)
        plate = load_plate(self.plate_file)
        runner, truth = make_runner(self.backend, plate, self.seed, self.plan.registration,
                                    self.plan.level_sigma_rad(), **self._runner_kw())
        previous: list[tuple[int, int, str]] = []

        def each(k: int, n: int, trial_id: str) -> None:
            # Called before trial k runs: trial k - 1's file is complete by then.
            if trial_done is not None and previous:
                trial_done(trial_series(self.campaign, previous[-1][2], *previous[-1][:2]))
            previous.append((k, n, trial_id))
            if progress is not None:
                progress(k, n, trial_id)

        sink: SamplesLive | None = None
        if samples is not None:
            # The RT process's runner hands over its telemetry, already ≈ 60 samples a second
            # (the plot's rate); the in-process runners hand over every 1 kHz sample.
            sink = samples if self.backend == "rt" else LiveDecimator(samples)
        try:
            index = run_campaign(self.plan, self.plate_file, runner, self.campaign, truth, each,
                                 trials=self.trials, samples=sink)
        finally:
            runner.close()       # the RT runner's heartbeat and control of the robot
        if trial_done is not None and previous:
            trial_done(trial_series(self.campaign, previous[-1][2], *previous[-1][:2]))
        return {"trials": len(index["trials"]), "robot_time_s": index["robot_time_s"]}

    def fit(self) -> dict[str, Any]:
        """Step 3: fit the campaign; the record (with its PASS/FAIL verdict and COP error
        map before/after) is written to ``calibration_record.json``."""
        from calibration.cli import fit_campaign
        from calibration.metrics import Thresholds

        if not (self.campaign / "campaign.json").exists():
            raise InputError("run the campaign first")
        record, _processed = fit_campaign(self.campaign, self.record_path, Thresholds(),
                                          self.operator)
        self.record = record
        return record

    def verify(self, load_n: float = 800.0,
               progress: Progress | None = None) -> dict[str, Any]:
        """Step 4: a short independent check of the fitted calibration (new trials at check
        sites, no fitting)."""
        from calibration.metrics import Thresholds
        from calibration.verify import verify

        if self.record is None:
            raise InputError("fit the calibration first")
        self.verification = verify(self.record_path, self.folder / "verification",
                                   self.backend, self.seed + 100, load_n, Thresholds(),
                                   progress, plate_file=self.plate_file,
                                   runner_kw={k: v for k, v in self._runner_kw().items()
                                              if k in ("endpoint", "client_id")})
        return self.verification

    def _runner_kw(self) -> dict[str, Any]:
        """``make_runner``'s keywords for this flow's backend: the campaign's plan and trials,
        the RT process and the GUI's client id for ``rt``; nothing for the in-process ones."""
        if self.backend != "rt":
            return {}
        return {"plan": self.plan, "trials": self.trials, "endpoint": self.endpoint,
                "client_id": self.client_id}

    def certificate(self, out: Path, settings: Any = None, record: Any = None,
                    actor: Any = None) -> dict[str, Any]:
        """Step 5: the certificate PDF at ``out`` (refused if it exists); with a clinical
        record and an actor allowed to, the calibration is stored there too."""
        from reports.certificate import calibration_record_from_dict, render_certificate

        if self.record is None:
            raise InputError("fit the calibration first")
        pages = render_certificate(calibration_record_from_dict(self.record, "the fit"), out,
                                   settings)
        stored = None
        if record is not None and actor is not None:
            stored = record.add_calibration(actor, self.record, str(out))
        return {"out": str(out), "pages": pages, "stored": stored}


def cop_error_points(record: dict[str, Any], stage: str) -> list[tuple[float, float, float]]:
    """(x m, y m, COP error mm) of the record's error map at ``stage`` ("before"/"after"),
    cells without data left out."""
    cmap = record["cop_error_map"]
    grid = cmap[f"{stage}_mm"]
    out = []
    for j, y in enumerate(cmap["y_m"]):
        for i, x in enumerate(cmap["x_m"]):
            v = grid[j][i]
            if v is not None and math.isfinite(float(v)):
                out.append((float(x), float(y), float(v)))
    return out
