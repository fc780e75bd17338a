"""``talus bench force``: force tracking on the twin through the whole session path (protocol
generator → hybrid explicit-force law → supervisor → drives), against the patient's compliant
foot: sine Fz 300 ± 100 N at 0.5, 1 and 2 Hz (RMS error % of amplitude over the full-amplitude
cycles) and gait replay at real speed (RMS error % of the peak force). Twin figures.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

SINE = """schema_version: 1
kind: sine_fz
name: bench sine {f} Hz
description: bench
pose: {{z_m: 0.63, roll_deg: 0.0, pitch_deg: 0.0}}
mean_n: 300.0
amplitude_n: 100.0
frequency_hz: {f}
cycles: {cycles}
ramp_in_s: 2.0
ramp_out_s: 2.0
"""


def _sine_error(freq: float, model) -> float:
    from protocols.session import SessionSetup, _run, build_twin_session
    from rt.sessions import COL_FREF, COL_FZ, COL_PHASE

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sine.yaml"
        path.write_text(SINE.format(f=freq, cycles=max(4, round(10 * freq))))
        _protocol, _gen, report, pl, tap = build_twin_session(SessionSetup(path), model, "fast")
        _run(pl, tap, report.duration_s, None)
    rows = tap.ring[:tap.written]
    play = rows[:, COL_PHASE] == 1
    t = rows[:, 0]
    t0 = t[play][0]
    full = play & (t >= t0 + 2.0) & (t < t0 + report.duration_s - 2.0)
    e = (rows[:, COL_FREF] - (-rows[:, COL_FZ]))[full]
    return float(np.sqrt(np.mean(e ** 2)) / 100.0 * 100.0)


def _gait_error(model) -> float:
    from protocols.library import list_library
    from protocols.session import SessionSetup, run_session

    path = next(p for p in list_library() if p.name == "gait_replay.yaml")
    summary = run_session(SessionSetup(path, patient_weight_kg=75.0), None, model=model)
    return float(summary["rms_error_pct"])


def run_force_benchmark(model=None) -> dict:
    """The figures on the default (realistic) twin, the controllers using ``model`` (default:
    the nominal robot)."""
    from rt.model import RobotModel

    model = model or RobotModel.load()
    return {"twin": True, "environment": "compliant foot (1e5 N/m)",
            "robot": model.description.name,
            "sine_rms_pct": {"0.5": _sine_error(0.5, model), "1": _sine_error(1.0, model),
                             "2": _sine_error(2.0, model)},
            "gait_rms_pct_of_peak": _gait_error(model)}




def register(commands) -> None:
    from rt.model.robot_option import add_robot_option

    """``talus bench force`` (composed into the bench group by the entry point)."""
    p = commands.add_parser("force", help="force tracking on the twin: sine Fz and gait replay")
    p.add_argument("--json", action="store_true")
    add_robot_option(p)
    p.set_defaults(func=_force)


def _force(args) -> int:
    import json

    from rt.model import RobotModel

    r = run_force_benchmark(model=RobotModel.load(args.robot))
    if args.json:
        print(json.dumps(r))
    else:
        print(f"force tracking on the twin ({r['environment']})")
        for f, v in r["sine_rms_pct"].items():
            print(f"  sine Fz 300 ± 100 N at {f} Hz: RMS error {v:.2f} % of amplitude")
        print(f"  gait replay at real speed: RMS error {r['gait_rms_pct_of_peak']:.2f} % of peak")
    return 0
