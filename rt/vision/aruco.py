"""ArUco markers found in one camera frame, as the PnP estimators take them."""
from __future__ import annotations

import cv2
import numpy as np

from rt.errors import InputError


def detect_markers(frame: np.ndarray, dictionary: int, subpixel: bool = False
                   ) -> list[tuple[int, np.ndarray]]:
    """(id, corners) of every marker of the predefined ``dictionary`` (``cv2.aruco.DICT_*``)
    seen in a BGR uint8 frame, in the detector's order; corners are 4 × 2 float64 px in
    ArUco's order (top-left, top-right, bottom-right, bottom-left of the printed marker).

    ``subpixel`` refines the corners (``CORNER_REFINE_SUBPIX``): a lone marker has only its
    four corners to give its depth, so it needs them to a fraction of a pixel; a board's many
    corners average that out. Raises ``InputError`` for a frame that is not H × W × 3 uint8.
    """
    if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
        raise InputError(f"camera frame: expected a BGR uint8 image (H × W × 3), got "
                         f"{frame.dtype} {frame.shape}")
    params = cv2.aruco.DetectorParameters()
    if subpixel:
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(dictionary), params)
    corners, ids, _ = detector.detectMarkers(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
    if ids is None:
        return []
    return [(int(i), c.reshape(4, 2).astype(np.float64)) for c, i in zip(corners, ids.ravel())]
