"""Where a gait replay's force error comes from, plate by plate, with the shipped force law and
with the law as it was before its preview (``--law before``: no preview, no lead, the integral
not held at the drives' limit nor through a heel strike), in one run.

Run:  .venv/bin/python bench/gait_error_sources.py [--data DIR] [--cases FILE:PLATE ...]
      [--law shipped|before|both|stiff|governor|friction] [--json]

Each plate's protocol (``bench/gait_files.py``: 60 % of a 75 kg patient) is played on the
in-process twin in simulated time (``protocols.session.build_twin_session``: the run
``bench/gait_files.py --in-process`` measures after its pre-flight; same figures). A probe reads
the twin's true contact force (before the ATI's 150 Hz filter) and the reference the law got
(after the lead and the unloading governor). Printed per plate and law (twin figures):

* RMS error, % of the peak reference (the session's figure), and the least force in contact;
* sensor: true − measured force (the ATI's filter and noise);
* governor: protocol reference − the reference the law tracked (the lead and the unloading
  governor's slowing together);
* best shift: the RMS error with the reference delayed by the shift that minimizes it (a pure
  lag would vanish there);
* the share of the error energy within ±20 ms of a drive at its limit, and in the two 100 ms
  windows that hold the most (heel strike, toe off).
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import gait_files as gf

from protocols import session as ses
from rt.engine import Array, Component
from rt.model import RobotModel
from rt.sessions import COL_CTRL_MODE, COL_FREF, COL_FZ, COL_PHASE, COLUMNS


class _Probe(Component):
    """Each cycle: the twin's true contact force (N, + pushing up) and the law's reference."""

    def __init__(self, name: str, pl_of: dict[str, Any]) -> None:
        super().__init__(name)
        self.pl_of = pl_of
        self.declare_output("unused", Array(1))
        self.rows: list[tuple[float, float]] = []

    def update(self, t: float, dt: float) -> int:
        pl = self.pl_of["pl"]
        law_ref = pl.graph.component("controller").law_force_ref_n
        self.rows.append((-float(pl.twin.plant.wrench_s[2]), float(law_ref)))
        return 0


def _before(pl: Any) -> None:
    """The law as it was: no preview, no lead (so no transient hold), no drive-limit hold, the
    integral's clamp at its old 1500 N (with no drive limit known the clamp is the gain alone,
    ``ExplicitForce.integral_limit_n``; today's gain is a 1e4 N cap under the drives'
    capacity)."""
    pl.reference.preview_steps = 0
    c = pl.graph.component("controller")
    c._beyond = lambda rate: False
    c.force_law.drive_force_limit_n = 0.0
    c.force_law.gains.integral_limit_n = 1500.0
    c.force_law._pack_gains()


def _unscheduled(pl: Any) -> None:
    """The law before the stiffness gain schedule and the angle integral (issue 15's stuck
    contact): the shipped law otherwise."""
    pl.graph.component("controller").force_law.set_gains(schedule_stiffness_n_per_m=0.0,
                                                          angle_ki_n_m_per_rad_s=0.0)


def _lagless(pl: Any) -> None:
    """The unloading governor before its lag allowance: 0.5 m/s², no lag (the law otherwise
    shipped)."""
    c = pl.graph.component("controller")
    c.unload_decel_m_s2 = 0.5
    c.unload_lag_s = 0.0


def _uncompensated(pl: Any) -> None:
    """The law without its friction compensation against stiff contacts (issue 15's
    friction-limited hold on the plate): the shipped law otherwise."""
    pl.graph.component("controller").force_law.set_gains(friction_compensation=0.0)


def run_case(case: gf.Case, data: Path, law: str, model: RobotModel) -> dict[str, Any]:
    pl_of: dict[str, Any] = {}
    probe = _Probe("probe", pl_of)
    build = ses.build_protocol_loop

    def with_probe(*args: Any, **kwargs: Any) -> Any:
        kwargs["extra_blocks"] = [*(kwargs.get("extra_blocks") or []), probe]
        pl = pl_of["pl"] = build(*args, **kwargs)
        if law == "before":
            _before(pl)
        elif law == "unscheduled":
            _unscheduled(pl)
        elif law == "lagless":
            _lagless(pl)
        elif law == "uncompensated":
            _uncompensated(pl)
        return pl

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "gait.yaml"
        path.write_text(gf.protocol_text(case, data))
        ses.build_protocol_loop = with_probe
        try:
            protocol, _gen, report, pl, tap = ses.build_twin_session(
                ses.SessionSetup(path, patient_weight_kg=gf.PATIENT_KG), model, "fast")
        finally:
            ses.build_protocol_loop = build
        ses._run(pl, tap, report.duration_s, None)
        summary = ses.summarize(pl, tap, protocol, model)
    rows = tap.ring[:tap.written]
    n = min(len(rows), len(probe.rows))
    rows, pr = rows[:n], np.asarray(probe.rows[:n])
    preload = ses.preload_of(pl)
    t = rows[:, 0]
    ref = np.maximum(rows[:, COL_FREF], preload)
    meas = -rows[:, COL_FZ]
    play = (rows[:, COL_PHASE] == 1) & (rows[:, COL_CTRL_MODE] > 0.5)
    idx = np.flatnonzero(play)
    peak = float(ref[play].max())
    e = ref - meas

    def pct(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(x[play] ** 2)) / peak * 100.0)

    shifts = [float(np.sqrt(np.mean((ref[idx - s] - meas[idx]) ** 2)) / peak * 100.0)
              for s in range(21)]
    limit = ses.RobotLimits().max_actuator_force_n
    at_limit = (np.abs(rows[:, COLUMNS["tau"]]) >= limit).any(axis=1) & play
    near = np.convolve(at_limit.astype(float), np.ones(41), "same") > 0
    energy = float(np.sum(e[play] ** 2))
    windows = np.bincount(((t[idx] - t[idx[0]]) / 0.1).astype(int), weights=e[idx] ** 2)
    top = np.argsort(windows)[::-1][:2]
    contact = idx[np.argmax(meas[idx] >= preload):]
    least = int(contact[np.argmin(meas[contact])])
    return {"file": case.file, "plate": case.plate, "law": law,
            "rms_error_pct": summary["rms_error_pct"], "least_force_n": float(meas[least]),
            "sensor_pct": pct(pr[:, 0] - meas),
            "governor_pct": pct(ref - np.maximum(pr[:, 1], preload)),
            "best_shift_ms": int(np.argmin(shifts)), "best_shift_pct": min(shifts),
            "near_limit_share": float(np.sum(e[near & play] ** 2)) / energy,
            "top_windows": [{"from_s": float(t[idx[0]] + 0.1 * k),
                             "share": float(windows[k]) / energy} for k in top]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=None, help="folder of the real C3D files")
    ap.add_argument("--cases", nargs="*", default=None, help="FILE:PLATE (default: every plate)")
    ap.add_argument("--law", choices=("shipped", "before", "unscheduled", "lagless",
                                      "uncompensated", "both", "stiff", "governor", "friction"),
                    default="both",
                    help="both: before and shipped; stiff: unscheduled (no stiffness gain "
                         "schedule, no angle integral) and shipped; governor: lagless (the "
                         "unloading governor at 0.5 m/s² without its lag allowance) and "
                         "shipped; friction: uncompensated (no friction compensation against "
                         "stiff contacts) and shipped")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    data = gf.data_dir(args.data)
    if data is None:
        print("the real C3D files are not found (give --data DIR or set TALUS_C3D_DIR)",
              file=sys.stderr)
        return 2
    cases = list(gf.CASES)
    if args.cases:
        wanted = {(c.split(":")[0], int(c.split(":")[1])) for c in args.cases}
        cases = [c for c in cases if (c.file, c.plate) in wanted]
    laws = {"both": ("before", "shipped"),
            "stiff": ("unscheduled", "shipped"),
            "governor": ("lagless", "shipped"),
            "friction": ("uncompensated", "shipped")}.get(args.law, (args.law,))
    model = RobotModel.load()
    out = [run_case(c, data, law, model) for c in cases for law in laws]
    if args.json:
        print(json.dumps({"twin": True, "rows": out}))
        return 0
    print("gait replay error sources on the twin (twin figures, simulated time)")
    print(f"{'file':22s} {'pl':>2s} {'law':11s} {'RMS %':>6s} {'least N':>7s} {'sensor':>6s} "
          f"{'gov.':>5s} {'shift':>9s} {'@limit':>6s}  top windows")
    for r in out:
        tops = ", ".join(f"{w['from_s']:.1f} s {w['share'] * 100:.0f} %"
                         for w in r["top_windows"])
        print(f"{r['file']:22s} {r['plate']:2d} {r['law']:11s} {r['rms_error_pct']:6.3f} "
              f"{r['least_force_n']:7.2f} {r['sensor_pct']:6.2f} {r['governor_pct']:5.2f} "
              f"{r['best_shift_ms']:2d} ms {r['best_shift_pct']:4.2f} "
              f"{r['near_limit_share'] * 100:5.0f}%  {tops}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
