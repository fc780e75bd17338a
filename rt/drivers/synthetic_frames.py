"""Deterministic synthetic camera frames: a planar ArUco board seen by an ideal pinhole camera.

Used to test camera code without a camera, and as the digital twin's camera: the board's
pose in the camera frame is known exactly, so a pose estimator can be checked against it.

Frames and conventions (OpenCV's, so ``solvePnP`` results compare directly):

* Camera frame C: x right, y down, z along the optical axis. Pixel coordinates have pixel
  centres at integers (as ``projectPoints`` and the ArUco detector report corners).
* Board frame B: origin at the board centre, X to the right and Y up as the board is printed,
  Z out of the printed face. Marker corners are listed top-left, top-right, bottom-right,
  bottom-left, the order of ``ArucoDetector`` and of ``SOLVEPNP_IPPE_SQUARE`` object points.
* A pose is ``(rvec_CB, tvec_CB)``: ``p_C = R(rvec_CB) p_B + tvec_CB`` (m).

Rendering: the printed board is a texture (``px_per_m`` texture pixels per metre); the
plane-to-image homography ``K [r1 r2 t]`` warps it into an image ``supersample`` times larger
than the camera's, which is then area-averaged down, so edges are anti-aliased like a real
sensor's and corner positions stay unbiased. OpenCV 5 notes: markers come from
``cv2.aruco.generateImageMarker``; there is no ``estimatePoseSingleMarkers`` any more, use
``solvePnP`` (``SOLVEPNP_IPPE_SQUARE`` per marker).
"""
from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from rt.devices.interfaces import Camera
from rt.errors import ConfigurationError

Pose = tuple[np.ndarray, np.ndarray]
"""(rvec_CB, tvec_CB): Rodrigues vector (rad) and translation (m) of the board in the camera."""


@dataclass(frozen=True)
class PinholeCamera:
    """An ideal pinhole camera: ``width`` x ``height`` px, focal lengths ``fx``, ``fy`` (px),
    principal point ``cx``, ``cy`` (px; default the image centre), no distortion."""

    width: int = 640
    height: int = 480
    fx: float = 600.0
    fy: float = 600.0
    cx: float | None = None
    cy: float | None = None

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix (px)."""
        cx = (self.width - 1) / 2 if self.cx is None else self.cx
        cy = (self.height - 1) / 2 if self.cy is None else self.cy
        return np.array([[self.fx, 0.0, cx], [0.0, self.fy, cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        """Distortion coefficients (all zero)."""
        return np.zeros(5)


def _pixels(length_m: float, px_per_m: float, name: str) -> int:
    px = length_m * px_per_m
    if abs(px - round(px)) > 1e-6 or round(px) < 0:
        raise ConfigurationError(
            f"{name} = {length_m} m is not a whole number of texture pixels at "
            f"{px_per_m} px/m; change one of them")
    return round(px)


@dataclass(frozen=True)
class MarkerBoard:
    """A grid of ``rows`` x ``cols`` ArUco markers (ids ``first_id`` onward, row by row from
    the top left) printed on white; lengths in metres, all whole multiples of a texture pixel.
    """

    rows: int = 3
    cols: int = 4
    marker_length_m: float = 0.04
    gap_m: float = 0.02
    margin_m: float = 0.02
    first_id: int = 0
    dictionary: int = cv2.aruco.DICT_4X4_50
    px_per_m: float = 2400.0

    def __post_init__(self) -> None:
        if self.rows < 1 or self.cols < 1:
            raise ConfigurationError("a marker board needs at least one row and one column")
        if self.first_id < 0 or self.first_id + self.rows * self.cols > 50:
            raise ConfigurationError("DICT_4X4_50 has ids 0-49; the board needs more")
        for name in ("marker_length_m", "gap_m", "margin_m"):
            _pixels(getattr(self, name), self.px_per_m, name)

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(range(self.first_id, self.first_id + self.rows * self.cols))

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the printed board (m)."""
        return (self.cols * self.marker_length_m + (self.cols - 1) * self.gap_m
                + 2 * self.margin_m,
                self.rows * self.marker_length_m + (self.rows - 1) * self.gap_m
                + 2 * self.margin_m)

    def marker_corners_B(self, marker_id: int) -> np.ndarray:
        """(4, 3) corners of marker ``marker_id`` in the board frame (m), TL, TR, BR, BL."""
        k = marker_id - self.first_id
        if not 0 <= k < self.rows * self.cols:
            raise ConfigurationError(f"marker {marker_id} is not on this board")
        r, c = divmod(k, self.cols)
        width, height = self.size_m
        step = self.marker_length_m + self.gap_m
        x0 = -width / 2 + self.margin_m + c * step
        y0 = height / 2 - self.margin_m - r * step
        L = self.marker_length_m
        return np.array([[x0, y0, 0.0], [x0 + L, y0, 0.0],
                         [x0 + L, y0 - L, 0.0], [x0, y0 - L, 0.0]])

    @functools.cached_property
    def texture(self) -> np.ndarray:
        """The printed board as a grey uint8 image, ``px_per_m`` pixels per metre."""
        s = self.px_per_m
        L, gap, margin = (_pixels(v, s, n) for v, n in (
            (self.marker_length_m, "marker_length_m"), (self.gap_m, "gap_m"),
            (self.margin_m, "margin_m")))
        width = self.cols * L + (self.cols - 1) * gap + 2 * margin
        height = self.rows * L + (self.rows - 1) * gap + 2 * margin
        image = np.full((height, width), 255, np.uint8)
        aruco_dict = cv2.aruco.getPredefinedDictionary(self.dictionary)
        for k, marker_id in enumerate(self.ids):
            r, c = divmod(k, self.cols)
            u0, v0 = margin + c * (L + gap), margin + r * (L + gap)
            image[v0:v0 + L, u0:u0 + L] = cv2.aruco.generateImageMarker(aruco_dict, marker_id, L)
        image.flags.writeable = False
        return image

    def texture_to_board(self) -> np.ndarray:
        """3x3 map from texture pixel coordinates (u, v, 1) to board coordinates (X, Y, 1) (m).

        Texture pixel i covers [i - 0.5, i + 0.5], so the board edge is at u = -0.5.
        """
        width, height = self.size_m
        s = self.px_per_m
        return np.array([[1 / s, 0.0, 0.5 / s - width / 2],
                         [0.0, -1 / s, height / 2 - 0.5 / s],
                         [0.0, 0.0, 1.0]])


def rotation_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def pose_facing_camera(distance_m: float = 0.6, tilt_x_rad: float = 0.0,
                       tilt_y_rad: float = 0.0, roll_rad: float = 0.0,
                       offset_m: Sequence[float] = (0.0, 0.0)) -> Pose:
    """Board pose with its printed face toward the camera, upright, then tilted.

    ``R_CB = diag(1, -1, -1) Rx(tilt_x) Ry(tilt_y) Rz(roll)`` (tilts about the board's own
    axes), ``tvec_CB = (offset_x, offset_y, distance)`` (m).
    """
    R = np.diag([1.0, -1.0, -1.0]) @ rotation_x(tilt_x_rad) @ rotation_y(tilt_y_rad) \
        @ rotation_z(roll_rad)
    rvec, _ = cv2.Rodrigues(R)
    return rvec.reshape(3), np.array([float(offset_m[0]), float(offset_m[1]), distance_m])


def project_board_corners(board: MarkerBoard, camera: PinholeCamera, pose: Pose
                          ) -> dict[int, np.ndarray]:
    """Ideal image positions (px) of every marker's corners: id -> (4, 2)."""
    rvec, tvec = pose
    out = {}
    for marker_id in board.ids:
        pts, _ = cv2.projectPoints(board.marker_corners_B(marker_id), rvec, tvec, camera.K,
                                   camera.dist_coeffs)
        out[marker_id] = pts.reshape(4, 2)
    return out


def render_board(board: MarkerBoard, camera: PinholeCamera, pose: Pose, supersample: int = 3,
                 background: int = 128, noise_std: float = 0.0,
                 rng: np.random.Generator | None = None) -> np.ndarray:
    """BGR uint8 image of ``board`` at ``pose`` seen by ``camera``.

    ``background`` is the grey level around the board; ``noise_std`` adds Gaussian sensor
    noise (grey levels) drawn from ``rng`` (default: a generator seeded with 0).
    """
    rvec, tvec = (np.asarray(v, float).reshape(3) for v in pose)
    R, _ = cv2.Rodrigues(rvec)
    width, height = board.size_m
    corners_B = np.array([[-width / 2, -height / 2, 0], [width / 2, -height / 2, 0],
                          [width / 2, height / 2, 0], [-width / 2, height / 2, 0]])
    if np.any((corners_B @ R.T + tvec)[:, 2] <= 1e-3):
        raise ConfigurationError("the board must lie entirely in front of the camera")
    k = int(supersample)
    if k < 1:
        raise ConfigurationError("supersample must be a positive integer")
    # Supersampled pixel j covers low-resolution coordinate (j + 0.5) / k - 0.5.
    S = np.array([[k, 0.0, (k - 1) / 2], [0.0, k, (k - 1) / 2], [0.0, 0.0, 1.0]])
    H = S @ camera.K @ np.column_stack((R[:, 0], R[:, 1], tvec)) @ board.texture_to_board()
    big = cv2.warpPerspective(board.texture, H, (camera.width * k, camera.height * k),
                              flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                              borderValue=int(background))
    grey = cv2.resize(big, (camera.width, camera.height), interpolation=cv2.INTER_AREA) \
        if k > 1 else big
    if noise_std > 0:
        rng = np.random.default_rng(0) if rng is None else rng
        noisy = grey.astype(np.float32) + rng.normal(0.0, noise_std, grey.shape)
        grey = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
    return cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)


class SyntheticMarkerCamera(Camera):
    """A ``Camera`` that renders a ``MarkerBoard`` at a known pose (the twin's camera).

    Outputs: ``read()`` -> (BGR frame, t) with ``t = clock()``; ``last_pose`` is the pose
    rendered in the last frame (the ground truth).

    ``pose`` is a fixed ``(rvec_CB, tvec_CB)`` or a function of the time ``t`` (s) returning
    one, so the twin can move the board with the simulated platform. Frames are deterministic:
    noise comes from a generator seeded with ``seed``.
    """

    def __init__(self, board: MarkerBoard | None = None, camera: PinholeCamera | None = None,
                 pose: Pose | Callable[[float], Pose] | None = None,
                 clock: Callable[[], float] = time.monotonic, supersample: int = 3,
                 noise_std: float = 0.0, seed: int = 0) -> None:
        self.board = MarkerBoard() if board is None else board
        self.camera = PinholeCamera() if camera is None else camera
        self._pose = pose_facing_camera() if pose is None else pose
        self._clock = clock
        self.supersample = supersample
        self.noise_std = noise_std
        self._rng = np.random.default_rng(seed)
        self.last_pose: Pose | None = None

    def read(self) -> tuple[np.ndarray, float]:
        self._check_open()
        t = self._clock()
        pose = self._pose(t) if callable(self._pose) else self._pose
        frame = render_board(self.board, self.camera, pose, self.supersample,
                             noise_std=self.noise_std, rng=self._rng)
        self.last_pose = pose
        return frame, t

    def _close(self) -> None:
        pass
