"""What the RT process offers, composed where every package is known: protocol sessions from
``protocols``; calibration programs from ``calibration``; identification programs from
``rt.identification``."""
from __future__ import annotations

from typing import Any


def rt_extensions() -> dict[str, Any]:
    """Keyword arguments for ``rt.service.serve``: the session factory and extra programs."""
    from calibration.rt_program import rt_programs as calibration_programs
    from protocols.rt_session import ProtocolSessions
    from rt.identification.program import rt_programs as identification_programs

    return {"sessions": ProtocolSessions(),
            "programs": {**calibration_programs(), **identification_programs()}}
