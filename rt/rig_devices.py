"""The real rig's device bundle for the loop (``talus rt serve --backend rig``).

The same loop as on the twin (``rt.position_loop``), with the rig's cards picked from the
device registry by the backend names in the ``rig:`` config (``rt.devices.rig_config``):
PCL-833 encoders, the PCI-1720 cards in failover order, the ATI sensor over RDT or CAN, and
the stop inputs. Nothing here steps a simulation: on the rig the world moves by itself.

``port_io`` and ``comedi`` replace the machine's ``/dev/port`` and comedilib (tests hand in the
twin's register-level fakes); everything above them is the code that runs on the rig.
"""
from __future__ import annotations

import logging
from typing import Any

from rt.devices import registry
from rt.devices.rig_config import AtiCan, AtiRdt, RigConfig
from rt.drivers.pcl833 import InputMode
from rt.drivers.port_io import PortIO
from rt.errors import HardwareError
from rt.model.description import RobotDescription
from rt.position_loop import Devices

log = logging.getLogger(__name__)


def rig_devices(config: RigConfig, description: RobotDescription, *,
                port_io: PortIO | None = None, comedi: Any = None) -> Devices:
    """Open every device of ``config`` and return them as the loop's ``Devices``.

    ``description`` gives the defaults the rig shares with the model: metres per encoder
    count and the DAC command limit (V). A device that fails to open closes those opened
    before it and the error propagates (``BackendUnavailableError`` on a machine without the
    card or its library, ``ConfigurationError`` for wiring the card does not have).
    """
    opened: list[Any] = []

    def open_(kind: str, backend: str, **kwargs: Any) -> Any:
        device = registry.create(kind, backend, **kwargs)
        opened.append(device)
        return device

    try:
        enc = config.encoders
        encoders = open_(
            "encoders", enc.backend, port_io=port_io, base=enc.base, port_path=enc.port_path,
            m_per_count=enc.m_per_count or description.encoder.m_per_count, sign=enc.sign,
            channels=enc.channels, input_mode=InputMode[enc.input_mode.upper()],
            reset_on_open=enc.reset_on_open, origin_m=enc.origin_m)
        cards = [open_("actuators", card.backend, device=card.device, subdevice=card.subdevice,
                       channels=card.channels, range_index=card.range_index,
                       limit_v=description.drive.command_limit_v,
                       enable_line=card.enable_line.model_dump(), lib=comedi)
                 for card in config.dac_cards]
        force = open_("force_torque", config.force_torque.backend,
                      **_sensor_kwargs(config.force_torque))
        s = config.stop_inputs
        stops = open_("digital_inputs", s.backend, device=s.device, subdevice=s.subdevice,
                      estop_channel=s.estop_channel, hand_stop_channel=s.hand_stop_channel,
                      healthy_level=s.healthy_level, lib=comedi)
        m = config.amplifier_monitor
        monitor = None if m is None else open_(
            "amplifier_monitor", m.backend, device=m.device, subdevice=m.subdevice,
            channels=m.channels, range_index=m.range_index, volts_per_volt=m.volts_per_volt,
            lib=comedi)
    except BaseException:
        _close_all(opened)
        raise
    return Devices(encoders, cards, force, stops,
                   monitor=None if monitor is None else monitor.read_volts,
                   close=lambda: _close_all(opened))


def _close_all(devices: list[Any]) -> None:
    """Close in reverse order of opening, every device attempted. A device that fails to close
    (a dead DAC card cannot write its 0 V) is logged, not raised: at shutdown the rest must
    still be released, and the fault is already in the event log."""
    for device in reversed(devices):
        try:
            device.close()
        except HardwareError as exc:
            log.error("closing %s failed: %s", type(device).__name__, exc)


def _sensor_kwargs(cfg: AtiRdt | AtiCan) -> dict[str, Any]:
    return cfg.model_dump(exclude={"backend"})

