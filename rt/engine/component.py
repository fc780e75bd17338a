"""The component base class: ports, parameters vs state, lifecycle, ``update`` (CONVENTIONS 3-6).

Lifecycle (ros2_control's, reduced to what the loop needs)::

    unconfigured --configure()--> inactive --start()--> active
         ^                          ^  |<----stop()------'
         |                          |  |
         '------ reset() -----------'--+-- error(reason) from any state --> error
                   (from error or inactive; back to inactive if the component was ever
                    configured, else to unconfigured)

Subclasses override the ``on_*`` hooks, never the transition methods, so the bookkeeping
cannot be forgotten. A hook that raises moves the component to ``error`` and the transition
raises :class:`LifecycleError` (``ConfigurationError`` for ``configure``).

Parameters and state are kept apart so a run can be reset and replayed deterministically:

* ``params`` — immutable (a frozen dataclass is expected; declare it as the nested class
  ``Params`` to get a default instance). Validate in ``Params.__post_init__`` and/or
  :meth:`Component.check_params`. Changed only through :meth:`Component.set_params`, which
  builds a new object and swaps it in whole, so a rejected value changes nothing.
* ``state`` — everything ``update`` mutates, built by :meth:`Component.make_state` from
  ``params`` on ``configure()`` and again on ``reset()``.

``update(t, dt)`` runs every cycle while the component is active: ``t`` is the loop time (s),
``dt`` the measured period (s). It returns 0 when fine and a non-zero, component-defined code
on failure; the graph then moves the component to ``error``. It should not raise, allocate, do
I/O or log; if it does raise, the graph catches it (status :data:`STATUS_EXCEPTION`).
"""
from __future__ import annotations

import dataclasses
import enum
from typing import Any, ClassVar

from rt.engine.ports import InputPort, OutputPort, PortType, check_name
from rt.epoch import bump
from rt.errors import ConfigurationError, InputError, TalusError

STATUS_OK = 0
"""``update`` succeeded."""
STATUS_EXCEPTION = -1
"""Recorded by the graph when ``update`` raised instead of returning a status."""


class Lifecycle(enum.Enum):
    """Lifecycle state of a component."""

    UNCONFIGURED = "unconfigured"
    INACTIVE = "inactive"
    ACTIVE = "active"
    ERROR = "error"


class LifecycleError(TalusError):
    """A lifecycle transition was refused (illegal from the current state: nothing changed) or
    its hook failed (the message says so; the component is then in ``error``)."""


class Component:
    """Base of every block of the real-time graph.

    Ports: none (subclasses document theirs here, first thing in the class docstring, as
    ``name: type, units — meaning``).

    Subclass contract:

    * ``__init__``: call ``super().__init__(name, params)``, then declare ports with
      :meth:`declare_input` / :meth:`declare_output` (keep the returned port objects as
      attributes). Nothing else heavy: devices are opened in ``on_configure``.
    * ``make_state()``: return the mutable state (preallocated arrays etc.).
    * ``update(t, dt) -> int``: the cycle's work; read ``inp.data``, fill ``out.data`` in place.
    * optional hooks: ``on_configure``, ``on_start``, ``on_stop``, ``on_error(reason)``,
      ``on_reset``, ``check_params(new)``, ``on_params_changed(old)``, ``handover(old)``.
    """

    Params: ClassVar[type | None] = None
    """Optional frozen dataclass of parameters; instantiated with defaults if none given."""

    def __init__(self, name: str, params: Any = None) -> None:
        self.name = check_name("component", name)
        if params is None and self.Params is not None:
            params = self.Params()
        self.params: Any = params
        self.state: Any = None
        self.inputs: dict[str, InputPort] = {}
        self.outputs: dict[str, OutputPort] = {}
        self.fault_reason: str | None = None
        self._lifecycle = Lifecycle.UNCONFIGURED
        # Read by the graph every cycle: a plain bool is the cheapest test (≈ 15 ns).
        self._active = False
        self._was_configured = False
        self._sealed = False  # set when added to a graph: the port set is then frozen
        self._graph: Any = None  # the graph whose slot this component occupies (or reserves)

    # ---------------------------------------------------------------- ports
    def _check_new_port(self, name: str) -> None:
        if self._sealed:
            raise ConfigurationError(
                f"component {self.name!r}: ports must be declared in __init__, before the "
                f"component is added to a graph (port {name!r})")
        check_name("port", name)
        if name in self.inputs or name in self.outputs:
            raise ConfigurationError(f"component {self.name!r} already has a port named {name!r}")

    def declare_input(self, name: str, type: PortType, doc: str = "") -> InputPort:
        """Declare an input port; its ``data`` is bound by the graph builder."""
        self._check_new_port(name)
        port = InputPort(self, name, type, doc)
        self.inputs[name] = port
        return port

    def declare_output(self, name: str, type: PortType, doc: str = "",
                       initial: Any = None, buffer: Any = None) -> OutputPort:
        """Declare an output port; its buffer is allocated now, holding ``initial`` (default
        zeros / 0 / False / ``cls()``) until the component first writes it. An array port may
        instead live in ``buffer``, a writeable float64 view of the component's own arena of
        the port's shape (so a compiled cycle takes every output as one argument)."""
        self._check_new_port(name)
        port = OutputPort(self, name, type, doc, initial, buffer)
        self.outputs[name] = port
        return port

    def describe_ports(self) -> str:
        """One line per port: direction, name, type, doc (for the CLI and docs)."""
        lines = [f"in  {p.name}: {p.type}  {p.doc}".rstrip() for p in self.inputs.values()]
        lines += [f"out {p.name}: {p.type}  {p.doc}".rstrip() for p in self.outputs.values()]
        return "\n".join(lines)

    # ---------------------------------------------------------------- lifecycle
    @property
    def lifecycle(self) -> Lifecycle:
        """Current lifecycle state."""
        return self._lifecycle

    def _refuse(self, action: str, allowed: str) -> LifecycleError:
        return LifecycleError(
            f"component {self.name!r}: cannot {action} while {self._lifecycle.value} "
            f"(allowed from: {allowed}); nothing was changed")

    def _hook_failed(self, hook: str, exc: BaseException) -> str:
        reason = f"{hook} failed: {type(exc).__name__}: {exc}"
        self.error(reason)
        return f"component {self.name!r}: {reason}; it is now in error (reset() to recover)"

    def configure(self) -> None:
        """unconfigured → inactive: open devices, derive constants, build the state."""
        if self._lifecycle is not Lifecycle.UNCONFIGURED:
            raise self._refuse("configure", "unconfigured")
        try:
            self.on_configure()
            self.state = self.make_state()
            bump()
        except Exception as exc:
            raise ConfigurationError(self._hook_failed("configure", exc)) from exc
        self._was_configured = True
        self._lifecycle = Lifecycle.INACTIVE

    def start(self) -> None:
        """inactive → active: the component's ``update`` runs from the next cycle."""
        if self._lifecycle is not Lifecycle.INACTIVE:
            raise self._refuse("start", "inactive")
        try:
            self.on_start()
        except Exception as exc:
            raise LifecycleError(self._hook_failed("start", exc)) from exc
        self._lifecycle = Lifecycle.ACTIVE
        self._active = True
        bump()                        # the fused cycle's plan checked the blocks' lifecycle

    def stop(self) -> None:
        """active → inactive."""
        if self._lifecycle is not Lifecycle.ACTIVE:
            raise self._refuse("stop", "active")
        self._active = False
        bump()
        try:
            self.on_stop()
        except Exception as exc:
            raise LifecycleError(self._hook_failed("stop", exc)) from exc
        self._lifecycle = Lifecycle.INACTIVE

    def error(self, reason: str) -> None:
        """Any state → error, latched until :meth:`reset`. Never raises (it is the fault path):
        a failing ``on_error`` hook is appended to the recorded reason."""
        self._active = False
        self._lifecycle = Lifecycle.ERROR
        bump()
        try:
            self.on_error(reason)
        except Exception as exc:  # noqa: BLE001 - the fault path must not fault
            reason = f"{reason}; on_error also failed: {type(exc).__name__}: {exc}"
        self.fault_reason = reason

    def reset(self) -> None:
        """error or inactive → inactive (or unconfigured if never configured): rebuild the state
        from ``params`` so that a run can be replayed, and clear the fault."""
        if self._lifecycle not in (Lifecycle.ERROR, Lifecycle.INACTIVE):
            raise self._refuse("reset", "error, inactive")
        if not self._was_configured:
            self.fault_reason = None
            self._lifecycle = Lifecycle.UNCONFIGURED
            return
        try:
            self.state = self.make_state()
            bump()
            self.on_reset()
        except Exception as exc:
            raise LifecycleError(self._hook_failed("reset", exc)) from exc
        self.fault_reason = None
        self._lifecycle = Lifecycle.INACTIVE

    # ---------------------------------------------------------------- parameters
    def set_params(self, **values: Any) -> None:
        """Replace some parameters, all or nothing.

        Builds a new params object (``dataclasses.replace``, which re-runs ``__post_init__``
        validation), asks :meth:`check_params`, swaps it in and calls :meth:`on_params_changed`;
        if any step fails the old params stay and :class:`InputError` says why. Not for the
        cycle itself: the loop calls it at a cycle boundary.
        """
        if self.params is None or not dataclasses.is_dataclass(self.params):
            raise InputError(f"component {self.name!r} has no settable parameters")
        fields = {f.name for f in dataclasses.fields(self.params) if f.init}
        unknown = sorted(set(values) - fields)
        if unknown:
            raise InputError(
                f"component {self.name!r} has no parameter {', '.join(map(repr, unknown))}; "
                f"known: {', '.join(sorted(fields))}")
        old: Any = self.params
        try:
            new = dataclasses.replace(old, **values)
            self.check_params(new)
        except TalusError as exc:
            raise InputError(f"component {self.name!r}: rejected {values!r}: {exc}") from exc
        except (TypeError, ValueError) as exc:
            raise InputError(f"component {self.name!r}: rejected {values!r}: {exc}") from exc
        self.params = new
        try:
            self.on_params_changed(old)
        except Exception as exc:
            self.params = old
            try:  # let derived quantities follow the restored params
                self.on_params_changed(new)
            except Exception as again:  # noqa: BLE001 - the first failure is the one raised
                exc.add_note(f"re-applying the previous params failed too: {again!r}")
            raise InputError(
                f"component {self.name!r}: rejected {values!r}: applying them failed: "
                f"{type(exc).__name__}: {exc}") from exc

    # ---------------------------------------------------------------- hooks
    def make_state(self) -> Any:
        """Return a fresh mutable state built from ``params`` (default: ``None``)."""
        return None

    def on_configure(self) -> None:
        """Open devices, derive constants from ``params``. May allocate."""

    def on_start(self) -> None:
        """Last preparation before the first ``update`` (also called on a swap, inside the
        loop at a cycle boundary: keep it short and allocation-free)."""

    def on_stop(self) -> None:
        """The component will not be updated any more until restarted."""

    def on_error(self, reason: str) -> None:
        """React to entering ``error`` (e.g. zero an actuator output). Keep it short."""

    def on_reset(self) -> None:
        """After ``state`` has been rebuilt by ``reset()``."""

    def check_params(self, new: Any) -> None:
        """Extra validation of a candidate params object; raise InputError/ValueError to refuse."""

    def on_params_changed(self, old: Any) -> None:
        """``self.params`` has just replaced ``old``: update derived quantities."""

    def handover(self, old: Component) -> None:
        """Initialise this component's state from ``old``, which it replaces in a graph slot.

        Called by a swap at a cycle boundary, after ``self.start()`` and before this
        component's first ``update``. ``old`` is untouched (still active, its last ``update``
        ran in the previous cycle); this component's outputs already share ``old``'s buffers,
        so they hold ``old``'s last outputs (what a bumpless transfer must continue from).
        Raising aborts the swap (``old`` stays in the slot).
        """

    def update(self, t: float, dt: float) -> int:
        """One cycle: ``t`` loop time (s), ``dt`` measured period (s). Return 0 or an error code."""
        raise NotImplementedError(f"{type(self).__name__}.update")

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r} {self._lifecycle.value}>"
