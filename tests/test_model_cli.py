"""``talus model ...`` end to end, through the installed console script."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

TALUS = [shutil.which("talus") or "", ] if shutil.which("talus") else [sys.executable, "-m", "talus"]


def run(args: list[str], stdin: str = "") -> tuple[int, list[dict]]:
    proc = subprocess.run(TALUS + args, input=stdin,
                          check=False, capture_output=True, text=True, timeout=120)
    lines = [json.loads(line) for line in proc.stdout.splitlines() if line.strip()]
    return proc.returncode, lines


def test_ik_fk_round_trip_through_the_cli():
    code, out = run(["model", "ik"], '{"z": 0.65, "roll": 0.12, "pitch": -0.08}\n')
    assert code == 0 and len(out) == 1
    q = out[0]["q"]
    code, back = run(["model", "fk"], json.dumps({"q": q}) + "\n")
    assert code == 0
    # JSON carries floats with 17 significant digits: the round trip is exact to ~1e-12.
    assert back[0]["z"] == pytest.approx(0.65, abs=1e-11)
    assert back[0]["roll"] == pytest.approx(0.12, abs=1e-11)
    assert back[0]["pitch"] == pytest.approx(-0.08, abs=1e-11)
    assert back[0]["yaw"] == pytest.approx(out[0]["yaw"], abs=1e-11)


def test_dynamics_with_payload_through_the_cli():
    code, out = run(["model", "ik"], '{"z": 0.63, "roll": 0, "pitch": 0}\n')
    q = out[0]["q"]
    lines = (json.dumps({"q": q}) + "\n"
             + json.dumps({"q": q, "payload": {"mass_kg": 30.0}}) + "\n")
    code, out = run(["model", "dynamics"], lines)
    assert code == 0
    assert set(out[0]) == {"M", "C", "G", "F", "tau"}
    # At rest τ = G; 30 kg centred adds m g / 3 per slider.
    for a, b in zip(out[1]["tau"], out[0]["tau"]):
        assert a - b == pytest.approx(30.0 * 9.81 / 3.0, abs=1e-8)


@pytest.mark.parametrize("command, line, message", [
    ("ik", "not json", "not valid JSON"),
    ("ik", '[1, 2]', "must be a JSON object"),
    ("ik", '{"z": 0.6, "roll": 0}', 'missing key "pitch"'),
    ("ik", '{"z": 0.6, "roll": 0, "pitch": 0, "yaw": 1}', 'unknown key(s) ["yaw"]'),
    ("ik", '{"z": 0.6, "roll": 1.0, "pitch": 0}', "roll 57.30 deg exceeds"),
    ("fk", '{"q": [0.1, 0.2]}', '"q" must be a list of 3 numbers'),
    ("fk", '{"q": [0.1, 0.2, 0.9]}', "outside the stroke"),
    ("dynamics", '{"q": [0.2, 0.2, 0.2], "qd": [0, "a", 0]}', '"qd" must hold finite numbers'),
    ("dynamics", '{"q": [0.2, 0.2, 0.2], "payload": {"mass_kg": -3}}', "mass_kg"),
])
def test_bad_lines_get_an_error_line_and_exit_code(command, line, message):
    good = {"ik": '{"z": 0.63, "roll": 0, "pitch": 0}',
            "fk": '{"q": [0.2, 0.2, 0.2]}',
            "dynamics": '{"q": [0.2, 0.2, 0.2]}'}[command]
    code, out = run(["model", command], f"{line}\n{good}\n")
    assert code == 2
    assert message in out[0]["error"] and out[0]["line"] == 1
    assert "error" not in out[1]                 # later good lines are still answered


def test_describe_documents_frames_bodies_and_base_parameters():
    proc = subprocess.run(TALUS + ["model", "describe"],
                          check=False, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0
    d = json.loads(proc.stdout)
    assert set(d["frames"]) == {"B", "Li", "Ri", "P", "S"}
    assert d["bodies"]["rod"]["mass_kg"] == 1.2 and d["bodies"]["rod"]["frame"] == "Ri"
    lo, hi = d["workspace"]["heave_level_m"]
    assert hi - lo == pytest.approx(0.40, abs=2e-3)
    names = [p["name"] for p in d["base_parameters"]]
    assert "Jr0" in names and len(names) < 79


def test_bad_description_file_is_refused(tmp_path):
    bad = tmp_path / "robot.yaml"
    bad.write_text("schema_version: 1\nname: x\n")
    code, out = run(["model", "ik", "--robot", str(bad)], '{"z": 0.6, "roll": 0, "pitch": 0}\n')
    assert code == 2 and "geometry: Field required" in out[0]["error"]


#: (number as written, part of the error); each is put where a command expects a number.
HOSTILE_NUMBERS = [
    ("1" + "0" * 5000, "4300 digits"),        # an integer too long for Python to parse
    ("1" + "0" * 400, "finite number"),       # parses, but beyond the float range
    ("0." + "1" * 5000, ""),                  # parses to 0.111..: answered, error or not
    ("NaN", "NaN is not JSON"),
    ("-Infinity", "-Infinity is not JSON"),
]
#: (whole line, part of the error)
HOSTILE_LINES = [
    ('{"q": ' + "[" * 30_000 + "]" * 30_000 + "}", "nested too deeply"),
    ("[" * 100_000 + "]" * 100_000, "characters, more than"),
    ('{"q": [' + ",".join(["1"] * 20_000) + "]}", ""),
]


def _with_number(command: str, number: str) -> str:
    if command == "ik":
        return f'{{"z": {number}, "roll": 0, "pitch": 0}}'
    return f'{{"q": [{number}, 0.2, 0.2]}}'


@pytest.mark.parametrize("command", ["ik", "fk", "dynamics"])
def test_hostile_lines_are_answered_one_by_one_with_valid_json(command):
    good = {"ik": '{"z": 0.63, "roll": 0, "pitch": 0}', "fk": '{"q": [0.2, 0.2, 0.2]}',
            "dynamics": '{"q": [0.2, 0.2, 0.2]}'}[command]
    hostile = [(_with_number(command, n), m) for n, m in HOSTILE_NUMBERS] + HOSTILE_LINES
    stdin = "".join(f"{line}\n{good}\n" for line, _ in hostile)
    proc = subprocess.run(TALUS + ["model", command], input=stdin, check=False, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2 and proc.stderr == ""
    # Strict JSON: Python's parser would accept NaN/Infinity, so refuse them explicitly.
    out = [json.loads(line, parse_constant=lambda c: pytest.fail(f"{c} in the output"))
           for line in proc.stdout.splitlines()]
    assert len(out) == 2 * len(hostile)
    for k, (_, message) in enumerate(hostile):
        answer, after = out[2 * k], out[2 * k + 1]
        if message:
            assert message in answer["error"] and answer["line"] == 2 * k + 1
        assert len(answer.get("error", "")) < 300      # the input is never echoed back
        assert "error" not in after                      # the stream goes on
