"""Real gait records replayed on the twin: the five C3D files of ``../shared/data/c3d`` (README
there), each plate a gait-replay protocol run as ``talus session run --fast`` runs it (pre-flight
on the twin, then the run), 60 % of a 75 kg patient's body weight, one stance.

Run:  .venv/bin/python bench/gait_files.py [--data DIR] [--json] [--in-process]

``--in-process`` runs each plate with ``protocols.session.run_session`` (pre-flight, then the
session on an in-process twin in simulated time, what ``talus bench force`` does) instead of
the ``talus session run --fast`` subprocess with its embedded RT process: the same twin, the
same law and supervisor, but no process answering on a wall-clock deadline, which a machine at
load 15-20 misses ("the embedded RT process did not answer within 60 s").
Prints per plate: force RMS error (% of the peak reference), offset removed, peak and least
measured force (N), peak actuator force. Twin figures: simulated time, the twin's compliant
foot (1e5 N/m heel), this machine. Target (DESIGN 10): gait RMS error ≤ 3 % of the peak; no
replay measures a force below 0 N.

Source body masses: ``functional_walk.c3d`` states its own (PROCESSING:Bodymass 60 kg); the
others do not, and the masses below are assumptions that put each stance's peak at a walking
1.0-1.2 BW (c3d.org's sample10 peaks at 398 N, sample15 at 284 N, sample01 at ~815 N).
``type3_kistler_fp1.c3d`` is loaded from its first sample to its last (no complete stance, no
unloaded stretch): an explicit window.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PATIENT_KG = 75.0


@dataclass(frozen=True)
class Case:
    file: str
    plate: int
    source_mass_kg: float | None = None      # None: the file states it
    window_s: tuple[float, float] | None = None  # None: automatic stance selection


CASES = (
    Case("type2_vicon.c3d", 0, 35.0),
    Case("type4_vicon.c3d", 0, 35.0),
    Case("type3_kistler_fp1.c3d", 0, 30.0, (0.0, 7.99)),
    Case("functional_walk.c3d", 0),
    Case("functional_walk.c3d", 1),
    Case("functional_walk.c3d", 2),
    Case("eb015pi_offset.c3d", 0, 70.0),
    Case("eb015pi_offset.c3d", 1, 70.0),
)


def data_dir(given: str | None = None) -> Path | None:
    """The real files: ``given``, else $TALUS_C3D_DIR, else ``../shared/data/c3d`` beside the
    repository; None when absent."""
    for d in (given, os.environ.get("TALUS_C3D_DIR"), REPO.parent / "shared/data/c3d"):
        if d and (Path(d) / "functional_walk.c3d").is_file():
            return Path(d)
    return None


def protocol_text(case: Case, data: Path) -> str:
    lines = ["schema_version: 1", "kind: gait_replay",
             f"name: {case.file} plate {case.plate}", "pose: {z_m: 0.63}",
             f"source: {data / case.file}", f"plate_index: {case.plate}",
             "percent_body_weight: 60", "repetitions: 1"]
    if case.source_mass_kg is not None:
        lines.append(f"source_body_weight_kg: {case.source_mass_kg:g}")
    if case.window_s is not None:
        lines.append(f"stance: {{select: explicit, start_s: {case.window_s[0]:g}, "
                     f"end_s: {case.window_s[1]:g}}}")
    return "\n".join(lines) + "\n"


def replay(case: Case, data: Path, workdir: Path) -> dict:
    """One plate through ``talus session run --fast --json`` (a subprocess, as a user runs it)."""
    import subprocess

    path = workdir / f"{Path(case.file).stem}_{case.plate}.yaml"
    path.write_text(protocol_text(case, data))
    talus = Path(sys.executable).with_name("talus")       # the console script, as installed
    proc = subprocess.run([str(talus), "session", "run", "--protocol",
                           str(path), "--patient-weight", f"{PATIENT_KG:g}", "--fast", "--json"],
                          check=False, capture_output=True, text=True, cwd=REPO, timeout=600)
    out = json.loads(proc.stdout) if proc.stdout.strip() else {"error": proc.stderr.strip()}
    out["exit_code"] = proc.returncode
    return out


def replay_in_process(case: Case, data: Path, workdir: Path) -> dict:
    """One plate through ``run_session`` (in-process twin, simulated time)."""
    from protocols.session import SessionSetup, run_session

    path = workdir / f"{Path(case.file).stem}_{case.plate}.yaml"
    path.write_text(protocol_text(case, data))
    try:
        out = run_session(SessionSetup(path, patient_weight_kg=PATIENT_KG))
    except Exception as exc:  # noqa: BLE001 - a refused plate is a row of the table
        return {"error": f"{type(exc).__name__}: {exc}", "exit_code": 2}
    out["exit_code"] = 0
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=None, help="folder of the real C3D files")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--in-process", action="store_true",
                    help="in-process twin in simulated time (no embedded RT process)")
    args = ap.parse_args()
    data = data_dir(args.data)
    if data is None:
        print("the real C3D files are not found (give --data DIR or set TALUS_C3D_DIR)",
              file=sys.stderr)
        return 2
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for case in CASES:
            s = (replay_in_process if args.in_process else replay)(case, data, Path(tmp))
            row = {"file": case.file, "plate": case.plate, "exit_code": s["exit_code"]}
            if "error" in s:
                row["error"] = s["error"]
            else:
                src = s.get("source") or {}
                row.update(completed=s["completed"], stops=len(s["stops"]),
                           rms_error_pct=s["rms_error_pct"],
                           offset_removed_n=(src.get("offset_removed_n") or {}).get("fz"),
                           offset_measured=bool(src.get("offset_measured")),
                           peak_force_n=s["peak_force_n"], least_force_n=s["min_force_n"],
                           peak_actuator_force_n=s["preflight"]["peak_actuator_force_n"],
                           source_peak_bw=src.get("source_peak_bw"))
            results.append(row)
    if args.json:
        print(json.dumps({"twin": True, "patient_kg": PATIENT_KG, "percent_body_weight": 60,
                          "replays": results}))
        return 0
    print(f"gait replay of the real C3D files on the twin (60 % of {PATIENT_KG:g} kg, fast)")
    print(f"{'file':24s} {'plate':>5s} {'RMS %pk':>8s} {'offset N':>9s} {'peak N':>8s} "
          f"{'least N':>8s} {'act. N':>7s}  outcome")
    for r in results:
        if "error" in r:
            print(f"{r['file']:24s} {r['plate']:5d}  refused: {r['error']}")
            continue
        off = f"{r['offset_removed_n']:9.2f}" if r["offset_measured"] else f"{'n/m':>9s}"
        print(f"{r['file']:24s} {r['plate']:5d} {r['rms_error_pct']:8.2f} {off} "
              f"{r['peak_force_n']:8.1f} {r['least_force_n']:8.2f} "
              f"{r['peak_actuator_force_n']:7.0f}  "
              f"{'completed' if r['completed'] else 'stopped'}, stops {r['stops']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
