"""A target's pose in the camera from its known points (PnP), with the pose's covariance.

The one estimator of every ArUco measurement (``calibration.registration``: the force plate
and the robot's board; ``patients.ankle_camera``: the platform's board and the malleolus
markers):

* :func:`solve_pnp` without a start: ``SOLVEPNP_IPPE_SQUARE``, the closed-form solution for
  one square marker's four corners (object points in its plane z = 0, in ArUco's corner
  order);
* :func:`solve_pnp` from a start: ``SOLVEPNP_ITERATIVE`` (Levenberg-Marquardt) over all the
  points, so every corner of a board refines the pose;
* :func:`solve_marker_board`: both, the first marker whose square solution exists giving the
  start.

Uncertainty: the pose's covariance over (rvec, tvec) is ``s² (JᵀJ)⁻¹``, J the Jacobian of the
projected points with respect to the pose (``cv2.projectPoints``) and s² the reprojection
residual variance (2N − 6 degrees of freedom), floored at the corner detector's own σ: at
the optimum of a clean synthetic frame the residuals can be far smaller than what a real
detector achieves, and the covariance must not claim more than that.

Units: object points in m, image points in px, rvec in rad (Rodrigues vector of the target
frame O in the camera frame C), tvec in m (O's origin in C).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from rt.errors import InputError
from rt.vision.transforms import from_rvec

#: Points a pose needs: a square marker's four corners (IPPE), and at least as many for LM.
MIN_POINTS = 4
#: Smallest/largest singular value of the projection Jacobian below which the points fix no
#: pose: collinear points give ~1e-18 (a rotation about their line moves none of them); one
#: 40 mm marker 0.6 m away, the weakest target measured, gives ~3e-3.
SINGULAR_RATIO = 1e-12


@dataclass(frozen=True)
class PnpPose:
    """A target's pose in the camera (frame O in C) with its 6 × 6 covariance over
    (rvec rad, tvec m) and the reprojection residuals (projected − observed, u and v
    interleaved, px)."""

    rvec: np.ndarray
    tvec: np.ndarray
    covariance: np.ndarray
    residuals_px: np.ndarray

    @property
    def rms_px(self) -> float:
        """The reprojection residual's root mean square (px, over u and v)."""
        return float(math.sqrt(float(np.mean(self.residuals_px ** 2))))

    def T_C_O(self) -> np.ndarray:
        """The pose as a 4 × 4 transform (O to C)."""
        return from_rvec(self.rvec, self.tvec)


def _points(name: str, points: np.ndarray, width: int) -> np.ndarray:
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != width:
        raise InputError(f"PnP: {name} must be an N × {width} array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"PnP: {name} hold NaN or infinite values")
    return arr


def _check(object_points: np.ndarray, image_points: np.ndarray, K: np.ndarray,
           sigma_floor_px: float, square: bool) -> tuple[np.ndarray, np.ndarray]:
    obj = _points("object points", object_points, 3)
    img = _points("image points", image_points, 2)
    if obj.shape[0] != img.shape[0]:
        raise InputError(f"PnP: {obj.shape[0]} object points but {img.shape[0]} image points: "
                         "one image point per object point")
    if square and obj.shape[0] != MIN_POINTS:
        raise InputError(f"PnP without a start solves one square marker: its 4 corners, got "
                         f"{obj.shape[0]} points (give a start to refine over more)")
    if obj.shape[0] < MIN_POINTS:
        raise InputError(f"PnP: {obj.shape[0]} points, at least {MIN_POINTS} needed")
    Km = np.asarray(K, dtype=np.float64)
    if Km.shape != (3, 3) or not np.all(np.isfinite(Km)) or Km[0, 0] <= 0 or Km[1, 1] <= 0:
        raise InputError(f"PnP: the camera matrix must be 3 × 3 with positive focal lengths, "
                         f"got {Km.tolist() if Km.size <= 9 else Km.shape}")
    if not (math.isfinite(sigma_floor_px) and sigma_floor_px > 0.0):
        raise InputError(f"PnP: the corner σ floor must be a positive number of px, got "
                         f"{sigma_floor_px}")
    return obj, img


def solve_pnp(object_points: np.ndarray, image_points: np.ndarray, K: np.ndarray,
              dist_coeffs: np.ndarray, *, sigma_floor_px: float,
              start: PnpPose | tuple[np.ndarray, np.ndarray] | None = None) -> PnpPose | None:
    """The pose of ``object_points`` (N × 3, m, in the target's frame) seen at
    ``image_points`` (N × 2, px) by a camera of intrinsics ``K`` and distortion
    ``dist_coeffs``: IPPE on a square marker's four corners when ``start`` is None, else
    Levenberg-Marquardt from ``start`` (a pose or (rvec, tvec)). Module docstring for the
    covariance.

    Returns None when OpenCV's solver finds no pose (the caller words what that means for
    its measurement). Raises ``InputError`` naming what is wrong with the input: shapes,
    counts, non-finite values, a bad camera matrix or σ floor, or points that fix no pose
    (a singular Jacobian: e.g. all on one line).
    """
    obj, img = _check(object_points, image_points, K, sigma_floor_px, start is None)
    if start is None:
        ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist_coeffs, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    else:
        r0, t0 = (start.rvec, start.tvec) if isinstance(start, PnpPose) else start
        ok, rvec, tvec = cv2.solvePnP(obj, img, K, dist_coeffs,
                                      rvec=np.array(r0, dtype=np.float64),
                                      tvec=np.array(t0, dtype=np.float64),
                                      useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        return None
    proj, jac = cv2.projectPoints(obj, rvec, tvec, K, dist_coeffs)
    resid = (proj.reshape(-1, 2) - img).ravel()
    dof = max(resid.size - 6, 1)
    s2 = max(float(resid @ resid) / dof, sigma_floor_px ** 2)
    J = jac[:, :6]
    singular = np.linalg.svd(J, compute_uv=False)
    if not singular[-1] > SINGULAR_RATIO * singular[0]:
        raise InputError(f"PnP: the {obj.shape[0]} points do not fix a pose (their projection "
                         "Jacobian is singular: points on one line, or repeated)")
    return PnpPose(rvec.reshape(3), tvec.reshape(3), s2 * np.linalg.inv(J.T @ J), resid)


def solve_marker_board(markers: Sequence[tuple[np.ndarray, np.ndarray]], K: np.ndarray,
                       dist_coeffs: np.ndarray, *, sigma_floor_px: float) -> PnpPose | None:
    """A board's pose from its markers seen, each (4 × 3 object corners m, 4 × 2 image
    corners px): the first marker whose square (IPPE) solution exists gives the start, then
    every corner refines it. None when no marker gives a start or the refinement fails;
    ``InputError`` as :func:`solve_pnp`, or for no markers at all."""
    if not markers:
        raise InputError("PnP: a board pose needs at least one marker's corners")
    start = None
    for obj, img in markers:
        start = solve_pnp(obj, img, K, dist_coeffs, sigma_floor_px=sigma_floor_px)
        if start is not None:
            break
    if start is None:
        return None
    return solve_pnp(np.concatenate([o for o, _ in markers]),
                     np.concatenate([i for _, i in markers]), K, dist_coeffs,
                     sigma_floor_px=sigma_floor_px, start=start)
