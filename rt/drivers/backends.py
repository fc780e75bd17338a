"""Registers the real drivers with the backend registry (lazily: nothing is imported here).

Call ``register()`` once at start-up; it is idempotent. Choosing a backend whose library or
device is missing fails at construction with one ``BackendUnavailableError``.
"""
from __future__ import annotations

from rt.devices.registry import register_backend

#: (kind, name, "module:Class") of every driver in this package.
DRIVERS: tuple[tuple[str, str, str], ...] = (
    ("encoders", "pcl833", "rt.drivers.pcl833:Pcl833Encoders"),
    ("actuators", "pci1720", "rt.drivers.pci1720:Pci1720Outputs"),
    ("camera", "opencv", "rt.drivers.camera_cv:OpenCvCamera"),
    ("camera", "synthetic", "rt.drivers.synthetic_frames:SyntheticMarkerCamera"),
)


def register() -> None:
    """Register the PCL-833, PCI-1720, OpenCV and synthetic camera backends."""
    for kind, name, target in DRIVERS:
        register_backend(kind, name, target)
