"""The fused pre-flight engine's sensor and drive stages (``rt.preflight.stages``) give bit for
bit what the register-level path gives: the PCL-833 driver reading the twin's emulated card,
and the PCI-1720 driver's codes turned back into amplifier input by the twin."""
from __future__ import annotations

import math

import numpy as np
import pytest

from rt.drivers.pcl833 import COUNTER_MASK
from rt.preflight.stages import EncoderStage, dac_parameters, dac_stage, encoder_read
from rt.twin.backends import TwinActuators, TwinEncoders
from rt.twin.serve import holding_volts
from rt.twin.twin import SimClock, Twin

DT = 0.001


def _moving_twin(seconds: float, near_wrap: bool):
    """A twin driven through the real drivers by a PD law on the decoded positions (a 2 cm,
    0.5 Hz sine per slider), yielding (driver reading, encoder reading) every period."""
    clock = SimClock()
    twin = Twin(clock=clock, seed=3)
    enc = TwinEncoders(twin)
    if near_wrap:
        # Counters a few hundred counts below the 24-bit wrap: the motion crosses it.
        for axis in range(3):
            twin.encoder_port.set_count(axis, COUNTER_MASK - 300 + 7 * axis)
    card = TwinActuators(twin, 0)
    card.enable()
    hold = holding_volts(twin)
    q = np.zeros(3)
    enc.read_positions_m(q)
    stage = EncoderStage(enc._driver, twin.encoder_port)
    q0 = q.copy()
    volts = [0.0, 0.0, 0.0]
    for k in range(int(seconds / DT)):
        clock.t = (k + 1) * DT
        enc.read_positions_m(q)
        yield stage, q, twin.plant.encoder_q
        for i in range(3):
            ref = q0[i] + 0.02 * math.sin(2 * math.pi * 0.5 * clock.t + 2.0944 * i)
            volts[i] = hold[i] + 300.0 * (ref - q[i])
        card.write_volts(volts)


@pytest.mark.parametrize("near_wrap", [False, True])
def test_encoder_stage_reads_what_the_driver_reads(near_wrap):
    out = np.zeros(3)
    moved = np.zeros(3)
    last = None
    for stage, q_driver, enc_q in _moving_twin(1.5, near_wrap):
        encoder_read(enc_q, stage.enc, out)
        # Bit for bit, every period (not a tolerance: the same operations on the same floats).
        assert out.tolist() == q_driver.tolist()
        if last is not None:
            moved += np.abs(q_driver - last)
        last = q_driver.copy()
    # The sliders really moved (a 2 cm sine over 1.5 s: ≥ 3 cm of travel per slider), so
    # thousands of count changes were compared.
    assert (moved > 0.03).all(), moved


def test_dac_stage_gives_the_drivers_codes_and_the_twins_amplifier_input():
    twin = Twin(clock=SimClock())
    card = TwinActuators(twin, 0)
    card.enable()
    dac = dac_parameters(card._driver, twin.command_limit_v)
    rng = np.random.default_rng(5)
    codes = np.zeros(3)
    amp = np.zeros(3)
    # Inside the range, at the driver's limit and beyond it, and exact half-code boundaries.
    lsb = 20.0 / 4095.0
    samples = [rng.uniform(-9.0, 9.0, 3) for _ in range(2000)]
    samples += [np.array([6.0, -6.0, 0.0]), np.array([7.5, -12.0, 1e-9]),
                np.array([(k + 0.5) * lsb - 10.0 for k in (2047, 2048, 1500)])]
    for volts in samples:
        clamped = dac_stage(volts, dac, codes, amp)
        card.write_volts(volts)
        twin._update_amplifier_input()
        assert codes.tolist() == [float(c) for c in card._driver.last_codes]
        assert amp.tolist() == twin.amp_volts.tolist()
        assert clamped == sum(card._driver.clamped)
