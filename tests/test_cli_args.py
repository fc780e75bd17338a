"""Hostile command-line arguments: refused by the shared types, one line, exit 2, no traceback."""
from __future__ import annotations

import argparse
import json
import math

import pytest

from rt.benchmarks.cli import CONTROLLER_NAMES
from rt.cli_args import bounded_int, finite_float, name_choice, port_number, seconds, seed
from talus import cli


def _refused(argv: list[str], capsys) -> str:
    """Run ``talus ARGV`` in process; return what it printed for a refusal (exit 2)."""
    with pytest.raises(SystemExit) as exit_info:
        cli.main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err.splitlines()[-1]


@pytest.mark.parametrize("argv, message", [
    (["bench", "loop", "--seconds", "-1"], "--seconds: must be in (0, 600] s, got -1"),
    (["bench", "loop", "--seconds", "0"], "--seconds: must be in (0, 600] s, got 0"),
    (["bench", "loop", "--seconds", "nan"], "must be a finite number"),
    (["bench", "loop", "--seconds", "inf"], "must be a finite number"),
    (["bench", "loop", "--rate", "0"], "--rate: must be in [100, 2000] Hz"),
    (["bench", "loop", "--rate", "nan"], "--rate: must be a finite number"),
    (["bench", "loop", "--rate", "1e9"], "--rate: must be in [100, 2000] Hz, got 1e9"),
    (["bench", "loop", "--controller", "paden-panjaa"], "unknown name 'paden-panjaa'"),
    (["ati", "read", "--port", "70000"], "--port: must be in [1, 65535], got 70000"),
    (["twin", "serve-ati", "--port", "-5"], "--port: must be in [0, 65535]"),
    (["twin", "step", "--seconds", "1", "--volts", "0", "0", "0", "--seed", "-1"],
     "--seed: must be in [0, 4294967295], got -1"),
    (["ati", "read", "--timeout", "nan"], "--timeout: must be a finite number"),
    (["ati", "read", "--timeout", "inf"], "--timeout: must be a finite number"),
    (["rt", "status", "--timeout", "inf"], "--timeout: must be a finite number"),
    (["ati", "read", "--samples", "9" * 5000], "must be an integer"),
    (["twin", "step", "--seconds", "1", "--volts", "0", "nan", "0"], "--volts: must be a finite"),
    (["session", "run", "--protocol", "x.yaml", "--patient-weight", "-70"], "--patient-weight"),
    (["faults", "matrix", "--only"], "expected at least one argument"),
])
def test_bad_arguments_are_refused_before_the_command_runs(argv, message, capsys):
    assert message in _refused(argv, capsys)


@pytest.mark.parametrize("argv, message", [
    (["faults", "matrix", "--only", "bogus"], "unknown fault(s) bogus; known: ati_dropout"),
    (["twin", "step", "--seconds", "0.01", "--volts", "0", "0", "0", "--env", "plate:-1"],
     "plate height -1 m is outside the tool tip's reach"),
    (["twin", "step", "--seconds", "0.01", "--volts", "0", "0", "0", "--env", "plate:5"],
     "outside the tool tip's reach"),
    (["twin", "step", "--seconds", "0.01", "--volts", "0", "0", "0", "--env", "payload:nan"],
     "mass_kg: Input should be a finite number"),
    (["twin", "step", "--seconds", "0.01", "--volts", "0", "0", "0", "--env", "payload:1e6"],
     "mass_kg: Input should be less than or equal to 500"),
    (["twin", "serve-ati", "--volts", "0", "0", "0", "--seconds", "0.1"], "needs --env"),
    (["model", "demo", "--robot", "/nonexistent/robot.yaml"], "/nonexistent/robot.yaml"),
])
def test_talus_errors_become_one_json_line_and_exit_2(argv, message, capsys):
    assert cli.main(argv) == 2
    out = capsys.readouterr()
    lines = out.out.splitlines()
    assert len(lines) == 1 and "Traceback" not in out.err
    error = json.loads(lines[0])["error"]
    assert message in error
    assert "errors.pydantic.dev" not in error and "np.float64" not in error


def test_controller_names_accept_dash_or_underscore(capsys):
    assert cli.main(["bench", "loop", "--controller", "paden-panja", "--mode", "fast",
                     "--seconds", "0.05", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["controller"] == "paden_panja"


def test_the_benchmark_lists_every_registered_position_controller():
    import rt.control.adaptive
    import rt.control.laws  # noqa: F401
    from rt.control.base import CONTROLLERS, create  # noqa: F401  (registers on first use)

    assert set(CONTROLLER_NAMES) <= set(CONTROLLERS)


@pytest.mark.parametrize("text", ["nan", "inf", "-inf", "1e400", "x", ""])
def test_finite_float_refuses_non_numbers(text):
    with pytest.raises(argparse.ArgumentTypeError):
        finite_float()(text)


def test_ranges_and_open_ends():
    positive = seconds()
    assert positive("0.5") == 0.5 and positive("3600") == 3600.0
    for bad in ("0", "-0.0", "3600.1"):
        with pytest.raises(argparse.ArgumentTypeError):
            positive(bad)
    assert seconds(allow_zero=True)("0") == 0.0
    assert finite_float(-1.0, 1.0, hi_open=True)("-1") == -1.0
    with pytest.raises(argparse.ArgumentTypeError):
        finite_float(-1.0, 1.0, hi_open=True)("1")
    assert math.isclose(finite_float()("1e300"), 1e300)


def test_integers_ports_seeds():
    assert port_number()("0") == 0 and port_number()("65535") == 65535
    for bad in ("65536", "-1", "1.5", "0x10"):
        with pytest.raises(argparse.ArgumentTypeError):
            port_number()(bad)
    with pytest.raises(argparse.ArgumentTypeError):
        port_number(allow_zero=False)("0")
    assert seed()("4294967295") == 2**32 - 1
    with pytest.raises(argparse.ArgumentTypeError):
        seed()("4294967296")
    assert bounded_int(1, 3)(" 2") == 2  # int() tolerates spaces, as a shell user expects


def test_names_where_dash_and_underscore_are_the_same():
    pick = name_choice(["pid-vs-paden", "paden_panja"])
    assert pick("PID_vs_paden") == "pid-vs-paden"        # returns the declared spelling
    assert pick("paden-panja") == "paden_panja"
    with pytest.raises(argparse.ArgumentTypeError, match="choose from paden_panja, pid-vs-paden"):
        pick("paden")


def test_messages_quote_numpy_scalars_as_plain_numbers():
    import numpy as np

    import rt  # noqa: F401  (sets the print options)

    assert f"{np.float64(0.05)!r}" == "0.05" and f"{np.int64(3)!r}" == "3"
