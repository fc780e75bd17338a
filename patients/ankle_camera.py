"""The patient's ankle centre measured with the camera: ArUco markers on both malleoli.

Set-up (:class:`MalleoliRig`): a camera in front of the foot, looking back at it; an ArUco board
fixed upright on the platform at a known pose ``T_P_R`` in the platform frame P (it registers
the camera to P); one square marker on a clip on each malleolus, printed face towards the
camera, its centre on the malleolus's most prominent point. From one frame:

1. the board's pose in the camera, ``T_C_R``: ``SOLVEPNP_IPPE_SQUARE`` on one marker for a
   start, then every corner of the board's markers refines it (Levenberg-Marquardt:
   ``rt.vision.pnp``, the estimator ``calibration.registration`` registers a force plate
   with); the camera in P is
   ``T_P_C = T_P_R T_C_R⁻¹``;
2. each malleolus marker's pose by ``SOLVEPNP_IPPE_SQUARE`` on its four corners: its centre in
   C, then in P;
3. ``rt.model.ankle.setup_from_malleoli``: the ankle centre is the malleoli's midpoint (the
   talocrural axis passes close to both tips), its height above the sole and its offsets from
   the sensor's axis → an :class:`~rt.model.ankle.AnkleSetup` with ``source="camera"``.

Uncertainty: each pose's covariance is ``s² (JᵀJ)⁻¹`` (J the projection Jacobian, s² the
reprojection residual variance floored at the detector's ~0.05 px for the board, as the
force-plate registration, 0.15 px for a lone marker: :data:`MARKER_CORNER_SIGMA_FLOOR_PX`); the centre's standard uncertainty per axis of P comes from sampling the three
poses (Monte Carlo, fixed seed). It covers the camera's part only: where the clinician put the
markers on the malleoli is not seen by the camera (palpation repeatability is a few mm).

A frame that does not show the board (at least three of its markers) and both malleolus
markers is refused, naming what is missing. On the twin, :func:`render_malleoli` draws the
board and the two markers where a known truth puts them (``rt.drivers.synthetic_frames``).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from rt.drivers.synthetic_frames import MarkerBoard, PinholeCamera, render_board
from rt.errors import InputError
from rt.model.ankle import AnkleSetup, sensor_to_ankle_S, setup_from_malleoli
from rt.vision.aruco import detect_markers
from rt.vision.pnp import PnpPose, solve_marker_board, solve_pnp
from rt.vision.transforms import from_rvec, inverse, transform

#: Corner localization floor (px, 1 σ) when the residuals are smaller than that: the board's
#: many corners (as the force-plate registration); a lone malleolus marker's four corners
#: leave 2 degrees of freedom to estimate it from, and its sub-pixel corners were biased
#: inwards by ~0.1 px on the twin (its centre 1-2 mm too far along the optical axis), so its
#: floor is set at 0.15 px.
CORNER_SIGMA_FLOOR_PX = 0.05
MARKER_CORNER_SIGMA_FLOOR_PX = 0.15
#: Half the distance between the malleoli's markers the twin puts about the centre (m): adults'
#: bimalleolar width is 60-80 mm (``rt.model.ankle.MALLEOLI_WIDTH_RANGE_M``); the lateral tip
#: sits a little lower and further back than the medial one.
TWIN_HALF_WIDTH_M = 0.035
TWIN_LATERAL_OFFSET_M = (-0.006, -0.006)    # (along the foot, vertical), medial: the opposite


#: Rotation of a marker or board facing a camera that looks along -x of P: its X along +y_P
#: (the camera's right), Y along +z_P (up), Z (out of the printed face) along +x_P.
R_P_FACING = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


@dataclass(frozen=True)
class MalleoliRig:
    """The camera, the platform's board and the malleolus markers (lengths in m, P frame).

    Default: a 1280 × 960 px camera (f = 1000 px) 0.55 m in front of the platform's axis and
    0.3 m above its joint plane, looking back and down at the foot; a 2 × 3 board of 40 mm
    markers (ids 0-5) upright in front of the toes, below the ankle's height; 40 mm malleolus
    markers, lateral id 40, medial id 41 (DICT_4X4_50).
    """

    camera: PinholeCamera = field(default_factory=lambda: PinholeCamera(
        width=1280, height=960, fx=1000.0, fy=1000.0))
    board: MarkerBoard = field(default_factory=lambda: MarkerBoard(
        rows=2, cols=3, marker_length_m=0.04, gap_m=0.01, margin_m=0.01, first_id=0))
    #: The board's centre in P (its pose: :data:`R_P_FACING`).
    board_centre_P: tuple[float, float, float] = (0.25, 0.0, 0.05)
    marker_length_m: float = 0.04
    lateral_id: int = 40
    medial_id: int = 41
    #: Where the twin's camera is in P (the measurement estimates it from the board).
    camera_centre_P: tuple[float, float, float] = (0.55, 0.0, 0.30)
    #: Where it aims (between the board and an adult's ankle centre: both in view).
    look_at_P: tuple[float, float, float] = (0.12, 0.0, 0.10)
    noise_grey: float = 1.0

    def T_P_R(self) -> np.ndarray:
        """The board's pose in P (4 × 4)."""
        return transform(R_P_FACING, self.board_centre_P)

    def marker(self, marker_id: int) -> MarkerBoard:
        """A malleolus marker as a one-marker board (centred on its origin)."""
        return MarkerBoard(rows=1, cols=1, marker_length_m=self.marker_length_m,
                           gap_m=0.01, margin_m=0.005, first_id=marker_id)

    def T_P_C(self) -> np.ndarray:
        """The twin camera's pose in P, its optical axis towards ``look_at_P`` (image x along
        +y_P, y down)."""
        c = np.asarray(self.camera_centre_P, float)
        z = np.asarray(self.look_at_P, float) - c
        z /= np.linalg.norm(z)
        x = np.cross(z, [0.0, 0.0, 1.0])
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        return transform(np.column_stack((x, y, z)), c)


@dataclass(frozen=True)
class MalleoliMeasurement:
    """What one frame gave: the ankle setup (``source="camera"``), the markers' centres in P
    (m), the centre's standard uncertainty per axis of P (m, 1 σ) and the reprojection
    residual (px RMS)."""

    setup: AnkleSetup
    lateral_P: tuple[float, float, float]
    medial_P: tuple[float, float, float]
    centre_sigma_m: tuple[float, float, float]
    reprojection_rms_px: float

    @property
    def sigma_m(self) -> float:
        """The centre's uncertainty as one number: the largest per-axis σ (m)."""
        return max(self.centre_sigma_m)

    def as_dict(self) -> dict[str, Any]:
        return {"setup": self.setup.model_dump(), "lateral_P_m": list(self.lateral_P),
                "medial_P_m": list(self.medial_P),
                "centre_sigma_m": list(self.centre_sigma_m),
                "reprojection_rms_px": self.reprojection_rms_px}


def _marker_pose(corners_obj: np.ndarray, corners_px: np.ndarray, camera: PinholeCamera
                 ) -> PnpPose:
    """A lone malleolus marker's pose (its four corners, IPPE), with its covariance."""
    pose = solve_pnp(corners_obj, corners_px, camera.K, camera.dist_coeffs,
                     sigma_floor_px=MARKER_CORNER_SIGMA_FLOOR_PX)
    if pose is None:
        raise InputError("camera frame: solvePnP failed on the markers seen")
    return pose


def measure_malleoli(frame: np.ndarray, rig: MalleoliRig, side: str,
                     sensor_offset_m: Sequence[float], sole_above_sensor_m: float = 0.0,
                     samples: int = 300, seed: int = 0) -> MalleoliMeasurement:
    """The ankle setup from one camera frame (module docstring).

    Raises ``InputError`` naming what is missing (the board, the lateral or the medial
    malleolus marker) or implausible (``setup_from_malleoli``: markers too far apart or
    swapped, a height above the sole out of range).
    """
    if side not in ("left", "right"):
        raise InputError(f"side must be 'left' or 'right' (got {side!r})")
    # Sub-pixel corners: a lone malleolus marker has only its four corners to give its depth
    # (without refinement its centre was off by 5-9 mm along the optical axis on the twin).
    seen = dict(detect_markers(frame, rig.board.dictionary, subpixel=True))
    board_ids = [i for i in rig.board.ids if i in seen]
    missing = []
    if len(board_ids) < 3:
        missing.append(f"the platform's board (ids {rig.board.ids[0]}-{rig.board.ids[-1]}: "
                       f"{len(board_ids)} of its markers seen, at least 3 needed)")
    for name, marker_id in (("lateral", rig.lateral_id), ("medial", rig.medial_id)):
        if marker_id not in seen:
            missing.append(f"the {name} malleolus marker (id {marker_id})")
    if missing:
        raise InputError("camera frame refused: not seen: " + "; ".join(missing)
                         + ": put both malleolus markers and the platform's board in view")
    board = solve_marker_board([(rig.board.marker_corners_B(i), seen[i]) for i in board_ids],
                               rig.camera.K, rig.camera.dist_coeffs,
                               sigma_floor_px=CORNER_SIGMA_FLOOR_PX)
    if board is None:
        raise InputError("camera frame: solvePnP failed on the markers seen")
    r_b, t_b, cov_b = board.rvec, board.tvec, board.covariance
    markers = []
    residuals = [board.residuals_px]
    for marker_id in (rig.lateral_id, rig.medial_id):
        m = _marker_pose(rig.marker(marker_id).marker_corners_B(marker_id), seen[marker_id],
                         rig.camera)
        markers.append((m.tvec, m.covariance))
        residuals.append(m.residuals_px)
    T_P_R = rig.T_P_R()

    def to_P(rb: np.ndarray, tb: np.ndarray, centre_C: np.ndarray) -> np.ndarray:
        T_P_C = T_P_R @ inverse(from_rvec(rb, tb))
        return T_P_C[:3, :3] @ centre_C + T_P_C[:3, 3]

    lateral = to_P(r_b, t_b, markers[0][0])
    medial = to_P(r_b, t_b, markers[1][0])
    setup = setup_from_malleoli(
        (float(lateral[0]), float(lateral[1]), float(lateral[2])),
        (float(medial[0]), float(medial[1]), float(medial[2])), side,
        [float(v) for v in sensor_offset_m], sole_above_sensor_m)
    # Monte Carlo over the three poses: the centre's spread in P.
    rng = np.random.default_rng(seed)
    xb = rng.multivariate_normal(np.r_[r_b, t_b], cov_b, size=samples)
    centres = np.empty((samples, 3))
    draws = []
    for t_m, cov_m in markers:
        # Only the marker's translation matters for its centre (its rotation does not move it).
        draws.append(rng.multivariate_normal(t_m, cov_m[3:, 3:], size=samples))
    for k in range(samples):
        centres[k] = 0.5 * (to_P(xb[k, :3], xb[k, 3:], draws[0][k])
                            + to_P(xb[k, :3], xb[k, 3:], draws[1][k]))
    sigma = centres.std(axis=0)
    res = np.concatenate(residuals)
    return MalleoliMeasurement(
        setup=setup, lateral_P=(float(lateral[0]), float(lateral[1]), float(lateral[2])),
        medial_P=(float(medial[0]), float(medial[1]), float(medial[2])),
        centre_sigma_m=(float(sigma[0]), float(sigma[1]), float(sigma[2])),
        reprojection_rms_px=float(math.sqrt(float(np.mean(res ** 2)))))


def twin_malleoli(truth: AnkleSetup, sensor_offset_m: Sequence[float]
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(lateral, medial) malleolus tips in P (m) that the twin puts about a true ankle centre:
    ±``TWIN_HALF_WIDTH_M`` across the foot (medial +y for a right foot), the lateral tip
    lower and further back, symmetric so their midpoint is the centre."""
    s = np.asarray(sensor_offset_m, float)
    centre = s + np.asarray(sensor_to_ankle_S(truth))
    medial_y = TWIN_HALF_WIDTH_M if truth.side == "right" else -TWIN_HALF_WIDTH_M
    dx, dz = TWIN_LATERAL_OFFSET_M
    return (centre + np.array([dx, -medial_y, dz]), centre + np.array([-dx, medial_y, -dz]))


def render_malleoli(rig: MalleoliRig, lateral_P: Sequence[float] | np.ndarray | None,
                    medial_P: Sequence[float] | np.ndarray | None, seed: int = 0,
                    show_board: bool = True) -> np.ndarray:
    """The twin camera's frame (BGR uint8): the platform's board and the malleolus markers
    (None: that marker is not in view) at their poses in P, facing the camera's way
    (:data:`R_P_FACING`), with the rig's sensor noise."""
    T_C_P = inverse(rig.T_P_C())
    items: list[tuple[MarkerBoard, np.ndarray]] = []
    if show_board:
        items.append((rig.board, rig.T_P_R()))
    for marker_id, where in ((rig.lateral_id, lateral_P), (rig.medial_id, medial_P)):
        if where is not None:
            items.append((rig.marker(marker_id), transform(R_P_FACING, where)))
    grey = np.full((rig.camera.height, rig.camera.width), 255.0, np.float32)
    for board, T_P_board in items:
        T_C_board = T_C_P @ T_P_board
        rvec, _ = cv2.Rodrigues(T_C_board[:3, :3])
        img = render_board(board, rig.camera, (rvec.ravel(), T_C_board[:3, 3]), background=255)
        grey = np.minimum(grey, img[:, :, 0].astype(np.float32))
    if rig.noise_grey > 0:
        grey += np.random.default_rng(seed).normal(0.0, rig.noise_grey, grey.shape
                                                   ).astype(np.float32)
    out = np.clip(np.rint(grey), 0, 255).astype(np.uint8)
    return cv2.cvtColor(out, cv2.COLOR_GRAY2BGR)
