"""Camera backend through OpenCV's ``cv2.VideoCapture`` (a device index, a file or a URL).

Imported only when the "opencv" camera backend is chosen (the registry is lazy).
"""
from __future__ import annotations

import os
import time
from collections.abc import Callable

import cv2
import numpy as np

from rt.devices.interfaces import Camera
from rt.errors import HardwareError


class OpenCvCamera(Camera):
    """BGR frames (uint8, H x W x 3) from a camera, a video file or a stream URL.

    Outputs: ``read()`` -> (frame, t) with ``t`` the host time (s, ``clock``, monotonic by
    default) taken when the frame was grabbed, before it was decoded; ``frames_read``.

    Parameters:

    * ``source``: an int is a device index (``/dev/video<N>``); a str or path is a file name,
      URL or pipeline string as ``cv2.VideoCapture`` understands it.
    * ``width``, ``height`` (px), ``fps`` (frames/s): requested capture settings, or ``None``
      to keep the device's. Cameras pick their nearest mode and files ignore them, so the
      values in effect are read back into ``resolution`` and ``fps``.
    * ``api_preference``: a ``cv2.CAP_*`` backend (for example ``cv2.CAP_V4L2``), default any.

    Raises ``HardwareError`` when the source cannot be opened or a frame cannot be read
    (end of a file, unplugged camera).
    """

    def __init__(self, source: int | str | os.PathLike = 0, width: int | None = None,
                 height: int | None = None, fps: float | None = None,
                 api_preference: int = cv2.CAP_ANY,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.source = source if isinstance(source, int) else os.fspath(source)
        self._clock = clock
        self.frames_read = 0
        self._cap = cv2.VideoCapture(self.source, api_preference)
        if not self._cap.isOpened():
            self._cap.release()
            self._closed = True
            raise HardwareError(
                f"cannot open camera source {self.source!r}: no such device, file or stream, "
                f"or no OpenCV backend can decode it")
        # Why: order matters on V4L2 (size before rate), and a refused setting is not an
        # error here; the read-back below says what the device actually does.
        if width is not None:
            self._cap.set(cv2.CAP_PROP_FRAME_WIDTH, float(width))
        if height is not None:
            self._cap.set(cv2.CAP_PROP_FRAME_HEIGHT, float(height))
        if fps is not None:
            self._cap.set(cv2.CAP_PROP_FPS, float(fps))

    @property
    def resolution(self) -> tuple[int, int]:
        """(width, height) in pixels as reported by the capture backend."""
        self._check_open()
        return (int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH)),
                int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))

    @property
    def fps(self) -> float:
        """Frame rate (frames/s) as reported by the capture backend (0 if unknown)."""
        self._check_open()
        return float(self._cap.get(cv2.CAP_PROP_FPS))

    def read(self) -> tuple[np.ndarray, float]:
        self._check_open()
        if not self._cap.grab():
            raise HardwareError(
                f"no frame from camera source {self.source!r} (end of file, camera unplugged "
                f"or driver error) after {self.frames_read} frames")
        t = self._clock()
        ok, frame = self._cap.retrieve()
        if not ok or frame is None:
            raise HardwareError(f"camera source {self.source!r} grabbed a frame it could not "
                                f"decode")
        if frame.ndim == 2:
            frame = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        elif frame.shape[2] == 4:
            frame = cv2.cvtColor(frame, cv2.COLOR_BGRA2BGR)
        self.frames_read += 1
        return frame, t

    def _close(self) -> None:
        self._cap.release()
