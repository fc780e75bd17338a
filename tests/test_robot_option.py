"""``--robot FILE`` reaches every command that loads the robot model."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from talus.cli import main as talus_main

NOMINAL = Path(__file__).resolve().parents[1] / "rt" / "data" / "robot_nominal.yaml"

COMMANDS = [
    ["rt", "serve", "--seconds", "1"],
    ["bench", "loop", "--seconds", "0.1", "--mode", "fast"],
    ["bench", "tracking", "--experiment", "payload-step"],
    ["bench", "force"],
    ["twin", "step", "--seconds", "0.1", "--volts", "0", "0", "0"],
    ["twin", "serve-ati", "--env", "free", "--seconds", "0.1", "--port", "0"],
    ["twin", "rig", "--shm", "talus-robot-option-test", "--seconds", "0.1"],
    ["faults", "matrix"],
    ["model", "describe"],
]


@pytest.mark.parametrize("argv", COMMANDS, ids=lambda a: " ".join(a[:2]))
def test_every_model_command_reads_robot(argv: list[str], tmp_path: Path,
                                         capsys: pytest.CaptureFixture) -> None:
    """A bad file is read (and refused in one line, exit 2) before anything runs."""
    bad = tmp_path / "robot.yaml"
    bad.write_text("geometry: [not, a, description]\n")
    assert talus_main([*argv, "--robot", str(bad)]) == 2
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and str(bad) in json.loads(out[0])["error"]


def test_twin_step_simulates_the_given_robot(tmp_path: Path,
                                             capsys: pytest.CaptureFixture) -> None:
    """With the drives at 0 V the sliders sink; a 40 kg platform sinks them faster than the
    nominal 8 kg one."""
    heavy = tmp_path / "heavy.yaml"
    text = NOMINAL.read_text()
    assert text.count("mass_kg: 8.0") == 1
    heavy.write_text(text.replace("mass_kg: 8.0", "mass_kg: 40.0"))
    finals = []
    for extra in ([], ["--robot", str(heavy)]):
        assert talus_main(["twin", "step", "--seconds", "0.3", "--volts", "0", "0", "0",
                           "--rate", "10", *extra]) == 0
        lines = capsys.readouterr().out.strip().splitlines()
        finals.append(json.loads(lines[-1])["q"][0])
    assert finals[1] < finals[0] - 1e-4, finals
