"""Wiring components into a graph, and running one cycle of it (DESIGN 5; thesis 3.3.3-3.7).

The thesis cascaded one periodic trigger through Orocos event ports: the encoder component
ran periodically and every other component ran when its inputs arrived. Here the same
behaviour is made explicit and deterministic: :class:`GraphBuilder` checks the wiring and
sorts the components in dependency order once; :meth:`Graph.step` then runs them in that
order every cycle, so each component sees its producers' outputs of the *same* cycle. A
feedback path must go through a one-cycle delay (``connect(..., delay=1)``), which the graph
implements as a latch buffer copied from the producer at the end of every cycle (producer's
buffer + latch = double buffer): the consumer reads the previous cycle's value whatever the
order.

Execution times (per slot and whole cycle, ns from ``time.perf_counter_ns``) go into
preallocated rings; :meth:`Graph.stats` summarises them. A component whose ``update`` returns
non-zero or raises is moved to ``error``, recorded as a :class:`~rt.engine.stats.Fault`, and
skipped from then on; the other components keep running (the supervisor decides what to do).
"""
from __future__ import annotations

import itertools
from array import array
from collections import deque
from dataclasses import dataclass
from time import perf_counter_ns
from typing import Any, TypeVar

import numpy as np

from rt.engine.component import STATUS_EXCEPTION, Component, Lifecycle, LifecycleError
from rt.engine.latches import copy_latches, latch_table
from rt.engine.ports import InputPort, OutputPort, PortType, StructType, check_name
from rt.engine.stats import (
    DEFAULT_CAPACITY,
    Fault,
    GraphStats,
    SlotStats,
    check_capacity,
    new_ring,
    summarize,
)
from rt.epoch import bump
from rt.errors import ConfigurationError, InputError

#: The graph's clock when it is not timed (:attr:`Graph.timed`): a C callable that returns 0,
#: cheaper than ``perf_counter_ns`` (≈ 25 against ≈ 75 ns, a dozen calls a cycle).
_untimed_clock = itertools.repeat(0).__next__
_NO_SAMPLES = np.full(1, -1, dtype=np.int64)

_C = TypeVar("_C", bound=Component)

FAULT_HISTORY = 1024
"""Faults kept by a graph (the total count is always kept)."""


@dataclass(frozen=True)
class Connection:
    """``source`` output → ``target`` input, both ``"slot.port"``; ``delay`` 0 or 1 cycle."""

    source: str
    target: str
    delay: int = 0
    initial: Any = None

    def __str__(self) -> str:
        d = ", delay=1" if self.delay else ""
        return f"connect({self.source!r} -> {self.target!r}{d})"


def _split(endpoint: str) -> tuple[str, str]:
    if not isinstance(endpoint, str) or endpoint.count(".") != 1:
        raise ConfigurationError(
            f"port address {endpoint!r} must be 'slot.port' (exactly one dot)")
    slot, port = endpoint.split(".")
    return slot, port


class GraphBuilder:
    """Collects components and connections, then :meth:`build` checks and wires them.

    Components are addressed by *slot* name, which defaults to the component's name; a slot
    keeps its name when :meth:`Graph.swap` puts another component in it.
    """

    def __init__(self, stats_capacity: int = DEFAULT_CAPACITY) -> None:
        self._capacity = check_capacity(stats_capacity)
        self._slots: dict[str, Component] = {}
        self._connections: list[Connection] = []
        self._built = False

    def add(self, component: _C, slot: str | None = None) -> _C:
        """Add ``component`` in ``slot`` (default: its name); returns the component."""
        self._check_open()
        if not isinstance(component, Component):
            raise ConfigurationError(f"only Component instances can be added, not {component!r}")
        slot = check_name("slot", component.name if slot is None else slot)
        if slot in self._slots:
            raise ConfigurationError(f"slot {slot!r} is already taken by {self._slots[slot]!r}")
        if any(c is component for c in self._slots.values()) or component._graph is not None:
            raise ConfigurationError(f"{component!r} is already in a graph")
        component._sealed = True
        self._slots[slot] = component
        return component

    def connect(self, source: str, target: str, *, delay: int = 0, initial: Any = None) -> None:
        """Connect output ``"slot.port"`` to input ``"slot.port"``.

        ``delay=1`` makes the consumer read the producer's value of the previous cycle (and
        ``initial``, default the producer port's initial value, on the first cycle): the only
        way to close a loop. Problems are reported all together by :meth:`build`.
        """
        self._check_open()
        _split(source)
        _split(target)
        self._connections.append(Connection(source, target, delay, initial))

    def _check_open(self) -> None:
        if self._built:
            raise ConfigurationError("this GraphBuilder has already built its graph; make a new one")

    # ------------------------------------------------------------------ build
    def _resolve(self, errors: list[str]) -> list[tuple[Connection, OutputPort, InputPort]]:
        resolved = []
        slots = ", ".join(self._slots) or "none"
        for c in self._connections:
            ports: list[Any] = []
            for endpoint, want in ((c.source, "output"), (c.target, "input")):
                slot, pname = _split(endpoint)
                comp = self._slots.get(slot)
                if comp is None:
                    errors.append(f"{c}: no component in slot {slot!r} (slots: {slots})")
                    ports.append(None)
                    continue
                mine, other = ((comp.outputs, comp.inputs) if want == "output"
                               else (comp.inputs, comp.outputs))
                if pname in mine:
                    ports.append(mine[pname])
                elif pname in other:
                    errors.append(f"{c}: {endpoint!r} is an {'input' if want == 'output' else 'output'}"
                                  f" port; the {'source' if want == 'output' else 'target'} must be"
                                  f" an {want} port")
                    ports.append(None)
                else:
                    errors.append(f"{c}: component {comp.name!r} in slot {slot!r} has no {want} "
                                  f"port {pname!r} ({want}s: {', '.join(mine) or 'none'})")
                    ports.append(None)
            src, dst = ports
            if c.delay not in (0, 1):
                errors.append(f"{c}: delay must be 0 or 1 cycle, got {c.delay!r}")
            if c.initial is not None and not c.delay:
                errors.append(f"{c}: an initial value only applies to a delayed connection")
            if src is None or dst is None:
                continue
            if src.type != dst.type:
                errors.append(f"{c}: type mismatch: output {c.source!r} is {src.type}, "
                              f"input {c.target!r} is {dst.type}")
                continue
            if c.delay == 1:
                if isinstance(src.type, StructType) and not src.type.copyable:
                    errors.append(f"{c}: a delayed {src.type} connection needs "
                                  f"{src.type}.copy_from(other)")
                    continue
                if c.initial is not None:
                    try:
                        src.type.check_initial(c.initial)
                    except ConfigurationError as exc:
                        errors.append(f"{c}: {exc}")
                        continue
            resolved.append((c, src, dst))
        return resolved

    def _order(self, resolved: list[tuple[Connection, OutputPort, InputPort]],
               errors: list[str]) -> list[str]:
        """Kahn's algorithm over undelayed edges; ties keep the order of ``add`` (determinism)."""
        names = list(self._slots)
        slot_of = {id(c): s for s, c in self._slots.items()}
        edges: dict[str, list[tuple[str, Connection]]] = {s: [] for s in names}
        indeg = {s: 0 for s in names}
        for c, src, dst in resolved:
            if c.delay:
                continue
            a, b = slot_of[id(src.owner)], slot_of[id(dst.owner)]
            edges[a].append((b, c))
            indeg[b] += 1
        order: list[str] = []
        ready = [s for s in names if indeg[s] == 0]
        while ready:
            s = ready.pop(0)
            order.append(s)
            for b, _ in edges[s]:
                indeg[b] -= 1
                if indeg[b] == 0:
                    ready.append(b)
                    ready.sort(key=names.index)
        if len(order) < len(names):
            errors.append(self._describe_cycle(set(names) - set(order), edges))
        return order

    @staticmethod
    def _describe_cycle(left: set[str], edges: dict[str, list[tuple[str, Connection]]]) -> str:
        # Every node Kahn could not order still has an incoming edge from another such node, so
        # walking incoming edges backwards inside `left` never gets stuck and must revisit a
        # node: the nodes between the two visits form a cycle.
        incoming: dict[str, tuple[str, Connection]] = {}
        for a in sorted(left):
            for b, c in edges[a]:
                if b in left and b not in incoming:
                    incoming[b] = (a, c)
        node = min(left)
        walk: list[Connection] = []
        seen: dict[str, int] = {}
        while node not in seen:
            seen[node] = len(walk)
            node, conn = incoming[node]
            walk.append(conn)
        cycle = walk[seen[node]:][::-1]
        hops = ", ".join(f"{c.source} -> {c.target}" for c in cycle)
        return (f"cycle without delay: {hops}; break it with connect(..., delay=1) on one of "
                f"these connections")

    def build(self) -> Graph:
        """Check everything, wire the ports (zero-copy) and return the :class:`Graph`.

        Raises ConfigurationError listing every problem found: unknown slots or ports, an
        input used as a source (or vice versa), type/shape mismatches, inputs left
        unconnected or connected twice, bad delays, and cycles without a delay.
        """
        self._check_open()
        if not self._slots:
            raise ConfigurationError("graph refused: no components")
        errors: list[str] = []
        resolved = self._resolve(errors)
        sources: dict[int, list[Connection]] = {}
        for c, _src, dst in resolved:
            sources.setdefault(id(dst), []).append(c)
        for c, _src, dst in resolved:
            got = sources[id(dst)]
            if len(got) > 1 and got[0] is c:
                errors.append(f"input {c.target!r} is connected {len(got)} times (from "
                              f"{', '.join(repr(x.source) for x in got)}); an input takes exactly "
                              "one source")
        targeted = {c.target for c in self._connections}  # incl. failed ones: reported above
        for slot, comp in self._slots.items():
            for pname, port in comp.inputs.items():
                if f"{slot}.{pname}" not in targeted:
                    errors.append(f"input {slot}.{pname} ({port.type}) is not connected")
        order = self._order(resolved, errors)
        if errors:
            raise ConfigurationError("graph refused:\n  - " + "\n  - ".join(errors))

        slot_of = {id(c): s for s, c in self._slots.items()}
        latches: list[_Latch] = []
        for c, src, dst in resolved:
            source = f"{slot_of[id(src.owner)]}.{src.name}"
            if c.delay:
                initial = c.initial if c.initial is not None else src.initial
                latch = src.type.allocate(initial)
                latches.append(_Latch(src.type, latch, src.data, initial))
                dst._bind(src.type.reader_view(latch), source + " (delay 1)")
            else:
                dst._bind(src.type.reader_view(src.data), source)
        self._built = True
        return Graph([(s, self._slots[s]) for s in order], list(self._connections), latches,
                     self._capacity)


@dataclass(frozen=True)
class _Latch:
    """A one-cycle delay: ``buffer`` (what the consumer reads) ← ``source`` (producer's)."""

    type: PortType
    buffer: Any
    source: Any
    initial: Any


@dataclass
class SwapPlan:
    """A swap checked and prepared off the cycle by :meth:`Graph.prepare_swap`."""

    slot: str
    old: Component
    new: Component


class Graph:
    """Components in dependency order, run by :meth:`step`; built by :class:`GraphBuilder`.

    Not thread-safe by itself: one thread (the loop's) calls ``step`` and the ``commit_*``
    methods; other threads go through the :class:`~rt.engine.loop.Loop`'s command queue.
    """

    def __init__(self, slots: list[tuple[str, Component]], connections: list[Connection],
                 latches: list[_Latch], capacity: int) -> None:
        self._order = tuple(s for s, _ in slots)
        self._components: dict[str, Component] = dict(slots)
        self._connections = tuple(connections)
        self._capacity = capacity
        self._mask = capacity - 1
        # The cycle stores each slot's time into an ``array.array`` (a store costs about two
        # thirds of a numpy int64 store; the engine's no-op cycle of ``bench/loop_overhead.py``
        # fell by 12 %); readers see the same memory as numpy views (``_rings``).
        self._stores = [array("q", new_ring(capacity).tobytes()) for _ in slots]
        self._rings = [np.frombuffer(st, dtype=np.int64) for st in self._stores]
        self._cycle_store = array("q", new_ring(capacity).tobytes())
        self._cycle_ring = np.frombuffer(self._cycle_store, dtype=np.int64)
        self._cycle_max = 0
        self._skips = [0] * len(slots)
        self._base = [0] * len(slots)  # graph cycle count when the slot's occupant arrived
        self._run = [(k, comp, comp.update, self._stores[k]) for k, (_, comp) in enumerate(slots)]
        # (copy, latch, producer buffer) triples: the producer buffer object never changes,
        # even across swaps (the new component adopts it), so this list is built once.
        self._latches = [(lt.type.copier(), lt.buffer, lt.source) for lt in latches]
        # All latches float64 arrays (the position loop's): one compiled copy of them all.
        self._latch_table = latch_table([(lt.buffer, lt.source) for lt in latches])
        self._latch_specs = tuple(latches)
        self._idx = 0
        self._cycles = 0
        self._clock = perf_counter_ns     # the blocks' and the cycle's clock (``timed``)
        self._faults: deque[Fault] = deque(maxlen=FAULT_HISTORY)
        self.fault_count = 0
        #: Slots whose component a fault in ``update`` put in error, with the reason; emptied
        #: by :meth:`restart_failed` / :meth:`reset`. Read every cycle by the supervisor.
        self.failed: dict[str, str] = {}
        """Total faults so far; a supervisor may poll it every cycle (a plain int read)."""
        self._running = False
        #: Bumped at every lifecycle change (start, stop, reset, restart, swap): a fused
        #: segment binds its buffers again when it changed.
        self.generation = 0
        self._segment: Any = None
        self._seg_faults = 0
        self._fused = False
        self._seg_first = 0
        self._pre: list = []
        self._seg: list = []
        self._seg_tails: list = []
        self._post: list = []
        for _, comp in slots:
            comp._graph = self

    # ------------------------------------------------------------------ introspection
    @property
    def order(self) -> tuple[str, ...]:
        """Slot names in execution order."""
        return self._order

    @property
    def components(self) -> dict[str, Component]:
        """Slot → current component (a copy)."""
        return dict(self._components)

    def component(self, slot: str) -> Component:
        """The component in ``slot``."""
        try:
            return self._components[slot]
        except KeyError:
            raise InputError(f"no slot {slot!r} (slots: {', '.join(self._order)})") from None

    @property
    def connections(self) -> tuple[Connection, ...]:
        return self._connections

    @property
    def cycles(self) -> int:
        """Cycles stepped so far."""
        return self._cycles

    @property
    def running(self) -> bool:
        """True between :meth:`start` and :meth:`stop`."""
        return self._running

    def output(self, address: str) -> Any:
        """Read-only view of output ``"slot.port"`` (for recording, telemetry, tests)."""
        slot, pname = _split(address)
        comp = self.component(slot)
        port = comp.outputs.get(pname)
        if port is None:
            raise InputError(f"slot {slot!r} ({comp.name}) has no output {pname!r} "
                             f"(outputs: {', '.join(comp.outputs) or 'none'})")
        return port.type.reader_view(port.data)

    def describe(self) -> str:
        """Execution order, each slot's ports and the connections, as text."""
        lines = ["execution order: " + " -> ".join(self._order)]
        for slot in self._order:
            comp = self._components[slot]
            lines.append(f"[{slot}] {type(comp).__name__} {comp.name!r} ({comp.lifecycle.value})")
            lines += ["    " + ln for ln in comp.describe_ports().splitlines()]
        lines += [f"  {c}" for c in self._connections]
        return "\n".join(lines)

    def faults(self) -> list[Fault]:
        """The most recent faults (up to FAULT_HISTORY), oldest first."""
        return list(self._faults)

    # ------------------------------------------------------------------ fused segment
    def fuse(self, segment: Any, enabled: bool = True) -> None:
        """Let ``segment`` run its consecutive slots (``segment.slots``, in execution order)
        in one call per cycle (e.g. ``rt.components.fused.FusedChain``): each cycle
        ``segment.run(t, dt, idx)`` returns how many of those slots it ran (0: none), having
        written the times (ns) of those after the first into their rings (``attach`` gives it
        the rings' addresses) at ``idx`` and their sum in ``segment.others_ns``, and in
        ``segment.pending`` None or the Python that completes
        the last one (timed into its ring; its exception or non-zero status is that slot's
        fault, as an ``update``'s). The slots it did not run run their ``update`` in the same
        cycle. ``enabled`` (also :attr:`fused`) False keeps every slot's ``update``."""
        slots = tuple(segment.slots)
        if not slots or slots[0] not in self._order:
            raise ConfigurationError(f"fused segment {slots!r}: no such slots in {self._order}")
        i = self._order.index(slots[0])
        if self._order[i:i + len(slots)] != slots:
            raise ConfigurationError(f"fused segment {slots!r} is not consecutive in the "
                                     f"execution order {self._order}")
        self._segment = segment
        self._seg_first = i
        segment.attach(self, [self._stores[i + j].buffer_info()[0] for j in range(len(slots))])
        self._split_run()
        self.fused = enabled
        if self._running:
            segment.prepare()

    @property
    def fused(self) -> bool:
        """True while a fused segment (:meth:`fuse`) runs its slots; settable between cycles
        (False: every slot's ``update``, the per-block reference)."""
        return self._fused

    @fused.setter
    def fused(self, on: bool) -> None:
        self._fused = bool(on) and self._segment is not None
        bump()                        # a toggle ends the segment's steady plan

    @property
    def segment(self) -> Any:
        """The fused segment (:meth:`fuse`), or None."""
        return self._segment

    def segment_run(self) -> list:
        """The fused segment's slots as :meth:`run_blocks` takes them (one entry per slot, in
        order); the list changes at a swap (the segment binds again then)."""
        return list(self._seg)

    def run_blocks(self, run: list, t: float, dt: float, idx: int) -> int:
        """For the fused segment, inside its ``run``: the blocks ``run`` (entries of
        :meth:`segment_run`) per block now, each timed into its ring with its fault recorded
        and counted in the cycle's, as :meth:`step` runs them; returns the ns they took.
        Why: a sensor whose backend calls a driver keeps its block while the stages after it
        run fused."""
        t0 = perf_counter_ns()
        faults, end = self._blocks(run, t, dt, idx, t0)
        self._seg_faults += faults
        return end - t0

    def _split_run(self) -> None:
        if self._segment is None:
            return
        i, n = self._seg_first, len(self._segment.slots)
        self._pre = self._run[:i]
        self._seg = self._run[i:i + n]
        self._seg_tails = [self._seg[j:] for j in range(n + 1)]
        self._post = self._run[i + n:]

    @property
    def timed(self) -> bool:
        """Whether the cycle times its blocks and itself (the default). A pre-flight, which
        never reads the times, turns it off: the same cycle with a clock that reads 0
        (:meth:`stats` then reports no samples). The timing of the fused segment's stages
        is the segment's own."""
        return self._clock is perf_counter_ns

    @timed.setter
    def timed(self, on: bool) -> None:
        self._clock = perf_counter_ns if on else _untimed_clock
        self.reset_stats()

    # ------------------------------------------------------------------ lifecycle
    def configure(self) -> None:
        """Configure every unconfigured component, in execution order."""
        for slot in self._order:
            comp = self._components[slot]
            if comp.lifecycle is Lifecycle.UNCONFIGURED:
                comp.configure()

    def start(self) -> None:
        """Start every inactive component; refuses if one is unconfigured or in error.

        If a start fails, the components already started are stopped again."""
        bad = [f"{s} ({c.name}: {c.lifecycle.value}"
               + (f": {c.fault_reason})" if c.fault_reason else ")")
               for s, c in self._components.items()
               if c.lifecycle in (Lifecycle.UNCONFIGURED, Lifecycle.ERROR)]
        if bad:
            raise LifecycleError("graph cannot start: " + ", ".join(bad)
                                 + "; configure() or reset() them first")
        started: list[Component] = []
        try:
            for slot in self._order:
                comp = self._components[slot]
                if comp.lifecycle is Lifecycle.INACTIVE:
                    comp.start()
                    started.append(comp)
        except LifecycleError:
            for comp in reversed(started):
                comp.stop()
            raise
        self._running = True
        self.generation += 1
        bump()
        if self._segment is not None:
            self._segment.prepare()       # bound (and its kernel loaded) now, not in a cycle

    def stop(self) -> None:
        """Stop every active component (reverse order); all are attempted, failures reported."""
        self._running = False
        self.generation += 1
        bump()
        failures = []
        for slot in reversed(self._order):
            comp = self._components[slot]
            if comp.lifecycle is Lifecycle.ACTIVE:
                try:
                    comp.stop()
                except LifecycleError as exc:
                    failures.append(str(exc))
        if failures:
            raise LifecycleError("; ".join(failures))

    def failed_components(self) -> str | None:
        """``"slot: reason; ..."`` for the components a fault put in error, None when none
        (cheap when none: the supervisor asks every cycle)."""
        if not self.failed:
            return None
        return "; ".join(f"{slot}: {why}" for slot, why in self.failed.items())

    def restart_failed(self, also: tuple[str, ...] = ()) -> dict[str, str]:
        """Between cycles of a running graph: reset and start again each component a fault put
        in error, and the running ones of ``also`` (state rebuilt from its parameters, as a
        fresh start). Returns ``{slot: why}`` for those that would not restart (a failed one
        stays in error, and in :attr:`failed`).

        Why: a device read that failed once (a stalled twin rig process, a card that timed
        out) must not leave the loop without that component for the life of the process; the
        supervisor hard-stops while one is in error, and the operator's reset restarts it."""
        refused: dict[str, str] = {}
        self.generation += 1
        bump()
        for slot in list(self.failed) + [s for s in also if s not in self.failed]:
            comp = self._components[slot]
            try:
                if comp.lifecycle is Lifecycle.ACTIVE:
                    comp.stop()
                if comp.lifecycle in (Lifecycle.ERROR, Lifecycle.INACTIVE):
                    comp.reset()
                if comp.lifecycle is Lifecycle.INACTIVE:
                    comp.start()
            except (LifecycleError, ConfigurationError) as exc:
                refused[slot] = str(exc)
                continue
            self.failed.pop(slot, None)
        bump()
        return refused

    def reset(self) -> None:
        """Back to the initial condition for a deterministic replay: components' state rebuilt
        (faults cleared), outputs and delay latches back to their initial values. The graph
        must be stopped. Timing statistics are kept (see :meth:`reset_stats`)."""
        if self._running:
            raise LifecycleError("graph.reset(): stop the graph first")
        self.generation += 1
        bump()
        for slot in self._order:
            comp = self._components[slot]
            if comp.lifecycle in (Lifecycle.INACTIVE, Lifecycle.ERROR):
                comp.reset()
            self.failed.pop(slot, None)
            for port in comp.outputs.values():
                port.reset_value()
        for lt in self._latch_specs:
            lt.type.copier()(lt.buffer, lt.type.allocate(lt.initial))
        bump()

    # ------------------------------------------------------------------ the cycle
    def step(self, t: float, dt: float) -> int:
        """Run one cycle: every active component's ``update(t, dt)`` in dependency order, then
        the delay latches. ``t`` loop time (s), ``dt`` measured period (s).

        Returns the number of components that faulted in this cycle (0 = all fine). Allocates
        nothing but transient ints; never raises for a component's failure.
        """
        if self._fused:
            return self._step_fused(t, dt)
        idx = self._idx
        t0 = self._clock()
        faults, _ = self._blocks(self._run, t, dt, idx, t0)
        return self._end_cycle(idx, t0, faults)

    def _end_cycle(self, idx: int, t0: int, faults: int) -> int:
        """The cycle's end, per block or fused: the delay latches, the cycle's time (from
        ``t0``, ns) into its ring and maximum, the ring index and the count; returns
        ``faults``."""
        table = self._latch_table
        if table is not None:
            copy_latches(table)
        else:
            for copy, latch, src in self._latches:
                copy(latch, src)
        elapsed = self._clock() - t0
        self._cycle_store[idx] = elapsed
        self._cycle_max = max(self._cycle_max, elapsed)
        self._idx = (idx + 1) & self._mask
        self._cycles += 1
        return faults

    def _blocks(self, run: list, t: float, dt: float, idx: int, prev: int) -> tuple[int, int]:
        """``step``'s per-block body over ``run`` (a part of the slots); returns (faults, the
        clock after the last)."""
        pc = self._clock
        faults = 0
        for k, comp, update, ring in run:
            if comp._active:
                try:
                    status = update(t, dt)
                except Exception as exc:  # noqa: BLE001 - a component bug must not kill the loop
                    now = pc()
                    ring[idx] = now - prev
                    prev = now
                    self._fault(k, comp, STATUS_EXCEPTION,
                                f"update raised {type(exc).__name__}: {exc}", t, exc)
                    faults += 1
                    continue
                now = pc()
                ring[idx] = now - prev
                prev = now
                if status:
                    self._fault(k, comp, int(status), f"update returned status {status}", t, None)
                    faults += 1
            else:
                ring[idx] = -1
                self._skips[k] += 1
        return faults, prev

    def _step_fused(self, t: float, dt: float) -> int:
        """:meth:`step` with the fused segment (:meth:`fuse`): the slots before it, then one
        ``segment.run`` for as many of its slots as it runs, its completion (``pending``),
        the segment's other slots and the slots after it, per block. The segment's first
        slot's time is the call's whole time minus the other stages' (the call's own
        overhead is charged to it), so the slots' times still add up to the cycle's."""
        pc = self._clock
        idx = self._idx
        t0 = pc()
        faults, prev = self._blocks(self._pre, t, dt, idx, t0)
        seg = self._segment
        try:
            n = seg.run(t, dt, idx)
        except Exception as exc:  # noqa: BLE001 - a bug of the segment must not kill the loop
            # Its checks run before its kernel: the blocks run this cycle, and every cycle
            # after it (the per-block path is the reference).
            self._fused = False
            self.last_exception = exc
            bump()
            n = 0
        faults += self._seg_faults
        self._seg_faults = 0
        if n:
            now = pc()
            seg_run = self._seg
            seg_run[0][3][idx] = now - prev - seg.others_ns
            prev = now
            pending = seg.pending
            if pending is not None:
                k, comp, _update, ring = seg_run[n - 1]
                try:
                    status = pending(t, dt)
                except Exception as exc:  # noqa: BLE001 - as an update's exception
                    now = pc()
                    ring[idx] += now - prev
                    prev = now
                    self._fault(k, comp, STATUS_EXCEPTION,
                                f"update raised {type(exc).__name__}: {exc}", t, exc)
                    faults += 1
                else:
                    now = pc()
                    ring[idx] += now - prev
                    prev = now
                    if status:
                        self._fault(k, comp, int(status), f"update returned status {status}",
                                    t, None)
                        faults += 1
        # (Empty in the steady fused cycle: no call then, ≈ 0.3 µs each.)
        tails = self._seg_tails[n]
        if tails:
            more, prev = self._blocks(tails, t, dt, idx, prev)
            faults += more
        if self._post:
            more, prev = self._blocks(self._post, t, dt, idx, prev)
            faults += more
        return self._end_cycle(idx, t0, faults)

    def _fault(self, k: int, comp: Component, code: int, reason: str, t: float,
               exc: BaseException | None) -> None:
        # The fault path may allocate: it runs once per fault, and faults latch.
        comp.error(reason)
        self.fault_count += 1
        self.failed[self._order[k]] = comp.fault_reason or reason
        bump()                        # the supervisor's cycle now reports it (Python)
        self._faults.append(Fault(self._cycles, t, self._order[k], comp.name, code,
                                  comp.fault_reason or reason))
        if exc is not None:
            self.last_exception = exc

    last_exception: BaseException | None = None
    """The last exception raised by a component's ``update`` (with its traceback), or None."""

    # ------------------------------------------------------------------ statistics
    def stats(self) -> GraphStats:
        """Execution-time statistics (µs) of every slot and of the whole cycle.

        Safe to call from another thread while the loop runs (it summarises a snapshot).
        """
        comps = {}
        timed = self.timed
        for k, slot in enumerate(self._order):
            comp = self._components[slot]
            count = self._cycles - self._base[k] - self._skips[k]
            s = summarize(self._rings[k] if timed else _NO_SAMPLES, count)
            comps[slot] = SlotStats(**s.as_dict(), component=comp.name,
                                    lifecycle=comp.lifecycle.value)
        return GraphStats(self._cycles,
                          summarize(self._cycle_ring if timed else _NO_SAMPLES, self._cycles,
                                    self._cycle_max),
                          comps, self.fault_count)

    def timing_samples(self) -> dict:
        """Copies of the timing rings (ns), aligned by cycle: ``{"cycle": int64[n],
        "components": {slot: int64[n]}}`` over the last n = min(cycles, capacity) cycles,
        oldest first; -1 marks a cycle in which a slot did not run. For benchmarks that need
        more than the summaries (e.g. a cycle's time minus one block's)."""
        capacity = len(self._cycle_ring)
        n = min(self._cycles, capacity)
        idx = np.arange(self._cycles - n, self._cycles) % capacity
        return {"cycle": self._cycle_ring[idx].copy(),
                "components": {slot: self._rings[k][idx].copy()
                               for k, slot in enumerate(self._order)}}

    def reset_stats(self) -> None:
        """Forget all timing samples (not the cycle count)."""
        for k, ring in enumerate(self._rings):
            ring.fill(-1)
            self._skips[k] = 0
            self._base[k] = self._cycles
        self._cycle_ring.fill(-1)
        self._cycle_max = 0

    # ------------------------------------------------------------------ reconfiguration
    def set_params(self, slot: str, **values: Any) -> None:
        """Set parameters of the component in ``slot`` now (see ``Component.set_params``).
        Call it from the loop's thread (or when no loop runs): the Loop does, at a boundary."""
        self.component(slot).set_params(**values)

    def prepare_swap(self, slot: str, new: Component) -> SwapPlan:
        """Check that ``new`` can replace the component in ``slot`` and get it ready, off the
        cycle: same input ports (names and types) as the old one, at least its outputs; then
        bind its inputs to the same sources, make its outputs adopt the old buffers (so the
        consumers' views stay valid) and configure it if needed. Raises InputError."""
        old = self.component(slot)
        if not isinstance(new, Component):
            raise InputError(f"swap into {slot!r}: {new!r} is not a Component")
        if new is old:
            raise InputError(f"swap into {slot!r}: {new.name!r} is already in that slot")
        if new._graph is not None:
            raise InputError(f"swap into {slot!r}: {new!r} is already in a graph")
        problems = []
        for name, inp in new.inputs.items():
            mine = old.inputs.get(name)
            if mine is None:
                problems.append(f"input {name!r} ({inp.type}) has no source in slot {slot!r} "
                                f"(its inputs: {', '.join(old.inputs) or 'none'})")
            elif mine.type != inp.type:
                problems.append(f"input {name!r} is {inp.type}, the slot's is {mine.type}")
        for name, out in old.outputs.items():
            theirs = new.outputs.get(name)
            if theirs is None:
                problems.append(f"output {name!r} ({out.type}) is missing")
            elif theirs.type != out.type:
                problems.append(f"output {name!r} is {theirs.type}, the slot's is {out.type}")
        if new.lifecycle not in (Lifecycle.UNCONFIGURED, Lifecycle.INACTIVE):
            problems.append(f"it is {new.lifecycle.value}; it must be unconfigured or inactive")
        if problems:
            raise InputError(f"cannot swap {new.name!r} into slot {slot!r}: " + "; ".join(problems))
        new._graph = self  # reserved: it cannot be prepared twice
        new._sealed = True
        for name, inp in new.inputs.items():
            src = old.inputs[name]
            inp._bind(src.data, src.source or "")
        for name, out in old.outputs.items():
            new.outputs[name]._adopt(out.data)
        if new.lifecycle is Lifecycle.UNCONFIGURED:
            try:
                new.configure()
            except ConfigurationError as exc:
                new._graph = None
                raise InputError(f"cannot swap {new.name!r} into slot {slot!r}: {exc}") from exc
        if self._segment is not None and slot in self._segment.slots:
            # Off the cycle: the fused kernel of the new block's law compiles or loads here.
            self._segment.prepare_swap(slot, new)
        return SwapPlan(slot, old, new)

    def commit_swap(self, plan: SwapPlan) -> None:
        """Put ``plan.new`` in the slot now (call at a cycle boundary, from the loop's thread).

        If the graph is running: ``new.start()``, then ``new.handover(old)``, then the slot
        switches and ``old.stop()``. If either of the first two fails, nothing changes (``new``
        is left inactive, or in error if its start hook failed) and InputError says why. The slot's timing statistics restart.
        """
        slot, old, new = plan.slot, plan.old, plan.new
        if self._components.get(slot) is not old:
            new._graph = None
            raise InputError(f"swap into {slot!r} abandoned: the slot changed since it was "
                             "prepared; prepare it again")
        started = False
        try:
            if self._running:
                new.start()
                started = True
            new.handover(old)
        except Exception as exc:
            if started:
                try:
                    new.stop()
                except LifecycleError:
                    pass
            new._graph = None
            raise InputError(f"swap of {new.name!r} into slot {slot!r} failed, "
                             f"{old.name!r} stays: {type(exc).__name__}: {exc}") from exc
        k = self._order.index(slot)
        self._components[slot] = new
        self._rings[k].fill(-1)
        self._skips[k] = 0
        self._base[k] = self._cycles
        self._run[k] = (k, new, new.update, self._stores[k])
        self._split_run()
        self.generation += 1
        bump()
        old._graph = None
        if old.lifecycle is Lifecycle.ACTIVE:
            try:
                old.stop()
            except LifecycleError:
                pass  # old is now in error with the reason recorded; the swap stands

    def swap(self, slot: str, new: Component) -> None:
        """prepare + commit in one go (when no loop runs, or from the loop's thread)."""
        self.commit_swap(self.prepare_swap(slot, new))
