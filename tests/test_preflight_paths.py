"""Pre-flight's verdict does not depend on how the loop runs its cycle (issue 16).

Pre-flight runs the session's own loop as fast as possible: the fused cycle
(``rt.components.fused``: the middle blocks in one compiled call) where it covers the cycle,
the blocks' ``update`` elsewhere. Its verdict must be the per-block loop's to the last bit: the
same stop or none, the same peak forces and speeds, the same ``at_robot_limit`` moments.
ankle_rom (one repetition) is a position protocol (the fused chain runs almost every cycle); gait_replay is a
force protocol (the chain stops before the controller in force mode and the blocks finish the
cycle), so both hand-over paths are exercised.
"""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from protocols import session
from protocols.library import load_protocol
from rt.components.fused import ENV_FLAG
from rt.model import RobotModel

LIBRARY = Path(__file__).resolve().parent.parent / "protocols" / "library"


def _bits(x: object) -> object:
    """Every float as its hex (exact equality, NaN equal to NaN)."""
    if isinstance(x, float):
        return "nan" if math.isnan(x) else x.hex()
    if isinstance(x, dict):
        return {k: _bits(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_bits(v) for v in x]
    return x


@pytest.fixture(scope="module")
def model() -> RobotModel:
    return RobotModel.load()


@pytest.mark.parametrize("protocol", ["ankle_rom.yaml", "gait_replay.yaml"])
def test_the_fused_preflight_gives_the_per_block_verdict(protocol, model, monkeypatch):
    program = load_protocol(LIBRARY / protocol)
    if protocol == "ankle_rom.yaml":     # one repetition of each motion: 40 s → 14 s
        program = program.model_copy(update={"repetitions": 1})
    setup = session.SessionSetup(protocol=program, base_dir=LIBRARY, patient_weight_kg=70.0)
    build = session.build_twin_session
    loops = []

    def keep(*args, **kwargs):
        out = build(*args, **kwargs)
        loops.append(out[3])
        return out
    monkeypatch.setattr(session, "build_twin_session", keep)
    verdicts = {}
    for fused in ("1", "0"):
        monkeypatch.setenv(ENV_FLAG, fused)
        verdicts[fused] = session.preflight(setup, model)
    # Each path ran as asked: the fused one ran the chain, the other every block's update.
    assert [pl.graph.fused for pl in loops] == [True, False]
    assert verdicts["1"]["ok"] and verdicts["1"]["predicted"]["duration_s"] > 5.0
    assert _bits(verdicts["1"]) == _bits(verdicts["0"])
