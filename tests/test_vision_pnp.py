"""The one PnP estimator (rt.vision.pnp) that the force-plate registration and the malleoli
measurement share: a known pose comes back from synthetic projections within what its own
covariance states, the covariance shrinks with more points and less noise and is calibrated
against the scatter it predicts, and bad input is refused naming what was wrong."""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from rt.drivers.synthetic_frames import (
    MarkerBoard,
    PinholeCamera,
    pose_facing_camera,
    project_board_corners,
    render_board,
)
from rt.errors import InputError
from rt.vision.aruco import detect_markers
from rt.vision.pnp import PnpPose, solve_marker_board, solve_pnp
from rt.vision.transforms import from_rvec, inverse, transform

CAMERA = PinholeCamera(width=1280, height=960, fx=1000.0, fy=1000.0)
BOARD = MarkerBoard(rows=3, cols=4, marker_length_m=0.04, gap_m=0.01, margin_m=0.01)
#: A tilted board 0.6 m away, off the optical axis: no symmetric special case.
POSE = pose_facing_camera(0.6, tilt_x_rad=0.3, tilt_y_rad=-0.2, roll_rad=0.1,
                          offset_m=(0.03, -0.02))
FLOOR_PX = 0.05


def _markers(sigma_px: float, seed: int, ids=None) -> list[tuple[np.ndarray, np.ndarray]]:
    """The board's markers projected at POSE, each corner moved by N(0, σ²) px."""
    rng = np.random.default_rng(seed)
    ideal = project_board_corners(BOARD, CAMERA, POSE)
    return [(BOARD.marker_corners_B(i), ideal[i] + rng.normal(0.0, sigma_px, (4, 2)))
            for i in (ids if ids is not None else BOARD.ids)]


def _solve(markers) -> PnpPose:
    pose = solve_marker_board(markers, CAMERA.K, CAMERA.dist_coeffs, sigma_floor_px=FLOOR_PX)
    assert pose is not None
    return pose


def _angle(R: np.ndarray) -> float:
    return math.acos(max(-1.0, min(1.0, (np.trace(R) - 1.0) / 2.0)))


def test_a_known_pose_is_recovered_within_its_stated_uncertainty() -> None:
    T_true = from_rvec(*POSE)
    # Noise-free: the exact pose, to the solver's convergence (nm, nrad).
    exact = _solve(_markers(0.0, 0))
    assert np.max(np.abs(exact.tvec - POSE[1])) < 1e-8
    assert _angle(exact.T_C_O()[:3, :3] @ T_true[:3, :3].T) < 1e-8
    assert exact.rms_px < 1e-6
    # With 0.2 px corner noise (a real detector's order): every component of the pose within
    # 4 σ of the covariance it states, and the pose good to a millimetre and a few tenths of
    # a degree (48 corners of a 0.2 m board at 0.6 m with f = 1000 px).
    for seed in range(5):
        pose = _solve(_markers(0.2, seed))
        sigma = np.sqrt(np.diag(pose.covariance))
        err = np.r_[cv2.Rodrigues(pose.T_C_O()[:3, :3] @ T_true[:3, :3].T)[0].ravel(),
                    pose.tvec - POSE[1]]
        assert np.all(np.abs(err[3:]) <= 4.0 * sigma[3:]), (seed, err, sigma)
        assert np.linalg.norm(err[3:]) < 1e-3
        assert np.linalg.norm(err[:3]) < math.radians(0.3)
        assert pose.rms_px == pytest.approx(0.2, rel=0.3)


def test_one_square_marker_alone_gives_its_pose() -> None:
    obj, img = _markers(0.0, 0, ids=[5])[0]
    pose = solve_pnp(obj, img, CAMERA.K, CAMERA.dist_coeffs, sigma_floor_px=FLOOR_PX)
    assert pose is not None
    assert np.max(np.abs(pose.tvec - POSE[1])) < 1e-8
    # Four corners, 8 residuals, 6 unknowns: the covariance rests on the floor here.
    assert pose.covariance.shape == (6, 6)
    assert np.all(np.linalg.eigvalsh(pose.covariance) > 0.0)


def test_the_covariance_shrinks_with_more_points_and_less_noise() -> None:
    few = _solve(_markers(0.3, 1, ids=BOARD.ids[:3]))
    many = _solve(_markers(0.3, 1))
    # Translation variance: 12 markers over a wider board against 3 in one row.
    assert np.trace(many.covariance[3:, 3:]) < 0.5 * np.trace(few.covariance[3:, 3:])
    assert np.trace(many.covariance[:3, :3]) < 0.5 * np.trace(few.covariance[:3, :3])
    # The same corners with 1/4 of the noise: s² falls ≈ 16-fold, J is the same pose's.
    quiet = _solve(_markers(0.075, 1))
    ratio = np.trace(many.covariance) / np.trace(quiet.covariance)
    assert 8.0 < ratio < 32.0
    # Below the detector's floor the covariance stops shrinking: σ_floor² (JᵀJ)⁻¹.
    silent = _solve(_markers(0.0, 1))
    floored = _solve(_markers(0.001, 1))
    np.testing.assert_allclose(silent.covariance, floored.covariance, rtol=1e-3)


def test_the_covariance_predicts_the_scatter_of_repeated_frames() -> None:
    # 200 frames of the same board with 0.3 px noise: the stated σ of tvec (a 48-corner board
    # estimates s² to ~10 %) against the frames' scatter (its own sampling error ~5 % at
    # n = 200): within 30 %.
    poses = [_solve(_markers(0.3, seed)) for seed in range(200)]
    scatter = np.std([p.tvec for p in poses], axis=0)
    stated = np.sqrt(np.mean([np.diag(p.covariance)[3:] for p in poses], axis=0))
    np.testing.assert_allclose(scatter, stated, rtol=0.3)


@pytest.mark.parametrize("obj, img, start, words", [
    (np.zeros((4, 2)), np.zeros((4, 2)), None, r"object points must be an N × 3 array"),
    (np.zeros((4, 3)), np.zeros((4, 3)), None, r"image points must be an N × 2 array"),
    (np.zeros((4, 3)), np.zeros((5, 2)), None, r"4 object points but 5 image points"),
    (np.full((4, 3), np.nan), np.zeros((4, 2)), None, r"object points hold NaN"),
    (np.zeros((8, 3)), np.zeros((8, 2)), None, r"one square marker: its 4 corners, got 8"),
    (np.zeros((3, 3)), np.zeros((3, 2)), (np.zeros(3), np.ones(3)), r"3 points, at least 4"),
])
def test_bad_points_are_refused_naming_what_is_wrong(obj, img, start, words) -> None:
    with pytest.raises(InputError, match=words):
        solve_pnp(obj, img, CAMERA.K, CAMERA.dist_coeffs, sigma_floor_px=FLOOR_PX, start=start)


def test_a_bad_camera_or_floor_or_degenerate_points_are_refused() -> None:
    obj, img = _markers(0.0, 0, ids=[0])[0]
    with pytest.raises(InputError, match="camera matrix must be 3 × 3 with positive focal"):
        solve_pnp(obj, img, np.eye(3) * -1.0, CAMERA.dist_coeffs, sigma_floor_px=FLOOR_PX)
    with pytest.raises(InputError, match="σ floor must be a positive number of px, got 0.0"):
        solve_pnp(obj, img, CAMERA.K, CAMERA.dist_coeffs, sigma_floor_px=0.0)
    with pytest.raises(InputError, match="at least one marker"):
        solve_marker_board([], CAMERA.K, CAMERA.dist_coeffs, sigma_floor_px=FLOOR_PX)
    # Four points on one line seen from a start: no pose is fixed by them.
    line = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.02, 0.0, 0.0], [0.03, 0.0, 0.0]])
    px = cv2.projectPoints(line, POSE[0], POSE[1], CAMERA.K, CAMERA.dist_coeffs)[0]
    with pytest.raises(InputError, match="do not fix a pose"):
        solve_pnp(line, px.reshape(4, 2), CAMERA.K, CAMERA.dist_coeffs,
                  sigma_floor_px=FLOOR_PX, start=POSE)


def test_transforms_compose_and_invert_exactly() -> None:
    T = from_rvec(*POSE)
    np.testing.assert_allclose(inverse(T) @ T, np.eye(4), atol=1e-15)
    assert np.array_equal(transform(T[:3, :3], T[:3, 3]), T)
    assert np.array_equal(_solve(_markers(0.0, 0)).T_C_O()[3], [0.0, 0.0, 0.0, 1.0])


def test_markers_are_detected_in_a_rendered_frame_and_a_bad_frame_is_refused() -> None:
    frame = render_board(BOARD, CAMERA, POSE, background=255)
    seen = dict(detect_markers(frame, BOARD.dictionary, subpixel=True))
    assert sorted(seen) == list(BOARD.ids)
    ideal = project_board_corners(BOARD, CAMERA, POSE)
    # Rendered corners found to a fraction of a pixel (sub-pixel refinement on).
    assert max(float(np.max(np.abs(seen[i] - ideal[i]))) for i in BOARD.ids) < 0.5
    assert detect_markers(np.full_like(frame, 255), BOARD.dictionary) == []
    with pytest.raises(InputError, match=r"expected a BGR uint8 image \(H × W × 3\), got"):
        detect_markers(frame[:, :, 0], BOARD.dictionary)
