"""The amplifiers' current loop in the robot description (issue 15): validated, round-tripped,
the one number the twin runs (its truth's) and identification aligns by (the lab's)."""
from __future__ import annotations

import copy
import math
from importlib import resources

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from rt.errors import ConfigurationError
from rt.identification.estimate import amplifier_to_positions, held_to_positions
from rt.model.description import RobotDescription, description_from_dict, load_description
from rt.twin import physics
from rt.twin.plant import TwinPlant
from rt.twin.realism import RigImperfections, perturbed_truth


@pytest.fixture()
def raw() -> dict:
    return yaml.safe_load(resources.files("rt.data").joinpath("robot_nominal.yaml").read_text())


def _amplifier(data: dict, bandwidth_hz, delay_s) -> dict:
    data = copy.deepcopy(data)
    data["drive"]["current_loop_bandwidth_hz"] = bandwidth_hz
    data["drive"]["amplifier_delay_s"] = delay_s
    return data


def test_the_nominal_amplifier_and_a_file_without_one(raw):
    d = description_from_dict(raw).drive
    assert (d.current_loop_bandwidth_hz, d.amplifier_delay_s) == (1000.0, 1.0e-4)
    assert d.current_loop_time_constant_s == pytest.approx(1.0 / (2.0 * math.pi * 1000.0))
    # A description written before the fields existed still loads, with the same defaults.
    old = copy.deepcopy(raw)
    del old["drive"]["current_loop_bandwidth_hz"], old["drive"]["amplifier_delay_s"]
    assert description_from_dict(old, "old.yaml") == description_from_dict(raw)


@pytest.mark.parametrize("bandwidth_hz, delay_s, field", [
    (0.0, 1e-4, "drive.current_loop_bandwidth_hz"),           # no loop at all is not a drive
    (-200.0, 1e-4, "drive.current_loop_bandwidth_hz"),
    (float("nan"), 1e-4, "drive.current_loop_bandwidth_hz"),
    (float("inf"), 1e-4, "drive.current_loop_bandwidth_hz"),
    (1.0e6, 1e-4, "drive.current_loop_bandwidth_hz"),         # above any PWM frequency
    ("fast", 1e-4, "drive.current_loop_bandwidth_hz"),
    (1000.0, -1e-5, "drive.amplifier_delay_s"),
    (1000.0, 2e-3, "drive.amplifier_delay_s"),                # a loop's delay, not a drive's
    (1000.0, float("nan"), "drive.amplifier_delay_s"),
])
def test_bad_amplifier_values_are_refused_by_name(raw, bandwidth_hz, delay_s, field):
    with pytest.raises(ConfigurationError) as info:
        description_from_dict(_amplifier(raw, bandwidth_hz, delay_s), "lab.yaml")
    assert field in str(info.value) and "lab.yaml" in str(info.value)


def test_round_trip_through_a_file(tmp_path, raw):
    want = description_from_dict(_amplifier(raw, 350.0, 2.5e-4))
    path = tmp_path / "robot.yaml"
    # As `talus identify` writes a description: the model dumped to YAML.
    path.write_text(yaml.safe_dump(want.model_dump(), sort_keys=False))
    back = load_description(path)
    assert back == want
    assert (back.drive.current_loop_bandwidth_hz, back.drive.amplifier_delay_s) == (350.0,
                                                                                   2.5e-4)
    # The twin's default truth is another rig with the same amplifiers (not perturbed).
    truth = perturbed_truth(want)
    assert truth.drive.current_loop_bandwidth_hz == 350.0
    assert truth.drive.amplifier_delay_s == 2.5e-4


def test_the_twin_runs_its_truths_amplifier_and_has_no_second_number(raw):
    with pytest.raises(ValidationError):                       # no bandwidth of its own
        RigImperfections(current_loop_bandwidth_hz=1000.0)
    truth = description_from_dict(_amplifier(raw, 200.0, 3.0e-4))
    plant = TwinPlant(truth)                                    # 5 kHz substeps
    h = 1.0 / plant.physics_rate_hz
    tau = 1.0 / (2.0 * math.pi * 200.0)
    r = plant.real
    assert r[physics.R_AMP_ALPHA] == pytest.approx(1.0 - math.exp(-h / tau))
    assert r[physics.R_AMP_MEAN] == pytest.approx(tau / h * (1.0 - math.exp(-h / tau)))
    # 0.3 ms = 1.5 substeps: one whole and half of the next (it was rounded to whole ones).
    assert (r[physics.R_AMP_DELAY_STEPS], r[physics.R_AMP_DELAY_FRAC]) == pytest.approx((1, 0.5))
    off = TwinPlant(truth, imperfections=RigImperfections(amplifier_dynamics=False))
    assert off.real[physics.R_AMP_ALPHA] == 1.0 and off.real[physics.R_AMP_MEAN] == 0.0
    assert off.real[physics.R_AMP_DELAY_STEPS] == 0.0
    assert RigImperfections.none().ideal and not RigImperfections.none().amplifier_dynamics


@pytest.mark.parametrize("compiled", [True, False])
def test_the_twins_current_follows_the_continuous_loop_at_its_substeps(raw, compiled):
    # A 200 Hz loop after 0.3 ms at the default 5 kHz substeps: the current after a command
    # step is the continuous 1 − exp(−(t − d)/τ) within 0.005 of the step. The previous
    # discretization (lag applied from each substep's start, delay rounded to whole substeps)
    # read 0.634 against 0.585 one period after the step.
    truth = RobotDescription.model_validate(_amplifier(raw, 200.0, 3.0e-4))
    imp = RigImperfections.none().model_copy(update={"amplifier_dynamics": True})
    plant = TwinPlant(truth, imperfections=imp, compiled=compiled)
    plant.set_state((0.2, 0.2, 0.2))
    gain = truth.drive.amplifier_gain_a_per_v
    tau = truth.drive.current_loop_time_constant_s
    for k in range(1, 5):
        plant.advance(1.0e-3, (1.0, 1.0, 1.0))
        want = 1.0 - math.exp(-(k * 1.0e-3 - 3.0e-4) / tau)
        np.testing.assert_allclose(plant.current / gain, want, atol=0.005)


def test_the_alignment_delays_the_held_commands_by_the_amplifiers_response():
    rate = 1000.0
    t = np.arange(20_000) / rate
    f = 5.0
    x = np.sin(2.0 * np.pi * f * t)[:, None] * np.ones((1, 3))
    # Without an amplifier it is the held half period exactly.
    np.testing.assert_array_equal(amplifier_to_positions(x, rate, 0.0, 0.0),
                                  held_to_positions(x))
    for bw, delay in ((1000.0, 1.0e-4), (100.0, 1.6e-3)):
        y = amplifier_to_positions(x, rate, bw, delay)[5000:, 1]
        basis = np.column_stack((np.sin(2 * np.pi * f * t[5000:]),
                                 np.cos(2 * np.pi * f * t[5000:])))
        c = np.linalg.lstsq(basis, y, rcond=None)[0]
        lag = -math.atan2(c[1], c[0]) / (2.0 * np.pi * f)
        tau = 1.0 / (2.0 * math.pi * bw)
        # The continuous hold + delay + first-order lag's phase at 5 Hz, to 0.5 µs (the
        # bilinear map's warping and the interpolation: 0.12 µs of 3.69 ms at 100 Hz).
        want = 0.5 / rate + delay + math.atan(2.0 * math.pi * f * tau) / (2.0 * math.pi * f)
        assert lag == pytest.approx(want, abs=5.0e-7)
        assert math.hypot(*c) == pytest.approx(1.0 / math.hypot(1.0, 2 * math.pi * f * tau),
                                               rel=2e-4)
    with pytest.raises(Exception, match="bandwidth"):
        amplifier_to_positions(x, rate, -1.0, 0.0)
