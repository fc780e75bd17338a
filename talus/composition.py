"""What the RT process offers, composed where every package is known: protocol sessions from
``protocols``; later, identification and calibration programs from their packages."""
from __future__ import annotations

from typing import Any


def rt_extensions() -> dict[str, Any]:
    """Keyword arguments for ``rt.service.serve``: the session factory and extra programs."""
    from protocols.rt_session import ProtocolSessions

    return {"sessions": ProtocolSessions(), "programs": {}}
