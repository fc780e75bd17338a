"""Where the plate is relative to the robot: ``T_BF`` (plate frame F in the robot base B).

* Nominal: from the plan — the plate placed so that the tool tip, at the trial's pose, lands
  on the site; the uncertainty is the operator's placement tolerance.
* Camera: two ArUco boards, one fixed on the robot's frame at a known ``T_B_R`` and one on the
  plate at a known ``T_F_P``, seen in the same image. Each board's pose in the camera and
  its covariance come from ``rt.vision.pnp.solve_marker_board`` (one marker's square
  solution for a start, all the board's corners refine it; the residual variance floored at
  the corner detector's ~0.05 px). ``T_BF = T_B_R T_C_R⁻¹ T_C_P T_F_P⁻¹``; its uncertainty is
  propagated by sampling the two board poses (Monte Carlo, fixed seed).

On the twin the camera is :mod:`rt.drivers.synthetic_frames` (both boards rendered into one
frame); a real camera gives frames through ``rt.drivers.camera_cv`` and the same estimator.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from rt.drivers.synthetic_frames import MarkerBoard, PinholeCamera, render_board
from rt.errors import HardwareError
from rt.vision.aruco import detect_markers
from rt.vision.pnp import PnpPose, solve_marker_board
from rt.vision.transforms import from_rvec, inverse, transform

#: The operator's placement tolerance when the plate is placed by hand to marks (1 σ).
NOMINAL_SIGMA_TRANSLATION_M = 2.0e-3
NOMINAL_SIGMA_ROTATION_RAD = math.radians(0.3)
#: Corner localization floor (px, 1 σ) when the residuals are smaller than that.
CORNER_SIGMA_FLOOR_PX = 0.05


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def small_rotation(angles: np.ndarray) -> np.ndarray:
    """R = exp([a]×) for a rotation vector (rad)."""
    R, _ = cv2.Rodrigues(np.asarray(angles, dtype=float).reshape(3, 1))
    return R


def rotation_angle(R: np.ndarray) -> float:
    """The angle of a rotation matrix (rad)."""
    return float(math.acos(max(-1.0, min(1.0, (np.trace(R) - 1.0) / 2.0))))


def nominal_T_BF(tip_B: np.ndarray, site_xy_m: tuple[float, float]) -> np.ndarray:
    """Plate F placed with its axes along B's and the site under the tool tip ``tip_B``."""
    return transform(np.eye(3), np.asarray(tip_B) - np.array([site_xy_m[0], site_xy_m[1], 0.0]))


@dataclass(frozen=True)
class Registration:
    """A registered plate pose with its standard uncertainties (per axis, 1 σ)."""

    method: str
    T_BF: np.ndarray
    sigma_translation_m: float
    sigma_rotation_rad: float

    def record_entry(self) -> dict:
        return {"method": self.method, "T_robot_plate": self.T_BF.tolist(),
                "sigma_translation_mm": self.sigma_translation_m * 1e3,
                "sigma_rotation_deg": math.degrees(self.sigma_rotation_rad)}


def nominal(tip_B: np.ndarray, site_xy_m: tuple[float, float]) -> Registration:
    return Registration("nominal", nominal_T_BF(tip_B, site_xy_m), NOMINAL_SIGMA_TRANSLATION_M,
                        NOMINAL_SIGMA_ROTATION_RAD)


# ------------------------------------------------------------------------------ camera
@dataclass(frozen=True)
class MarkerRig:
    """The camera set-up: intrinsics, the two boards and where they are mounted.

    Default: the camera 1.2 m below the plate's surface looking up at it (the robot presses
    the plate's working surface from below); the plate's board at F's origin, printed face
    along F's z; the robot's board beside it, fixed to the robot frame.
    """

    camera: PinholeCamera = field(default_factory=lambda: PinholeCamera(
        width=1600, height=1600, fx=1300.0, fy=1300.0))
    plate_board: MarkerBoard = field(default_factory=lambda: MarkerBoard(
        rows=3, cols=4, marker_length_m=0.06, gap_m=0.02, margin_m=0.02, first_id=0))
    robot_board: MarkerBoard = field(default_factory=lambda: MarkerBoard(
        rows=3, cols=4, marker_length_m=0.06, gap_m=0.02, margin_m=0.02, first_id=20))
    distance_m: float = 1.2
    robot_board_offset_m: tuple[float, float] = (0.0, 0.46)
    noise_grey: float = 2.0

    def T_F_P(self) -> np.ndarray:
        """The plate's board at F's origin, printed face towards the camera (along -z_F)."""
        return transform(np.diag([1.0, -1.0, -1.0]), np.zeros(3))

    def T_B_R(self, T_BF_nominal: np.ndarray) -> np.ndarray:
        """The robot board: at the plate's nominal height, beside its nominal centre (the
        central site's); fixed in B."""
        dx, dy = self.robot_board_offset_m
        return transform(np.diag([1.0, -1.0, -1.0]),
                         T_BF_nominal[:3, 3] + np.array([dx, dy, 0.0]))

    def T_C_B(self, T_BF_nominal: np.ndarray) -> np.ndarray:
        """Camera below the plate, optical axis up: its axes are B's."""
        centre = T_BF_nominal[:3, 3] + np.array([0.0, 0.0, -self.distance_m])
        return inverse(transform(np.eye(3), centre))


def _board_pose(frame: np.ndarray, board: MarkerBoard, camera: PinholeCamera) -> PnpPose:
    """A board's pose in the camera, with its covariance, from one frame."""
    seen = detect_markers(frame, board.dictionary)
    if not seen:
        raise HardwareError("camera registration: no ArUco marker seen")
    markers = [(board.marker_corners_B(i), px) for i, px in seen if i in board.ids]
    if len(markers) < 3:
        raise HardwareError(f"camera registration: board with ids {board.ids[0]}-"
                            f"{board.ids[-1]}: {len(markers)} markers seen, need at least 3")
    pose = solve_marker_board(markers, camera.K, camera.dist_coeffs,
                              sigma_floor_px=CORNER_SIGMA_FLOOR_PX)
    if pose is None:
        raise HardwareError("camera registration: solvePnP failed")
    return pose


def camera_registration(frame: np.ndarray, rig: MarkerRig, T_B_R: np.ndarray,
                        samples: int = 300, seed: int = 0) -> Registration:
    """Estimate T_BF from one frame showing both boards (module docstring)."""
    plate = _board_pose(frame, rig.plate_board, rig.camera)
    robot = _board_pose(frame, rig.robot_board, rig.camera)
    r_p, t_p, cov_p = plate.rvec, plate.tvec, plate.covariance
    r_r, t_r, cov_r = robot.rvec, robot.tvec, robot.covariance
    T_BF = T_B_R @ inverse(from_rvec(r_r, t_r)) @ from_rvec(r_p, t_p) @ inverse(rig.T_F_P())
    rng = np.random.default_rng(seed)
    dp, da = [], []
    for _ in range(samples):
        xp = rng.multivariate_normal(np.r_[r_p, t_p], cov_p)
        xr = rng.multivariate_normal(np.r_[r_r, t_r], cov_r)
        T = (T_B_R @ inverse(from_rvec(xr[:3], xr[3:])) @ from_rvec(xp[:3], xp[3:])
             @ inverse(rig.T_F_P()))
        dp.append(T[:3, 3] - T_BF[:3, 3])
        dR = T[:3, :3] @ T_BF[:3, :3].T
        a, _ = cv2.Rodrigues(dR)
        da.append(a.ravel())
    sigma_t = float(np.sqrt(np.mean(np.var(np.array(dp), axis=0))))
    sigma_r = float(np.sqrt(np.mean(np.var(np.array(da), axis=0))))
    return Registration("camera", T_BF, sigma_t, sigma_r)


def average_registrations(regs: list[Registration]) -> Registration:
    """The mean of several frames' registrations (translation mean; rotation: the mean
    rotation vector relative to the first); σ shrinks as √n for the frames' independent noise
    but not below the frames' own scatter over √n."""
    n = len(regs)
    R0 = regs[0].T_BF[:3, :3]
    vecs = np.array([cv2.Rodrigues(r.T_BF[:3, :3] @ R0.T)[0].ravel() for r in regs])
    ps = np.array([r.T_BF[:3, 3] for r in regs])
    R = small_rotation(vecs.mean(axis=0)) @ R0
    sig_t = max(float(np.mean([r.sigma_translation_m for r in regs])) / math.sqrt(n),
                float(np.sqrt(np.mean(np.var(ps, axis=0)))) / math.sqrt(n) if n > 1 else 0.0)
    sig_r = max(float(np.mean([r.sigma_rotation_rad for r in regs])) / math.sqrt(n),
                float(np.sqrt(np.mean(np.var(vecs, axis=0)))) / math.sqrt(n) if n > 1 else 0.0)
    return Registration(regs[0].method, transform(R, ps.mean(axis=0)), sig_t, sig_r)


def with_level_prior(r: Registration, level_sigma_rad: float | None) -> Registration:
    """Fuse the registration's tilt with the knowledge that plate and robot are levelled
    (a force plate is installed level to within ``level_sigma_rad``, 1 σ; the robot's base
    too): the tilt (rotation about the base's x and y) is shrunk toward level by inverse-
    variance weighting; the yaw and the translation stay the camera's. A monocular camera's
    tilt of a plane seen face-on is its weakest estimate, and the one the shear channels
    are most sensitive to."""
    if level_sigma_rad is None:
        return r
    R = r.T_BF[:3, :3]
    yaw = math.atan2(R[1, 0], R[0, 0])
    tilt_vec = cv2.Rodrigues(rot_z(yaw).T @ R)[0].ravel()      # R = Rz(yaw) · R_tilt
    w = level_sigma_rad ** 2 / (level_sigma_rad ** 2 + r.sigma_rotation_rad ** 2)
    R_new = rot_z(yaw) @ small_rotation(tilt_vec * w)
    fused = 1.0 / math.sqrt(1.0 / level_sigma_rad ** 2 + 1.0 / r.sigma_rotation_rad ** 2) \
        if r.sigma_rotation_rad > 0 else 0.0
    # The yaw keeps the camera's σ; report the per-axis RMS of (tilt, tilt, yaw).
    sigma = math.sqrt((2 * fused ** 2 + r.sigma_rotation_rad ** 2) / 3.0)
    return Registration(r.method, transform(R_new, r.T_BF[:3, 3]), r.sigma_translation_m, sigma)


def render_rig(rig: MarkerRig, T_BF_true: np.ndarray, T_BF_nominal: np.ndarray,
               rng: np.random.Generator) -> np.ndarray:
    """The twin camera's frame: both boards at their true poses, sensor noise added."""
    T_C_B = rig.T_C_B(T_BF_nominal)
    frames = []
    for board, T_B_board in ((rig.plate_board, T_BF_true @ rig.T_F_P()),
                             (rig.robot_board, rig.T_B_R(T_BF_nominal))):
        T_C_board = T_C_B @ T_B_board
        rvec, _ = cv2.Rodrigues(T_C_board[:3, :3])
        frames.append(render_board(board, rig.camera, (rvec.ravel(), T_C_board[:3, 3]),
                                   background=255))
    grey = np.minimum(frames[0], frames[1]).astype(np.float32)
    if rig.noise_grey > 0:
        grey += rng.normal(0.0, rig.noise_grey, grey.shape).astype(np.float32)
    return np.clip(np.rint(grey), 0, 255).astype(np.uint8)
