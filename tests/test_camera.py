"""OpenCV camera backend and the synthetic ArUco frames: write a video, read it back, recover
the known board pose."""
from __future__ import annotations

import itertools

import cv2
import numpy as np
import pytest

from rt.devices import registry
from rt.drivers.camera_cv import OpenCvCamera
from rt.drivers.synthetic_frames import (
    MarkerBoard,
    PinholeCamera,
    SyntheticMarkerCamera,
    pose_facing_camera,
    project_board_corners,
    render_board,
)
from rt.errors import ConfigurationError, HardwareError

BOARD = MarkerBoard()            # 3 x 4 markers of 40 mm, DICT_4X4_50 ids 0-11
CAMERA = PinholeCamera()         # 640 x 480 px, f = 600 px
POSES = [
    pose_facing_camera(0.60),
    pose_facing_camera(0.55, 0.30, -0.20, 0.10, (0.02, -0.01)),
    pose_facing_camera(0.50, -0.25, 0.35, -0.50, (-0.03, 0.02)),
    pose_facing_camera(0.70, 0.20, 0.20, 2.50, (0.04, 0.03)),
    pose_facing_camera(0.65, -0.35, -0.10, -2.00, (-0.05, -0.02)),
]
# Tolerances, from ~0.2-0.4 px corner error of the ArUco sub-pixel refiner after MJPEG
# (measured: board <= 0.45 mm and <= 0.08 deg; one 40 mm marker alone <= 1.1 % of the
# distance and <= 1.2 deg). Set at 4-5x (board) and 2.5x (marker) the measured worst case.
BOARD_TRANSLATION_TOL_M = 2e-3
BOARD_ROTATION_TOL_DEG = 0.3
MARKER_CENTRE_TOL_REL = 0.025
MARKER_ROTATION_TOL_DEG = 3.0


def detector() -> cv2.aruco.ArucoDetector:
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    # The default relative window (0.3 of a marker module) is ~1.5 px here and biases corners
    # by ~0.4 px; half a module halves that.
    params.relativeCornerRefinmentWinSize = 0.5
    return cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(BOARD.dictionary), params)


def rotation_error_deg(rvec_a, rvec_b) -> float:
    Ra, _ = cv2.Rodrigues(np.asarray(rvec_a, float))
    Rb, _ = cv2.Rodrigues(np.asarray(rvec_b, float))
    return float(np.degrees(np.linalg.norm(cv2.Rodrigues(Ra @ Rb.T)[0])))


@pytest.fixture(scope="module")
def video(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("video") / "board.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0,
                             (CAMERA.width, CAMERA.height))
    assert writer.isOpened()
    for pose in POSES:
        writer.write(render_board(BOARD, CAMERA, pose))
    writer.release()
    return str(path)


def test_video_round_trip_recovers_the_known_poses(video):
    det = detector()
    L = BOARD.marker_length_m
    # SOLVEPNP_IPPE_SQUARE needs exactly this corner order and layout.
    square = np.array([[-L / 2, L / 2, 0], [L / 2, L / 2, 0], [L / 2, -L / 2, 0],
                       [-L / 2, -L / 2, 0]])
    with OpenCvCamera(video) as cam:
        assert cam.resolution == (CAMERA.width, CAMERA.height)
        stamps = []
        for rvec_true, tvec_true in POSES:
            frame, t = cam.read()
            stamps.append(t)
            assert frame.shape == (CAMERA.height, CAMERA.width, 3) and frame.dtype == np.uint8
            corners, ids, _ = det.detectMarkers(frame)
            assert ids is not None and sorted(ids.ravel()) == list(BOARD.ids)
            ids = ids.ravel()

            # The whole board: all 48 corners in one solvePnP.
            obj = np.concatenate([BOARD.marker_corners_B(i) for i in ids])
            img = np.concatenate([c.reshape(4, 2) for c in corners])
            ok, rvec, tvec = cv2.solvePnP(obj, img, CAMERA.K, CAMERA.dist_coeffs)
            assert ok
            assert np.linalg.norm(tvec.ravel() - tvec_true) <= BOARD_TRANSLATION_TOL_M
            assert rotation_error_deg(rvec, rvec_true) <= BOARD_ROTATION_TOL_DEG

            # Each marker alone, the OpenCV 5 replacement of estimatePoseSingleMarkers.
            R_true, _ = cv2.Rodrigues(rvec_true)
            for c, marker_id in zip(corners, ids):
                ok, rvec_m, tvec_m = cv2.solvePnP(square, c.reshape(4, 2), CAMERA.K,
                                                  CAMERA.dist_coeffs,
                                                  flags=cv2.SOLVEPNP_IPPE_SQUARE)
                assert ok
                centre_C = R_true @ BOARD.marker_corners_B(marker_id).mean(axis=0) + tvec_true
                assert (np.linalg.norm(tvec_m.ravel() - centre_C)
                        <= MARKER_CENTRE_TOL_REL * tvec_true[2])
                assert rotation_error_deg(rvec_m, rvec_true) <= MARKER_ROTATION_TOL_DEG
        assert stamps == sorted(stamps)
        assert cam.frames_read == len(POSES)
        with pytest.raises(HardwareError, match="no frame"):      # end of the file
            cam.read()


def test_nonexistent_source_is_a_hardware_error(tmp_path):
    with pytest.raises(HardwareError, match="cannot open camera source"):
        OpenCvCamera(str(tmp_path / "missing.avi"))


def test_close_is_idempotent_and_reading_after_close_fails(video):
    cam = OpenCvCamera(video)
    cam.read()
    cam.close()
    cam.close()
    with pytest.raises(HardwareError, match="closed"):
        cam.read()


def test_opencv_camera_uses_the_given_clock(video):
    ticks = itertools.count(100.0, 0.5)
    with OpenCvCamera(video, clock=lambda: next(ticks)) as cam:
        assert [cam.read()[1] for _ in range(3)] == [100.0, 100.5, 101.0]


def test_rendered_corners_lie_where_the_pinhole_model_puts_them():
    # Frontal board, 0.8 m: compare the edge crossings with the projected corners directly.
    pose = pose_facing_camera(0.8)
    grey = render_board(BOARD, CAMERA, pose)[:, :, 0].astype(float)
    tl = project_board_corners(BOARD, CAMERA, pose)[0][0]     # marker 0, top-left (x, y)
    row = round(tl[1]) + 5                               # inside the marker's border
    col = round(tl[0]) + 5
    # Sub-pixel edge position where the intensity crosses half way between white and black.
    def crossing(profile: np.ndarray, start: int) -> float:
        half = (profile.max() + profile.min()) / 2
        k = int(np.argmax(profile < half))
        return start + k - 1 + (profile[k - 1] - half) / (profile[k - 1] - profile[k])
    x0 = int(tl[0]) - 4
    y0 = int(tl[1]) - 4
    # Pixel centres are integers, so the edge is at the projected corner itself. Linear
    # interpolation between box-averaged pixels misplaces a step edge by at most
    # 1.5 - sqrt(2) = 0.086 px, hence the 0.1 px tolerance.
    assert crossing(grey[row, x0:x0 + 9], x0) == pytest.approx(tl[0], abs=0.1)
    assert crossing(grey[y0:y0 + 9, col], y0) == pytest.approx(tl[1], abs=0.1)


def test_synthetic_camera_is_deterministic_and_reports_its_pose():
    clock = itertools.count(0.0, 0.01)
    def moving(t: float):
        return pose_facing_camera(0.6, tilt_x_rad=0.2 * t)
    a = SyntheticMarkerCamera(pose=moving, clock=lambda: next(clock), noise_std=2.0, seed=7)
    b = SyntheticMarkerCamera(pose=moving, clock=itertools.count(0.0, 0.01).__next__,
                              noise_std=2.0, seed=7)
    for _ in range(2):
        (fa, ta), (fb, tb) = a.read(), b.read()
        assert ta == tb and np.array_equal(fa, fb)
    assert np.allclose(a.last_pose[0], moving(0.01)[0])
    a.close()
    a.close()
    with pytest.raises(HardwareError):
        a.read()


def test_board_behind_the_camera_is_refused():
    rvec, tvec = pose_facing_camera(0.6)
    with pytest.raises(ConfigurationError, match="in front of the camera"):
        render_board(BOARD, CAMERA, (rvec, -tvec))


def test_registered_camera_backends(video):
    with registry.create("camera", "opencv", source=video) as cam:
        assert isinstance(cam, OpenCvCamera)
    with registry.create("camera", "synthetic") as cam:
        frame, _ = cam.read()
        assert frame.shape == (480, 640, 3)
