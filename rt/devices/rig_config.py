"""The real rig's devices, typed (the ``rig:`` section of ``talus rt serve --backend rig``).

Every field has a documented default: the thesis rig (3.1-3.2) where the thesis says, our
assumption where it is silent (marked *assumed*). ``rt/data/rig_example.yaml`` is a complete
RT config for that rig. What each card is:

* ``encoders``: the PCL-833 quadrature card (ISA, base 0x220, read through ``/dev/port``);
  the counters are reset to their midpoint at start-up (thesis 3.2.2) while the sliders rest
  at ``origin_m`` (*assumed*: on their lower end stops, 0 m, as they sink with the drives off).
* ``dac_cards``: the two PCI-1720 cards through comedi (``/dev/comedi0``, ``/dev/comedi1``),
  ±10 V range, commands clamped at the robot description's ``command_limit_v`` (6 V). The
  second card takes over when the first fails (thesis 3.7.3). *Assumed* wiring: each card
  reaches the amplifier inputs through a relay driven by its ``enable_line``, so exactly the
  enabled card commands the amplifiers; the PCI-1720 has no digital output, so the lines sit
  on a digital I/O card (``/dev/comedi2``, subdevice 1, lines 0 and 1).
* ``force_torque``: the ATI sensor over UDP RDT (Net F/T, 192.168.1.1:49152) or over CAN
  (python-can channel); counts per unit from the sensor's configuration page.
* ``stop_inputs``: the hardware e-stop chain and the hand-held stop on the digital I/O card's
  inputs (subdevice 0, lines 0 and 1), normally closed (``rt.drivers.comedi_dio``).
* ``amplifier_monitor`` (optional, *assumed* wiring, default none): the three amplifier
  inputs read back by an analog-input card (``rt.drivers.comedi_ai``), so the failover also
  catches a DAC channel that accepts writes but outputs nothing. Without it the failover
  reacts to write errors only (a dead output then shows as a tracking error: soft stop).
"""
from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from rt.ati.rdt import DEFAULT_COUNTS_PER_FORCE, DEFAULT_COUNTS_PER_TORQUE, RDT_PORT

Vec3 = tuple[float, float, float]
Axis = Annotated[int, Field(ge=0, le=63)]
Sign = Literal[1, -1]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class EncoderCard(_Strict):
    """The PCL-833 (thesis 3.2.2); see ``rt.drivers.pcl833.Pcl833Encoders``."""

    backend: Literal["pcl833"] = "pcl833"
    #: I/O base address set on the card's DIP switches (YAML: 0x220).
    base: int = Field(default=0x220, ge=0, le=0x3F0)
    #: The kernel's port device (root needed).
    port_path: str = "/dev/port"
    #: Metres of slider travel per count; None: the robot description's encoder.m_per_count.
    m_per_count: float | None = Field(default=None, gt=0.0)
    #: +1 or -1 per axis, so that q grows upward along each guide.
    sign: tuple[Sign, Sign, Sign] = (1, 1, 1)
    #: Card channel (1-3) of each axis; thesis wiring: axis i on channel i+1.
    channels: tuple[int, int, int] = (1, 2, 3)
    #: Quadrature multiplication (thesis: x1); m_per_count must match it.
    input_mode: Literal["x1", "x2", "x4"] = "x1"
    #: Reset the counters to the midpoint at start-up (thesis); False keeps counting positions.
    reset_on_open: bool = True
    #: Slider positions (m) the counters' reset value stands for (assumed: the end stops, 0 m).
    origin_m: Vec3 = (0.0, 0.0, 0.0)


class EnableLine(_Strict):
    """A digital output that connects one DAC card to the amplifiers (assumed wiring)."""

    device: str = "/dev/comedi2"
    subdevice: Axis = 1
    channel: Axis = 0
    active_high: bool = True


class DacCard(_Strict):
    """One PCI-1720 (thesis 3.2.3); see ``rt.drivers.pci1720.Pci1720Outputs``."""

    backend: Literal["pci1720"] = "pci1720"
    device: str = "/dev/comedi0"
    #: Analog-output subdevice (adv_pci1720: 0).
    subdevice: Axis = 0
    #: DAC channel of each axis (thesis: 0, 1, 2).
    channels: tuple[int, int, int] = (0, 1, 2)
    #: comedi range index (adv_pci1720: 3 = ±10 V).
    range_index: Axis = 3
    enable_line: EnableLine = EnableLine()


def _default_cards() -> list[DacCard]:
    return [DacCard(device="/dev/comedi0", enable_line=EnableLine(channel=0)),
            DacCard(device="/dev/comedi1", enable_line=EnableLine(channel=1))]


class AtiRdt(_Strict):
    """ATI Net F/T over UDP RDT; see ``rt.ati.rdt_client.RdtForceTorqueSensor``."""

    backend: Literal["ati_rdt"] = "ati_rdt"
    host: str = "192.168.1.1"
    port: int = Field(default=RDT_PORT, ge=1, le=65535)
    #: counts/N and counts/(N m), from the sensor's configuration page.
    counts_per_force: float = Field(default=DEFAULT_COUNTS_PER_FORCE, gt=0.0)
    counts_per_torque: float = Field(default=DEFAULT_COUNTS_PER_TORQUE, gt=0.0)
    #: A reading older than this is stale (s).
    timeout_s: float = Field(default=0.05, gt=0.0, le=1.0)
    #: Several records per datagram (RDT command 0x0003).
    buffered: bool = False


class AtiCan(_Strict):
    """ATI Net F/T over CAN; see ``rt.ati.can_client.AtiCanForceTorqueSensor``."""

    backend: Literal["ati_can"] = "ati_can"
    #: python-can channel and interface (SocketCAN ``can0`` on the rig).
    channel: str = "can0"
    interface: str = "socketcan"
    #: The sensor's CAN base identifier (11 bit).
    base_id: int = Field(default=0, ge=0, le=0x7F0)
    counts_per_force: float = Field(default=16.0, gt=0.0)
    counts_per_torque: float = Field(default=500.0, gt=0.0)
    poll_rate_hz: float = Field(default=500.0, gt=0.0, le=2000.0)
    timeout_s: float = Field(default=0.05, gt=0.0, le=1.0)


class StopInputs(_Strict):
    """E-stop chain and hand-held stop; see ``rt.drivers.comedi_dio.ComediDigitalInputs``."""

    backend: Literal["comedi"] = "comedi"
    device: str = "/dev/comedi2"
    subdevice: Axis = 0
    estop_channel: Axis = 0
    hand_stop_channel: Axis = 1
    #: The level an unpressed, normally closed contact gives.
    healthy_level: Literal[0, 1] = 1


class AmplifierMonitor(_Strict):
    """Amplifier inputs read back; see ``rt.drivers.comedi_ai.ComediAmplifierMonitor``."""

    backend: Literal["comedi_ai"] = "comedi_ai"
    device: str = "/dev/comedi3"
    subdevice: Axis = 0
    #: Input of each axis.
    channels: tuple[int, int, int] = (0, 1, 2)
    #: A range covering the ±6 V commands (PCI-1711 range 0: ±10 V).
    range_index: Axis = 0
    #: Amplifier-input volts per volt read (1: wired directly).
    volts_per_volt: float = 1.0


class RigConfig(_Strict):
    """The rig's device files and wiring (module docstring)."""

    schema_version: Literal[1] = 1
    encoders: EncoderCard = EncoderCard()
    #: The DAC cards in failover order (the first drives, the next takes over on a fault).
    dac_cards: list[DacCard] = Field(default_factory=_default_cards, min_length=1, max_length=2)
    force_torque: Annotated[AtiRdt | AtiCan, Field(discriminator="backend")] = AtiRdt()
    stop_inputs: StopInputs = StopInputs()
    amplifier_monitor: AmplifierMonitor | None = None

    @model_validator(mode="after")
    def _distinct_wiring(self) -> "RigConfig":
        devices = [c.device for c in self.dac_cards]
        if len(set(devices)) != len(devices):
            raise ValueError(f"dac_cards must be distinct devices, got {devices}")
        lines = [(c.enable_line.device, c.enable_line.subdevice, c.enable_line.channel)
                 for c in self.dac_cards]
        if len(set(lines)) != len(lines):
            raise ValueError(f"dac_cards need distinct enable lines, got {lines}")
        s = self.stop_inputs
        inputs = {(s.device, s.subdevice, s.estop_channel), (s.device, s.subdevice,
                                                             s.hand_stop_channel)}
        if len(inputs) != 2 or inputs & set(lines):
            raise ValueError("stop inputs must be two lines distinct from the enable lines")
        return self
