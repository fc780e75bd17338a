"""talus protocols: declarative therapy/calibration protocols and their reference generators.

* :mod:`protocols.schema` — the file schema (pydantic, one model per ``kind``).
* :mod:`protocols.library` — ``load_protocol(path)``, ``list_library()``.
* :mod:`protocols.generators` — ``make_generator(...)`` → ``validate()`` / ``update(out)``.
* :mod:`protocols.output` — the per-cycle output struct, statuses, the validation report.
* :mod:`protocols.gait` — ground-reaction-force records (C3D, CSV) and the published shape.
* :mod:`protocols.profiles` — smooth time laws and angular paths.
"""
from protocols.generators import Generator, make_generator
from protocols.library import list_library, load_protocol
from protocols.output import (
                              GeneratorInput,
                              GeneratorStatus,
                              Mode,
                              ReferenceOutput,
                              ValidationReport,
)
from protocols.schema import (
                              ActiveAssist,
                              AnkleRom,
                              GaitReplay,
                              IsometricHold,
                              PositionPlayback,
                              Protocol,
                              SineFz,
)

__all__ = ["ActiveAssist", "AnkleRom", "GaitReplay", "Generator", "GeneratorInput",
           "GeneratorStatus", "IsometricHold", "Mode", "PositionPlayback", "Protocol",
           "ReferenceOutput", "SineFz", "ValidationReport", "list_library", "load_protocol",
           "make_generator"]
