"""The amplifiers' input offset (rt.twin.realism): its signature is a motor current with a zero
command while the drives are enabled — and none while they are disabled; seeded per axis."""
from __future__ import annotations

import numpy as np

from rt.model.description import load_description
from rt.twin.plant import TwinPlant
from rt.twin.realism import RigImperfections

NONE = RigImperfections.none()


def test_offset_drives_current_with_a_zero_command_only_while_enabled():
    imp = NONE.model_copy(update={"amplifier_offset_v": 0.015,
                                  "amplifier_dynamics": True})   # the file's 1 kHz
    offsets = imp.amplifier_offsets_v()
    assert np.all(np.abs(offsets) <= 0.015) and len(set(offsets.tolist())) == 3
    assert np.array_equal(offsets, imp.amplifier_offsets_v())              # seeded
    other = imp.model_copy(update={"amplifier_offset_seed": 1}).amplifier_offsets_v()
    assert not np.array_equal(offsets, other)
    desc = load_description()
    plant = TwinPlant(desc, imperfections=imp)
    plant.set_state((0.2, 0.2, 0.2))
    plant.advance(0.01, (0.0, 0.0, 0.0))                   # drives disabled: nothing
    assert np.all(plant.current == 0.0)
    plant.set_drives_enabled(True)
    plant.advance(0.01, (0.0, 0.0, 0.0))                   # 10 current-loop time constants
    gain = desc.drive.amplifier_gain_a_per_v
    np.testing.assert_allclose(plant.current, offsets * gain, rtol=1e-3)
    # ≤ ±5 N at the slider: the documented order of magnitude.
    assert np.all(np.abs(plant.current * desc.drive.force_per_amp_n) <= 5.1)


def test_the_ideal_twin_has_no_offset():
    assert RigImperfections.none().ideal
    assert np.all(RigImperfections.none().amplifier_offsets_v() == 0.0)
    # On by default: ±15 mV per axis (the PCI-1720's zero error plus an amplifier's residual
    # offset after trim), seeded, so every default twin carries the same offsets.
    default = RigImperfections().amplifier_offsets_v()
    assert RigImperfections().amplifier_offset_v == 0.015
    assert np.all(np.abs(default) <= 0.015) and np.all(default != 0.0)
    assert np.array_equal(default, RigImperfections(amplifier_offset_v=0.015)
                          .amplifier_offsets_v())
