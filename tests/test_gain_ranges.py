"""Every controller declares the range of each gain; values outside are refused with the range,
directly, through the loop's ``set_params`` and through the RT service's ``set_gains``."""
from __future__ import annotations

import math

import pytest

from rt.control.base import CONTROLLERS, GainRange, check_range_table, create
from rt.control.force import Admittance, ExplicitForce
from rt.errors import ConfigurationError, InputError
from rt.service import RtConfig, RtService, build_rt_loop

LAW_NAMES = ["pid", "pd_g", "pd_g0", "paden_panja", "computed_torque_ptp", "computed_torque",
             "adaptive"]


def _make(name: str, robot, gains=None):
    if name == "explicit_force":
        return ExplicitForce(robot, gains)
    if name == "admittance":
        return Admittance(robot, gains)
    return create(name, robot, gains)


def _outside(rng: GainRange) -> list[float]:
    """A value just above the top and, unless the bottom is 0 on a field that forbids
    negatives anyway, just below the bottom."""
    span = rng.hi - rng.lo
    return [rng.hi + max(1e-6 * span, 1e-9), rng.lo - max(1e-6 * span, 1e-9)]


def test_every_registered_law_has_a_full_range_table(robot) -> None:
    create("pid", robot)                                 # imports every law
    assert sorted(CONTROLLERS) == sorted(LAW_NAMES)
    for cls in [*CONTROLLERS.values(), ExplicitForce, Admittance]:
        check_range_table(cls.name, cls.gain_ranges, cls.gains_type)
        for rng in cls.gain_ranges.values():
            assert rng.unit is not None and rng.lo <= rng.hi


@pytest.mark.parametrize("name", [*LAW_NAMES, "explicit_force", "admittance"])
def test_gains_outside_their_range_are_refused_with_the_range(name: str, robot) -> None:
    law = _make(name, robot)
    before = law.gains.model_dump()
    for gain, rng in law.gain_ranges.items():
        default = before[gain]
        is_tuple = isinstance(default, tuple)
        for bound in (rng.lo, rng.hi):                     # the bounds themselves are allowed
            if gain == "forgetting" and bound == rng.lo:
                continue                                   # the field itself excludes 0.9
            law.set_gains(**{gain: tuple([bound] * len(default)) if is_tuple else bound})
            law.set_gains(**{gain: default})
        for bad in _outside(rng):
            value = tuple([bad] * len(default)) if is_tuple else bad
            with pytest.raises(ConfigurationError) as info:
                law.set_gains(**{gain: value})
            message = str(info.value)
            if "outside its range" in message:
                assert gain in message and str(rng) in message
            assert law.gains.model_dump() == before        # nothing changed
        with pytest.raises(ConfigurationError, match=gain):
            _make(name, robot, {gain: tuple([rng.hi * 10 + 1] * len(default)) if is_tuple
                                else rng.hi * 10 + 1})


def test_message_names_value_range_and_units(robot) -> None:
    law = create("paden_panja", robot)
    with pytest.raises(ConfigurationError) as info:
        law.set_gains(kp_n_per_m=3.4e7)
    assert str(info.value) == ("paden_panja gain kp_n_per_m = 3.4e+07 N/m is outside its range "
                               "[5000, 5e+06] N/m")
    described = law.describe_gains()["kp_n_per_m"]
    assert described == {"default": 3.4e5, "min": 5e3, "max": 5e6, "unit": "N/m"}


def test_a_range_must_be_an_interval() -> None:
    with pytest.raises(ConfigurationError):
        GainRange(2.0, 1.0, "N/m")
    with pytest.raises(ConfigurationError):
        GainRange(0.0, math.inf, "N/m")


def test_loop_set_params_and_service_set_gains_refuse_out_of_range() -> None:
    pl, tap = build_rt_loop(RtConfig(controller="pid", loop_mode="fast"))
    service = RtService(pl, RtConfig(controller="pid"), tap)
    service.control_acquire(client="me", name="test")
    pl.loop.start()
    try:
        with pytest.raises(InputError, match=r"kp_n_per_m = 1e\+07 N/m is outside its range "
                                             r"\[5000, 5e\+06\] N/m"):
            pl.loop.set_params("controller", kp_n_per_m=1.0e7).result(timeout=30.0)
        with pytest.raises(InputError, match=r"ki_n_per_m_s = 1e\+08 N/\(m s\) is outside"):
            service.set_gains("me", "pid", {"kp_n_per_m": 2.0e5, "ki_n_per_m_s": 1.0e8})
        # All or nothing: the valid kp in the refused request did not apply either.
        assert pl.graph.component("controller").controller.gains.kp_n_per_m == 3.4e5
        assert service.set_gains("me", "pid", {"kp_n_per_m": 2.0e5})["gains"] == \
            {"kp_n_per_m": 2.0e5}
    finally:
        pl.loop.stop()
    assert pl.graph.component("controller").controller.gains.kp_n_per_m == 2.0e5


def test_service_refuses_out_of_range_gains_even_with_the_loop_stopped() -> None:
    pl, tap = build_rt_loop(RtConfig(controller="computed_torque", loop_mode="fast"))
    service = RtService(pl, RtConfig(controller="computed_torque"), tap)
    service.control_acquire(client="me", name="test")
    with pytest.raises(InputError, match=r"kd_per_s = 900 1/s is outside its range \[5, 600\]"):
        service.set_gains("me", "computed_torque", {"kd_per_s": 900.0})
    assert pl.graph.component("controller").controller.gains.kd_per_s == 80.0
