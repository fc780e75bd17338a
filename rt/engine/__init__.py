"""The real-time engine: typed ports, components, the graph and the periodic loop (DESIGN 5).

Typical use::

    b = GraphBuilder()
    b.add(Encoders("enc")); b.add(Pid("ctl"), slot="controller"); b.add(Dac("dac"))
    b.connect("enc.q", "controller.q"); b.connect("controller.u", "dac.u")
    loop = Loop(b.build(), rate_hz=1000.0, mode="realtime")
    loop.start(); ...; loop.swap("controller", PadenPanja("pp")).result(timeout=1.0); ...
    loop.stop(); loop.graph.stop()
"""
from rt.engine.commands import CommandResult
from rt.engine.component import STATUS_EXCEPTION, STATUS_OK, Component, Lifecycle, LifecycleError
from rt.engine.graph import Connection, Graph, GraphBuilder
from rt.engine.loop import MAX_RATE_HZ, MIN_RATE_HZ, Loop, LoopStats
from rt.engine.ports import (
                                 BOOL,
                                 FLOAT,
                                 INT,
                                 Array,
                                 ArrayType,
                                 Box,
                                 InputPort,
                                 OutputPort,
                                 PortType,
                                 ScalarType,
                                 Struct,
                                 StructType,
)
from rt.engine.stats import Fault, GraphStats, SlotStats, TimingStats

__all__ = [
                                 "BOOL",
                                 "FLOAT",
                                 "INT",
                                 "MAX_RATE_HZ",
                                 "MIN_RATE_HZ",
                                 "STATUS_EXCEPTION",
                                 "STATUS_OK",
                                 "Array",
                                 "ArrayType",
                                 "Box",
                                 "CommandResult",
                                 "Component",
                                 "Connection",
                                 "Fault",
                                 "Graph",
                                 "GraphBuilder",
                                 "GraphStats",
                                 "InputPort",
                                 "Lifecycle",
                                 "LifecycleError",
                                 "Loop",
                                 "LoopStats",
                                 "OutputPort",
                                 "PortType",
                                 "ScalarType",
                                 "SlotStats",
                                 "Struct",
                                 "StructType",
                                 "TimingStats",
]
