"""Component lifecycle, parameters vs state, port declarations."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from rt.engine import FLOAT, Array, Component, Lifecycle, LifecycleError
from rt.engine.ports import ArrayType, ScalarType
from rt.errors import ConfigurationError, InputError


class Pid(Component):
    """Ports: in ``e``: float64[3] (m); out ``u``: float64[3] (V) = kp e + ki ∫e dt."""

    @dataclass(frozen=True)
    class Params:
        kp: float = 1.0
        ki: float = 0.0
        limit_v: float = 6.0

        def __post_init__(self) -> None:
            if not (self.kp >= 0.0 and self.ki >= 0.0):
                raise ValueError(f"gains must be ≥ 0 (kp={self.kp}, ki={self.ki})")

    def __init__(self, name: str, params: Pid.Params | None = None, fail_in: str = "") -> None:
        super().__init__(name, params)
        self.e = self.declare_input("e", Array(3), "tracking error (m)")
        self.u = self.declare_output("u", Array(3), "command (V)")
        self.fail_in = fail_in
        self.calls: list[str] = []
        self.derived = 0.0

    def _hook(self, name: str) -> None:
        self.calls.append(name)
        if self.fail_in == name:
            raise RuntimeError(f"{name} broke")

    def on_configure(self) -> None:
        self._hook("configure")
        self.derived = 2.0 * self.params.kp

    def on_start(self) -> None:
        self._hook("start")

    def on_stop(self) -> None:
        self._hook("stop")

    def on_error(self, reason: str) -> None:
        self.calls.append("error")
        self.u.data.fill(0.0)  # the safe output

    def on_reset(self) -> None:
        self._hook("reset")

    def make_state(self) -> np.ndarray:
        return np.zeros(3)  # the integral of e (m s)

    def check_params(self, new: Pid.Params) -> None:
        if new.limit_v > 10.0:
            raise InputError(f"limit_v {new.limit_v} V exceeds the DAC's ±10 V")

    def on_params_changed(self, old: Pid.Params) -> None:
        if self.fail_in == "params_changed" and self.params.kp == 13.0:
            raise RuntimeError("unlucky gain")
        self.derived = 2.0 * self.params.kp

    def update(self, t: float, dt: float) -> int:
        self.state += self.e.data * dt
        np.multiply(self.e.data, self.params.kp, out=self.u.data)
        return 0


def test_lifecycle_happy_path_and_hook_order():
    c = Pid("pid")
    assert c.lifecycle is Lifecycle.UNCONFIGURED and c.state is None
    c.configure()
    assert c.lifecycle is Lifecycle.INACTIVE and c.derived == 2.0
    np.testing.assert_array_equal(c.state, np.zeros(3))
    c.start()
    assert c.lifecycle is Lifecycle.ACTIVE and c._active
    c.stop()
    assert c.lifecycle is Lifecycle.INACTIVE and not c._active
    c.state += 1.0
    c.reset()
    np.testing.assert_array_equal(c.state, np.zeros(3))  # state rebuilt from params
    assert c.calls == ["configure", "start", "stop", "reset"]


@pytest.mark.parametrize("prepare, action, allowed", [
    ([], "start", "inactive"),
    ([], "stop", "active"),
    ([], "reset", "error, inactive"),
    (["configure"], "configure", "unconfigured"),
    (["configure"], "stop", "active"),
    (["configure", "start"], "start", "inactive"),
    (["configure", "start"], "configure", "unconfigured"),
    (["configure", "start"], "reset", "error, inactive"),
])
def test_illegal_transitions_are_refused_and_change_nothing(prepare, action, allowed):
    c = Pid("pid")
    for step in prepare:
        getattr(c, step)()
    before, calls = c.lifecycle, list(c.calls)
    with pytest.raises(LifecycleError, match=rf"cannot {action} while {before.value} "
                                             rf"\(allowed from: {allowed}\); nothing was changed"):
        getattr(c, action)()
    assert c.lifecycle is before and c.calls == calls


@pytest.mark.parametrize("hook, exc_type", [("configure", ConfigurationError),
                                            ("start", LifecycleError)])
def test_a_failing_hook_moves_to_error_and_reset_recovers(hook, exc_type):
    c = Pid("pid", fail_in=hook)
    if hook == "start":
        c.configure()
    with pytest.raises(exc_type, match=rf"{hook} failed: RuntimeError: {hook} broke; it is now in error"):
        getattr(c, hook)()
    assert c.lifecycle is Lifecycle.ERROR and c.calls[-1] == "error"
    assert "broke" in c.fault_reason
    c.fail_in = ""
    c.reset()
    # never configured -> back to unconfigured; configured before -> inactive
    assert c.lifecycle is (Lifecycle.UNCONFIGURED if hook == "configure" else Lifecycle.INACTIVE)
    assert c.fault_reason is None


def test_error_from_any_state_latches_until_reset():
    c = Pid("pid")
    c.configure()
    c.start()
    c.u.data[:] = 3.0
    c.error("tracking error too large")
    assert c.lifecycle is Lifecycle.ERROR and not c._active
    assert c.fault_reason == "tracking error too large"
    np.testing.assert_array_equal(c.u.data, 0.0)  # on_error zeroed the output
    with pytest.raises(LifecycleError):
        c.start()
    c.reset()
    c.start()
    assert c.lifecycle is Lifecycle.ACTIVE


def test_set_params_is_all_or_nothing():
    c = Pid("pid", Pid.Params(kp=2.0))
    c.configure()
    c.set_params(kp=3.0, ki=0.5)
    assert (c.params.kp, c.params.ki, c.derived) == (3.0, 0.5, 6.0)
    for kwargs, message in [
        ({"kp": -1.0}, r"gains must be ≥ 0"),                         # Params.__post_init__
        ({"limit_v": 12.0}, r"limit_v 12\.0 V exceeds the DAC"),      # check_params
        ({"kd": 1.0}, r"has no parameter 'kd'; known: ki, kp, limit_v"),
        ({"kp": 4.0, "ki": -2.0}, r"gains must be ≥ 0"),              # one bad value spoils all
    ]:
        before = c.params
        with pytest.raises(InputError, match=message):
            c.set_params(**kwargs)
        assert c.params is before and c.derived == 6.0


def test_set_params_rolls_back_when_applying_fails():
    c = Pid("pid", fail_in="params_changed")
    c.configure()
    with pytest.raises(InputError, match="applying them failed: RuntimeError: unlucky gain"):
        c.set_params(kp=13.0)
    assert c.params.kp == 1.0 and c.derived == 2.0


def test_components_without_params_refuse_set_params():
    class Bare(Component):
        """Ports: none."""

        def update(self, t: float, dt: float) -> int:
            return 0

    with pytest.raises(InputError, match="has no settable parameters"):
        Bare("bare").set_params(x=1)


def test_port_declarations_are_checked():
    c = Pid("pid")
    with pytest.raises(ConfigurationError, match="already has a port named 'u'"):
        c.declare_input("u", FLOAT)
    with pytest.raises(ConfigurationError, match="port name 'a.b' is not valid"):
        c.declare_output("a.b", FLOAT)
    with pytest.raises(ConfigurationError, match="component name '1x' is not valid"):
        Pid("1x")
    with pytest.raises(ConfigurationError, match="type must be a PortType"):
        c.declare_output("v", float)
    with pytest.raises(ConfigurationError, match="shape must be positive integers"):
        Array(3, 0)
    with pytest.raises(ConfigurationError, match="scalar ports carry float, int or bool"):
        ScalarType(str)
    with pytest.raises(ConfigurationError, match=r"does not fit a float64\[3\] port"):
        c.declare_output("w", Array(3), initial=[1.0, 2.0])
    assert c.describe_ports().splitlines() == ["in  e: float64[3]  tracking error (m)",
                                               "out u: float64[3]  command (V)"]
    assert Array(3) == ArrayType((3,)) and str(Array(2, 3)) == "float64[2,3]"
