"""4 × 4 homogeneous rigid transforms (rotation R, translation p in m), named as the frames
they map: ``T_A_B`` takes coordinates in B to coordinates in A."""
from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np


def transform(R: np.ndarray, p: Sequence[float] | np.ndarray) -> np.ndarray:
    """T = [[R, p], [0, 1]] from a 3 × 3 rotation and a translation (m)."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, np.asarray(p, float)
    return T


def inverse(T: np.ndarray) -> np.ndarray:
    """T⁻¹ of a rigid transform (Rᵀ, −Rᵀ p): exact, no general matrix inversion."""
    R, p = T[:3, :3], T[:3, 3]
    return transform(R.T, -R.T @ p)


def from_rvec(rvec: Sequence[float] | np.ndarray, tvec: Sequence[float] | np.ndarray
              ) -> np.ndarray:
    """The transform of an OpenCV pose: Rodrigues rotation vector (rad) and translation (m)."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, float).reshape(3, 1))
    return transform(R, np.asarray(tvec, float).reshape(3))
