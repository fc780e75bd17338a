"""What the RT process offers, composed where every package is known: protocol sessions from
``protocols``; calibration programs from ``calibration``; later, identification programs."""
from __future__ import annotations

from typing import Any


def rt_extensions() -> dict[str, Any]:
    """Keyword arguments for ``rt.service.serve``: the session factory and extra programs."""
    from calibration.rt_program import rt_programs
    from protocols.rt_session import ProtocolSessions

    return {"sessions": ProtocolSessions(), "programs": rt_programs()}
