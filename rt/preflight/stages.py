"""The sensor and drive stages of a fused pre-flight engine, compiled (issue 16).

Pre-flight runs every protocol on the twin through the component graph
(``protocols.session.preflight``); the graph pays Python per block per cycle, which is most of a
pre-flight's cost. The fused engine planned in docs/worklog/2026-11-25b/preflight.md runs the
cycle as one numba loop instead. The twin's physics (``rt.twin.kernels.advance``), the
estimator (``rt.estimation.compiled``), the model block (``rt.model.kernels.model_state``), the
control laws (``rt.control.kernels``), the supervisor's checks
(``rt.safety.supervisor_kernel``) and the ATI's arithmetic (``rt.ati.twin_sensor``) already
have kernels. Two stages between them did not: they run as Python objects emulating the cards
at register level (``FakePcl833Port`` read by ``Pcl833Encoders``; ``Pci1720Outputs`` writing to
``FakeComedi``, read back by the twin). This module is those two stages as arithmetic on
arrays, bit for bit what the register-level path computes when no fault is injected
(``tests/test_preflight_stages.py`` compares them on a moving twin):

* :func:`encoder_read`: the motor encoder's reading (``plant.encoder_q``) → the counts the card
  has accumulated → the driver's decoded slider positions. Between two reads the card only
  adds the change of the encoder index, so the decoded position is the displacement at a
  reference instant plus the index change since then: :class:`EncoderStage` captures that
  reference from the live driver and port (the hand-over from the component path).
* :func:`dac_stage`: the supervisor's volts → the PCI-1720 driver's clamp and 12-bit code →
  the amplifier input the twin derives from the code (clamped at the amplifier's limit).

Faults the register-level path models (frozen or jumping counters, dead or stuck DAC
channels, latency) are not modelled here: an engine using these stages must refuse to judge a
run with a fault plan, and leave it to the component path.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from rt.drivers.fake_pcl833 import FakePcl833Port
from rt.drivers.kernels import dac_code, dac_code_volts
from rt.drivers.pci1720 import Pci1720Outputs
from rt.drivers.pcl833 import Pcl833Encoders
from rt.errors import ConfigurationError

# ---- encoder parameter/state array ``enc`` (float64[ENC_SIZE]); integers are exact in float64
ENC_SIGN = 0            # 3: the port's count direction × the driver's sign (±1)
ENC_PORT_SIGN = 3       # 3: the port's count direction (±1)
ENC_MPC = 6             # 3: m per count (the port's = the driver's, checked)
ENC_ORIGIN = 9          # 3: the driver's origin (m)
ENC_INDEX_REF = 12      # 3: the port's encoder index at the reference instant (counts)
ENC_DISP_REF = 15       # 3: the driver's unwrapped displacement then (counts)
ENC_SIZE = 18

# ---- DAC parameter array ``dac`` (float64[DAC_SIZE])
DAC_LIMIT_V = 0         # the driver's clamp (V)
DAC_V_MIN = 1           # the channel range (V); the same for the three channels (checked)
DAC_V_MAX = 2
DAC_MAXDATA = 3         # 4095 on the PCI-1720
DAC_AMP_LIMIT_V = 4     # the amplifier's input limit (V)
DAC_SIZE = 5


@njit(cache=True)
def encoder_read(enc_q, enc, out):
    """Decoded slider positions (m) into ``out`` for the motor encoders at ``enc_q`` (m).

    The port's encoder index is ``floor(sign·x/mpc + 0.5)`` (``FakePcl833Port.set_position_m``);
    the counter moves by the index change, the driver unwraps it into a displacement and
    decodes ``origin + sign·displacement·mpc`` (``Pcl833Encoders.read_positions_m``). The
    same operations in the same order, so the result is bit-identical.
    """
    for i in range(3):
        mpc = enc[ENC_MPC + i]
        index = math.floor(enc[ENC_PORT_SIGN + i] * enc_q[i] / mpc + 0.5)
        displacement = enc[ENC_DISP_REF + i] + (index - enc[ENC_INDEX_REF + i])
        out[i] = enc[ENC_ORIGIN + i] + enc[ENC_SIGN + i] * displacement * mpc


@njit(cache=True)
def dac_stage(volts, dac, codes, amp):
    """The drive path for ``volts`` (V): the driver's clamp and code into ``codes``
    (``rt.drivers.kernels.dac_code``, what ``Pci1720Outputs.write_volts`` calls), the
    amplifier input the twin makes of each code into ``amp`` (``code_to_volts``, clamped at
    the amplifier's limit). Returns the number of channels the driver clamped."""
    limit = dac[DAC_LIMIT_V]
    v_min = dac[DAC_V_MIN]
    v_max = dac[DAC_V_MAX]
    maxdata = dac[DAC_MAXDATA]
    amp_limit = dac[DAC_AMP_LIMIT_V]
    clamped = 0
    for i in range(3):
        v = volts[i]
        if not -limit <= v <= limit:
            clamped += 1
        # The driver's own quantizer and its inverse (one definition for both paths).
        code = dac_code(v, limit, v_min, v_max, maxdata)
        codes[i] = code
        a = dac_code_volts(code, v_min, v_max, maxdata)
        amp[i] = max(-amp_limit, min(amp_limit, a))
    return clamped


class EncoderStage:
    """The ``enc`` array of :func:`encoder_read` for a driver reading a fake port, referenced
    to the present instant: call it right after a read (the driver's displacement is then the
    one of the port's current index)."""

    def __init__(self, driver: Pcl833Encoders, port: FakePcl833Port) -> None:
        if any(abs(a - b) != 0.0 for a, b in zip(driver.m_per_count, port.m_per_count)):
            raise ConfigurationError(
                f"the encoder driver's m_per_count {driver.m_per_count} differs from the "
                f"card's {port.m_per_count}: the stage models one scale per axis")
        self.enc = np.zeros(ENC_SIZE)
        for i in range(3):
            channel = driver.channels[i] - 1
            if channel != i:
                raise ConfigurationError(f"axis {i} is read from card channel {channel + 1}: "
                                         "the stage models the thesis wiring (axis i on "
                                         "channel i + 1)")
            self.enc[ENC_SIGN + i] = driver.sign[i]
            self.enc[ENC_PORT_SIGN + i] = port.sign[i]
            self.enc[ENC_MPC + i] = port.m_per_count[i]
            self.enc[ENC_ORIGIN + i] = driver.origin_m[i]
            self.enc[ENC_INDEX_REF + i] = port._encoder_index[i]
            self.enc[ENC_DISP_REF + i] = driver._unwrap[i].displacement


def dac_parameters(driver: Pci1720Outputs, amp_limit_v: float) -> np.ndarray:
    """The ``dac`` array of :func:`dac_stage` for a driver (one range on every channel)."""
    ranges = {(ch.v_min, ch.v_max, ch.maxdata) for ch in driver._channels}
    if len(ranges) != 1:
        raise ConfigurationError(f"the DAC channels have different ranges {sorted(ranges)}: "
                                 "the stage models one range")
    v_min, v_max, maxdata = ranges.pop()
    dac = np.zeros(DAC_SIZE)
    dac[DAC_LIMIT_V] = driver.limit_v
    dac[DAC_V_MIN] = v_min
    dac[DAC_V_MAX] = v_max
    dac[DAC_MAXDATA] = maxdata
    dac[DAC_AMP_LIMIT_V] = amp_limit_v
    return dac
