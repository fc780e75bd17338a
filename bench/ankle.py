"""Ankle-centred exercises: the issue's three figures (issue 17). Twin figures, this machine.

1. Ankle-centre displacement over a ±20° DF/PF and ±15° INV/EV exercise (one repetition each,
   jerk-limited, 20 deg/s, 0.5 s holds), the foot turned about the platform's centre (heave
   held) vs about the ankle with z compensation: peak and RMS over the exercise, mm, whole
   and horizontal (kinematics only: ``rt.model.ankle``; the RMS is over every 10th sample of
   the reference, holds included).
2. The same exercise run on the twin (its foot turning about the same ankle centre, shank
   springs 3e3 N/m horizontal, 1e5 N/m vertical): commanded vs achieved ankle angle (deg RMS,
   1 kHz samples of ``/robot/state``: forward kinematics of q_ref and of the measured q) and
   the shank's reaction force at the ankle centre the misalignment produces (N, peak and
   RMS; the twin's springs times the recorded ``/ankle/state`` centre displacement), about
   the platform's centre vs about the ankle.
3. Isometric holds at 10° plantarflexion and 10° dorsiflexion (5 s each) on the twin: the
   ankle torque the product reports (the twin ATI sensor's wrench moved to the ankle centre)
   vs the twin ankle's true joint torque, N·m RMS over the holds; also the torque about the
   sensor origin (what was reported before) and about an ankle centre entered 10 mm too high.
4. Isometric holds with an ankle-torque target regulated by the loop (``protocols.
   torque_hold``; plantarflexion and dorsiflexion 8 N·m, inversion and eversion 5 N·m, 5 s
   at full target each, on the twin's passive ankle, through pre-flight): per hold, the
   torque reported against the target and against the twin ankle's true torque (N·m RMS
   over the full-target stretch, 1 kHz samples).

5. The ankle centre measured by the twin camera (``patients.ankle_camera``: ArUco markers on
   both malleoli and the platform's board, one 1280 × 960 frame per foot placement, 5
   placements): error against the truth per axis (mm) and the stated 1 σ.

    .venv/bin/python bench/ankle.py [--json]

Patient: left foot, ankle centre 70 mm above the sole (150 mm above the platform's joint
plane), 10 mm in front of the platform's axis. The comfort limit is raised to 100 mm so both
variants run (the default 30 mm refuses ±20°, naming the angle).
"""
from __future__ import annotations

import argparse
import json
import math

import numpy as np

from protocols.schema import validate_protocol_data
from protocols.session import RATE_HZ, SessionSetup, build_twin_session
from rt.model import RobotModel
from rt.model.ankle import AnkleKinematics, AnkleSetup, ankle_angles, ankle_torques
from rt.references.sequencer import Phase
from rt.safety.events import Reaction
from rt.safety.limits import PatientLimits
from rt.sessions import COLUMNS

SETUP = AnkleSetup(side="left", height_above_sole_m=0.07, offset_x_m=0.01)
#: The patient's limits: the ±20° exercise ends exactly at the default ±20° ROM limit, where
#: the supervisor's cushion stops it; a prescription of ±25° (and the force limit raised past
#: the platform-centred variant's shank reaction) lets both variants run.
LIMITS = PatientLimits(roll_min_deg=-25.0, roll_max_deg=25.0, pitch_min_deg=-25.0,
                       pitch_max_deg=25.0, max_force_n=2000.0)


def exercise(centre: str) -> dict:
    return {"schema_version": 1, "kind": "ankle_rom", "name": f"rom about the {centre}",
            "pose": {"z_m": 0.63}, "sequence": ["dorsi_plantar", "inversion_eversion"],
            "amplitude_deg": {"dorsiflexion": 20.0, "plantarflexion": 20.0,
                              "inversion": 15.0, "eversion": 15.0},
            "speed_deg_s": 20.0, "hold_s": 0.5, "max_acceleration_deg_s2": 100.0,
            "max_jerk_deg_s3": 1000.0, "centre": centre, "ankle_displacement_limit_mm": 100.0}


def displacement(model: RobotModel) -> dict:
    from protocols.generators import make_generator
    out = {}
    for centre in ("platform", "ankle"):
        gen = make_generator(validate_protocol_data(exercise(centre)), kinematics=model.kin,
                             ankle=SETUP)
        report = gen.validate()
        assert report.ok, report.violations
        pose = gen.samples()["pose"][::10]
        ak = AnkleKinematics(model.kin, SETUP, list(model.description.sensor.offset_m),
                             (0.63, 0.0, 0.0))
        d = np.array([[a - s for a, s in zip(ak.centre(*p), ak.start, strict=True)]
                      for p in pose]) * 1e3
        whole, horiz = np.linalg.norm(d, axis=1), np.linalg.norm(d[:, :2], axis=1)
        out[centre] = {"peak_mm": float(whole.max()), "rms_mm": float(np.sqrt(np.mean(whole ** 2))),
                       "horizontal_peak_mm": float(horiz.max()),
                       "horizontal_rms_mm": float(np.sqrt(np.mean(horiz ** 2))),
                       "vertical_peak_mm": float(np.abs(d[:, 2]).max())}
    return out


def _drive(model: RobotModel, doc: dict, sample) -> dict:
    """Run a protocol on the in-process twin (no pre-flight: the platform-centred variant is
    what pre-flight would refuse), calling ``sample(pl, twin, row)`` every 10 ms of loop time
    until the program is back at rest or the supervisor stopped it."""
    setup = SessionSetup(protocol=validate_protocol_data(doc), ankle=SETUP,
                         patient_limits=LIMITS)
    _protocol, gen, _report, pl, tap = build_twin_session(setup, model, "fast")
    twin = pl.twin
    assert twin is not None
    t, end = 0.0, gen.duration_s + 20.0
    while t < end:
        pl.loop.run(seconds=0.01)
        t += 0.01
        if not tap.written:
            continue
        row = tap.ring[(tap.written - 1) % tap.capacity]
        sample(pl, twin, row)
        if row[COLUMNS["phase"].start] >= Phase.REST or pl.supervisor.reaction >= Reaction.SOFT_STOP:
            break
    stops = [e.cause for e in pl.events.snapshot() if e.reaction >= Reaction.SOFT_STOP]
    return {"completed": bool(row[COLUMNS["phase"].start] >= Phase.REST) and not stops,
            "stops": stops}


def on_twin(model: RobotModel) -> dict:
    out = {}
    for centre in ("platform", "ankle"):
        err: list[list[float]] = []
        force: list[float] = []

        def sample(pl, twin, row, err=err, force=force) -> None:
            if row[COLUMNS["phase"].start] != Phase.PLAY:
                return
            c = model.kin.fk(twin.plant.q, check=False)
            r = model.kin.fk(pl.reference.q_ref.data, check=False)
            err.append([math.degrees(a - b) for a, b in zip(
                ankle_angles(c.roll, c.pitch, SETUP.side),
                ankle_angles(r.roll, r.pitch, SETUP.side), strict=True)])
            force.append(float(np.linalg.norm(twin.plant.env_state[4:7])))

        run = _drive(model, exercise(centre), sample)
        e, f = np.array(err), np.array(force)
        out[centre] = {**run, "angle_error_rms_deg": {
                           "plantarflexion": float(np.sqrt(np.mean(e[:, 0] ** 2))),
                           "inversion": float(np.sqrt(np.mean(e[:, 1] ** 2)))},
                       "reaction_force_peak_n": float(f.max()),
                       "reaction_force_rms_n": float(np.sqrt(np.mean(f ** 2)))}
    return out


def isometric(model: RobotModel) -> dict:
    doc = {"schema_version": 1, "kind": "isometric_hold", "name": "holds",
           "pose": {"z_m": 0.63},
           "holds": [{"roll_deg": 0.0, "pitch_deg": 10.0, "hold_s": 5.0, "rest_s": 0.5},
                     {"roll_deg": 0.0, "pitch_deg": -10.0, "hold_s": 5.0, "rest_s": 0.5}],
           "transition_speed_deg_s": 10.0}
    high = SETUP.model_copy(update={"height_above_sole_m": SETUP.height_above_sole_m + 0.01})
    rows: list[tuple[float, float, float, float, float]] = []

    def sample(pl, twin, row) -> None:
        w = row[COLUMNS["wrench"]]
        if not np.all(np.isfinite(w)):
            return
        # The joint's moment on the foot, in the foot's (platform's) axes: y is DF/PF.
        true = float((twin.plant.rot.T @ twin.plant.env_state[1:4])[1])
        cfg = model.kin.fk(row[COLUMNS["q"]], check=False)
        rows.append((math.degrees(cfg.pitch), true, ankle_torques(tuple(w), SETUP)[0],
                     ankle_torques(tuple(w), high)[0], float(w[4])))

    run = _drive(model, doc, sample)
    a = np.array(rows)
    h = a[np.abs(np.abs(a[:, 0]) - 10.0) < 0.2]     # samples at a hold's angle
    rms = {name: float(np.sqrt(np.mean((h[:, k] - h[:, 1]) ** 2)))
           for name, k in (("about_the_ankle", 2), ("ankle_entered_10mm_high", 3),
                           ("about_the_sensor_origin", 4))}
    return {**run, "samples": len(h),
            "true_torque_nm": [float(h[:, 1].min()), float(h[:, 1].max())],
            "rms_error_nm": rms}


TORQUE_HOLDS = {"schema_version": 1, "kind": "isometric_hold", "name": "ankle-torque holds",
                "pose": {"z_m": 0.63},
                "holds": [{"roll_deg": 0.0, "pitch_deg": 0.0, "hold_s": 5.0, "rest_s": 0.5,
                           "torque": {"direction": d, "target_nm": t}}
                          for d, t in (("plantarflexion", 8.0), ("dorsiflexion", 8.0),
                                       ("inversion", 5.0), ("eversion", 5.0))],
                "transition_speed_deg_s": 10.0}


def torque_holds(model: RobotModel) -> list[dict]:
    from protocols.session import preflight
    setup = SessionSetup(protocol=validate_protocol_data(TORQUE_HOLDS), ankle=SETUP,
                         patient_limits=LIMITS)
    return preflight(setup, model)["predicted"]["ankle_torque_holds"]


def camera() -> dict:
    # Run as a script, bench/ is first on sys.path and bench/patients.py would shadow the
    # package: the repository's root goes first (as bench/patients.py does).
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from patients.ankle_camera import MalleoliRig, measure_malleoli, render_malleoli, twin_malleoli
    from rt.model.description import load_description
    offset = list(load_description().sensor.offset_m)
    rig = MalleoliRig()
    errors, sigmas = [], []
    for side, h, x, y in (("right", 0.07, 0.0, 0.0), ("left", 0.085, 0.02, -0.015),
                          ("right", 0.06, -0.01, 0.01), ("left", 0.075, 0.0, 0.02),
                          ("right", 0.09, 0.03, -0.02)):
        truth = AnkleSetup(side=side, height_above_sole_m=h, offset_x_m=x, offset_y_m=y)
        m = measure_malleoli(render_malleoli(rig, *twin_malleoli(truth, offset)), rig, side,
                             offset)
        errors.append([(m.setup.offset_x_m - x) * 1e3, (m.setup.offset_y_m - y) * 1e3,
                       (m.setup.height_above_sole_m - h) * 1e3])
        sigmas.append([v * 1e3 for v in m.centre_sigma_m])
    e, sg = np.abs(np.array(errors)), np.array(sigmas)
    return {"placements": len(errors), "max_abs_error_mm": e.max(axis=0).tolist(),
            "rms_error_mm": np.sqrt((e ** 2).mean(axis=0)).tolist(),
            "mean_sigma_mm": sg.mean(axis=0).tolist()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    model = RobotModel.load()
    result = {"rate_hz": RATE_HZ, "twin": True, "setup": SETUP.model_dump(),
              "displacement": displacement(model), "on_twin": on_twin(model),
              "isometric": isometric(model), "torque_holds": torque_holds(model),
              "camera": camera()}
    if args.json:
        print(json.dumps(result, indent=2))
        return
    d = result["displacement"]
    print("1. ankle-centre displacement, ±20° DF/PF and ±15° INV/EV (mm, kinematics)")
    for c in ("platform", "ankle"):
        x = d[c]
        print(f"   about the {c:8s}: peak {x['peak_mm']:6.1f}  RMS {x['rms_mm']:6.1f}   "
              f"(horizontal peak {x['horizontal_peak_mm']:5.1f} RMS "
              f"{x['horizontal_rms_mm']:5.1f}; vertical peak {x['vertical_peak_mm']:5.1f})")
    print("2. on the twin: commanded vs achieved ankle angle, shank reaction at the ankle")
    for c in ("platform", "ankle"):
        x = result["on_twin"][c]
        e = x["angle_error_rms_deg"]
        print(f"   about the {c:8s}: angle error RMS DF/PF {e['plantarflexion']:.3f} deg, "
              f"INV/EV {e['inversion']:.3f} deg; reaction force peak "
              f"{x['reaction_force_peak_n']:6.1f} N, RMS {x['reaction_force_rms_n']:6.1f} N"
              + ("" if x["completed"] else f"  (stopped: {x['stops']})"))
    r = result["isometric"]
    print(f"3. isometric holds ±10° (twin, {r['samples']} samples at 100 Hz): true torque "
          f"{r['true_torque_nm'][0]:.2f} .. {r['true_torque_nm'][1]:.2f} N m; RMS error of "
          "the reported torque:")
    for k, v in r["rms_error_nm"].items():
        print(f"   {k:26s} {v:.3f} N m")
    print("4. ankle-torque holds regulated on the twin's passive ankle (N m, full-target "
          "stretch, 1 kHz):")
    for h in result["torque_holds"]:
        print(f"   {h['direction']:15s} target {h['target_nm']:4.1f}: reported mean "
              f"{h['reported_mean_nm']:6.2f} (RMS {h['rms_error_to_target_nm']:.3f} from the "
              f"target), true mean {h['true_mean_nm']:6.2f}; reported vs true RMS "
              f"{h['rms_reported_vs_true_nm']:.3f}")
    c = result["camera"]
    print(f"5. ankle centre by the twin camera ({c['placements']} placements; x along the "
          "foot, y across, z height; mm): max |error| "
          + ", ".join(f"{v:.2f}" for v in c["max_abs_error_mm"]) + "; RMS "
          + ", ".join(f"{v:.2f}" for v in c["rms_error_mm"]) + "; stated σ (mean) "
          + ", ".join(f"{v:.2f}" for v in c["mean_sigma_mm"]))


if __name__ == "__main__":
    main()
