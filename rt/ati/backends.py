"""Registration of the ATI force/torque backends (the lead calls ``register()`` at start-up).

Only the "module:Class" strings are registered; the modules (and python-can) are imported when
a configuration picks the backend.
"""
from __future__ import annotations

from rt.devices.registry import register_backend


def register() -> None:
    """Register ``ati_rdt`` (Net F/T over UDP RDT) and ``ati_can`` (Net F/T over CAN)."""
    register_backend("force_torque", "ati_rdt", "rt.ati.rdt_client:RdtForceTorqueSensor")
    register_backend("force_torque", "ati_can", "rt.ati.can_client:AtiCanForceTorqueSensor")
