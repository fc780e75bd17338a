"""Typed ports: how components exchange data without moving it (DESIGN 5, CONVENTIONS 5-6).

A component declares its ports in ``__init__`` (``declare_input`` / ``declare_output``). Every
output port owns one buffer, allocated once when it is declared:

* :class:`ArrayType` — a fixed-shape float64 ``numpy`` array. Writers fill it in place
  (``out.data[:] = ...``, ``np.multiply(a, b, out=out.data)``); they never rebind ``data``.
* :class:`ScalarType` — a :class:`Box` whose ``value`` attribute holds a ``float``, ``int``
  or ``bool`` (Python numbers are immutable, so the box is what is shared).
* :class:`StructType` — an instance of a small mutable class with slots (e.g.
  ``rt.devices.interfaces.Wrench``) built by its no-argument constructor; writers mutate its
  fields in place. Delayed connections need a ``copy_from(other)`` method on the class.

The graph builder binds each connected input port to its producer's buffer: an array input
sees a *read-only view* of the producer's array (same memory, so a write by the consumer is
refused by numpy instead of silently corrupting the producer); scalar and struct inputs see
the producer's very object. A cycle therefore moves no data and allocates nothing.

Components may cache ``port.data`` in ``on_configure()``/``on_start()``: the builder binds
ports before configuring, and a swapped-in component adopts the buffers of the one it replaces
before it is configured.
"""
from __future__ import annotations

import abc
import builtins
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from rt.errors import ConfigurationError

if TYPE_CHECKING:  # pragma: no cover
    from rt.engine.component import Component

_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def check_name(kind: str, name: str) -> str:
    """Return ``name`` if it is a valid identifier (no dots: they separate slot and port)."""
    if not isinstance(name, str) or not _NAME_RE.match(name):
        raise ConfigurationError(
            f"{kind} name {name!r} is not valid: use letters, digits and '_' "
            "(not starting with a digit, no dots)")
    return name


class Box:
    """A mutable holder for one scalar (``value``); the shared buffer of a scalar port."""

    __slots__ = ("value",)

    def __init__(self, value: Any) -> None:
        self.value = value

    def __repr__(self) -> str:
        return f"Box({self.value!r})"


class PortType(abc.ABC):
    """What flows through a port; two ports connect only if their types are equal."""

    @abc.abstractmethod
    def allocate(self, initial: Any = None) -> Any:
        """A new buffer holding ``initial`` (or the type's default: zeros, 0, False, cls())."""

    @abc.abstractmethod
    def reader_view(self, buf: Any) -> Any:
        """What a connected input port sees of an output buffer (zero-copy)."""

    @abc.abstractmethod
    def copier(self) -> Callable[[Any, Any], None]:
        """A function ``copy(dst, src)`` that copies a buffer in place (delays, resets)."""

    @abc.abstractmethod
    def check_initial(self, initial: Any) -> None:
        """Raise ConfigurationError if ``initial`` cannot initialise a buffer of this type."""


@dataclass(frozen=True)
class ArrayType(PortType):
    """A fixed-shape float64 array (units are the port's, stated in the owner's docstring)."""

    shape: tuple[int, ...]

    def __post_init__(self) -> None:
        if not isinstance(self.shape, tuple) or not all(
                isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n > 0
                for n in self.shape):
            raise ConfigurationError(f"array port shape must be positive integers, got {self.shape!r}")

    def __str__(self) -> str:
        return "float64[" + ",".join(str(n) for n in self.shape) + "]"

    def allocate(self, initial: Any = None) -> np.ndarray:
        buf = np.zeros(self.shape, dtype=np.float64)
        if initial is not None:
            self.check_initial(initial)
            buf[...] = initial
        return buf

    def reader_view(self, buf: np.ndarray) -> np.ndarray:
        view = buf.view()
        view.flags.writeable = False
        return view

    def copier(self) -> Callable[[Any, Any], None]:
        def copy(dst: np.ndarray, src: np.ndarray) -> None:
            dst[...] = src
        return copy

    def check_initial(self, initial: Any) -> None:
        try:
            arr = np.asarray(initial, dtype=np.float64)
            np.broadcast_to(arr, self.shape)
        except (TypeError, ValueError) as exc:
            raise ConfigurationError(
                f"initial value {initial!r} does not fit a {self} port: {exc}") from None


@dataclass(frozen=True)
class ScalarType(PortType):
    """One ``float``, ``int`` or ``bool`` held in a :class:`Box`."""

    kind: type

    def __post_init__(self) -> None:
        if self.kind not in (float, int, bool):
            raise ConfigurationError(
                f"scalar ports carry float, int or bool, not {getattr(self.kind, '__name__', self.kind)}")

    def __str__(self) -> str:
        return self.kind.__name__

    def allocate(self, initial: Any = None) -> Box:
        if initial is None:
            return Box(self.kind())
        self.check_initial(initial)
        return Box(self.kind(initial))

    def reader_view(self, buf: Box) -> Box:
        return buf

    def copier(self) -> Callable[[Any, Any], None]:
        def copy(dst: Box, src: Box) -> None:
            dst.value = src.value
        return copy

    def check_initial(self, initial: Any) -> None:
        if self.kind is bool:
            ok = isinstance(initial, (bool, np.bool_))
        elif self.kind is int:
            ok = isinstance(initial, (int, np.integer)) and not isinstance(initial, bool)
        else:
            ok = isinstance(initial, (int, float, np.integer, np.floating)) and not isinstance(
                initial, bool)
        if not ok:
            raise ConfigurationError(f"initial value {initial!r} does not fit a {self} port")


@dataclass(frozen=True)
class StructType(PortType):
    """An instance of a small mutable class (constructed with no arguments), shared in place."""

    cls: type

    def __str__(self) -> str:
        return self.cls.__qualname__

    def allocate(self, initial: Any = None) -> Any:
        buf = self.cls()
        if initial is not None:
            self.check_initial(initial)
            self.copier()(buf, initial)
        return buf

    def reader_view(self, buf: Any) -> Any:
        return buf

    @property
    def copyable(self) -> bool:
        return callable(getattr(self.cls, "copy_from", None))

    def copier(self) -> Callable[[Any, Any], None]:
        if not self.copyable:
            raise ConfigurationError(
                f"struct type {self} has no copy_from(other) method; it is needed for delayed "
                "connections and resets")

        def copy(dst: Any, src: Any) -> None:
            dst.copy_from(src)
        return copy

    def check_initial(self, initial: Any) -> None:
        if not isinstance(initial, self.cls):
            raise ConfigurationError(f"initial value {initial!r} is not a {self}")


def Array(*shape: int) -> ArrayType:
    """Array port type of the given shape: ``Array(3)``, ``Array(3, 3)``."""
    return ArrayType(tuple(shape))


def Struct(cls: type) -> StructType:
    """Struct port type carrying instances of ``cls``."""
    return StructType(cls)


FLOAT = ScalarType(float)
INT = ScalarType(int)
BOOL = ScalarType(bool)


class Port:
    """Common part of input and output ports.

    ``data`` is the buffer (array, :class:`Box` or struct instance). It is a plain attribute
    rather than a property because it is read every cycle (a slot read costs ≈ 12 ns, a
    property ≈ 60 ns); never assign to it from a component.
    """

    __slots__ = ("data", "doc", "name", "owner", "type")

    def __init__(self, owner: Component, name: str, type: PortType, doc: str) -> None:
        if not isinstance(type, PortType):
            raise ConfigurationError(
                f"port {owner.name}.{name}: type must be a PortType (Array(n), FLOAT, INT, BOOL, "
                f"Struct(cls)), got {type!r}")
        self.owner = owner
        self.name = check_name("port", name)
        self.type = type
        self.doc = doc
        self.data: Any = None

    @property
    def path(self) -> str:
        """``component.port`` using the owner's component name."""
        return f"{self.owner.name}.{self.name}"


class OutputPort(Port):
    """An output: owns its buffer (allocated once, at declaration)."""

    __slots__ = ("initial",)

    def __init__(self, owner: Component, name: str, type: PortType, doc: str = "",
                 initial: Any = None, buffer: np.ndarray | None = None) -> None:
        super().__init__(owner, name, type, doc)
        self.initial = initial
        if buffer is None:
            self.data = type.allocate(initial)
            return
        # A view into the owner's arena: the block's kernel then takes all its outputs as one
        # argument (numba's dispatch costs per array argument).
        if not isinstance(type, ArrayType):
            raise ConfigurationError(f"port {owner.name}.{name}: only array ports can live in "
                                     f"a given buffer, not a {type} port")
        if not (isinstance(buffer, np.ndarray) and buffer.dtype == np.float64
                and buffer.shape == type.shape and buffer.flags.writeable):
            raise ConfigurationError(
                f"port {owner.name}.{name}: its buffer must be a writeable float64 array of "
                f"shape {type.shape}, got "
                f"{getattr(buffer, 'dtype', builtins.type(buffer).__name__)}{getattr(buffer, 'shape', '')}")
        buffer[...] = type.allocate(initial)
        self.data = buffer

    def reset_value(self) -> None:
        """Put the buffer back to its initial value, in place (not in the cycle: may allocate)."""
        self.type.copier()(self.data, self.type.allocate(self.initial))

    def _adopt(self, buf: Any) -> None:
        """Take over another output's buffer (a swap keeps the consumers' views valid)."""
        self.data = buf

    def __repr__(self) -> str:
        return f"<output {self.path}: {self.type}>"


class InputPort(Port):
    """An input: ``data`` is ``None`` until the builder binds it to a producer's buffer."""

    __slots__ = ("source",)

    def __init__(self, owner: Component, name: str, type: PortType, doc: str = "") -> None:
        super().__init__(owner, name, type, doc)
        self.source: str | None = None

    @property
    def connected(self) -> bool:
        return self.data is not None

    def _bind(self, view: Any, source: str) -> None:
        self.data = view
        self.source = source

    def __repr__(self) -> str:
        src = f" <- {self.source}" if self.source else " (unconnected)"
        return f"<input {self.path}: {self.type}{src}>"
