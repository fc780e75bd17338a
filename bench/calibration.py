"""Force-plate calibration figures on the twin plate (issue 12).

Run:  .venv/bin/python bench/calibration.py [--campaign DIR | --out DIR] [--backend twin|direct]
      [--plan PLAN.yaml | --shear] [--json]

Runs the default campaign (plan → run → fit) on the twin — by default the robot twin pressing
the twin plate through its ATI under force control; ``--backend direct`` feeds the plate the
commanded load without the robot (seconds instead of minutes) — or reuses a campaign folder
made by ``talus calibrate demo|run``. ``--plan`` runs another plan; ``--shear`` adds to the
default plan the four shear pushes of :data:`SHEAR_PUSHES` (roll ±1.5°, pitch ±1.5° under
600 N: shear along both plate axes, both signs), to measure what they identify. Prints, on the held-out sites and trials (never fitted):

* ``cop_rms_mm``, ``cop_max_mm``, ``force_pct_fs`` (max over Fx, Fy, Fz), each
  ``{before, linear, nonlinear}``;
* recovery of the twin plate's true matrix entry by entry (the fitted matrix against the
  matrix an ideal linear calibration of the truth gives, in % of the row's full scale at the
  channel's full range), identified entries only;
* the origin offset: the truth's, and the COP bias at the centre before and after;
* the campaign's length in robot time and the processing (fit) time.

Twin figures: measured on the twin plate (the truth in ``calibration.twin_plate``), this
machine; the target (DESIGN §10, Cappello 2011) is COP ≤ 0.5 mm RMS and force ≤ 0.5 % FS.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

# This file is named like the package it measures: run as a script, its own folder comes
# first on sys.path and would shadow the package.
_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path = [p for p in sys.path if os.path.abspath(p or os.curdir) != _HERE]

import numpy as np

from calibration import campaign, metrics
from calibration.plan import ShearPush, default_plan, load_plan
from calibration.plate import TWIN_PLATE_FILE, cop_F, load_plate

#: ``--shear``: shear along +y/-y (roll) and +x/-x (pitch) at the centre, at the default
#: ShearPush's load and (slow) tilt ramp.
SHEAR_PUSHES = (ShearPush(roll_deg=1.5), ShearPush(roll_deg=-1.5), ShearPush(pitch_deg=1.5),
                ShearPush(pitch_deg=-1.5))


def figures(folder: Path) -> dict:
    p = campaign.process(folder)
    record = campaign.build_record(folder, p, metrics.Thresholds(), campaign.ReferenceSensor(),
                                   "bench")
    m = record["metrics"]
    stages = ("before", "linear", "nonlinear")
    out: dict = {
        "cop_rms_mm": {k: m[k]["cop_rms_mm"] for k in stages},
        "cop_max_mm": {k: m[k]["cop_max_mm"] for k in stages},
        "force_pct_fs": {k: max(m[k]["force_pct_fs"][:3]) for k in stages},
        "moment_pct_fs": {k: max(m[k]["force_pct_fs"][3:]) for k in stages},
        "crosstalk_pct": {k: m[k]["crosstalk_pct"] for k in stages},
        "hysteresis_pct_fs": {k: m[k]["hysteresis_pct_fs"] for k in stages},
        "verdict": record["verdict"],
        "nonlinear_degree": p.nonlinear.degree,
        "robot_time_s": p.index.get("robot_time_s"),
        "processing_time_s": round(p.processing_time_s, 2),
        "held_out_samples": len(p.held),
        "not_identified_entries": [
            f"{r}<-{c}" for i, r in enumerate(record["matrix"]["row_order"])
            for j, c in enumerate(record["matrix"]["channel_order"])
            if not record["matrix"]["identified"][i][j]],
        "uncertainty_k2": {"force_n": record["uncertainty"]["force_n"][:3],
                           "cop_mm": record["uncertainty"]["cop_mm"]},
    }
    truth_path = folder / campaign.TRUTH_FILE
    if truth_path.is_file():
        truth = json.loads(truth_path.read_text())
        plate = p.plate
        expected = np.array(truth["C_expected"])
        fs = plate.full_scale()[:, None] / plate.channel_ranges()[None, :]
        err = (p.linear.C - expected) / fs * 100.0
        ident = p.linear.identified
        out["matrix_recovery_pct_fs"] = {
            "max_identified": float(np.max(np.abs(err[ident]))) if ident.any() else None,
            "per_entry": np.where(ident, np.round(err, 3), None).tolist(),
            "not_identified": int((~ident).sum())}
        offset = (np.array(truth["origin_true_m"]) - np.array(plate.origin_m)) * 1e3
        centre = min(range(len(p.all_samples.site_names)),
                     key=lambda k: _site_distance(p, k))
        m_c = (p.all_samples.site == centre) & (p.all_samples.w_ref[:, 2] > 150.0)
        bias = {}
        for stage, w in p.stages_all.items():
            cop, _ = cop_F(w[m_c], plate.origin_m)
            bias[stage] = ((np.mean(cop, axis=0) - np.mean(p.all_samples.p_ref[m_c, :2], axis=0))
                           * 1e3).round(3).tolist()
        out["origin_offset_mm"] = {"true": offset.round(3).tolist(),
                                   "cop_bias_at_centre": bias,
                                   "note": "a moment crosstalk from Fz acts like an origin "
                                           "offset; the bias at the centre is their sum"}
    return out


def _site_distance(p: campaign.Processed, k: int) -> float:
    name = p.all_samples.site_names[k]
    xy = next(e["site_xy_m"] for e in p.index["trials"] if e["site"] == name)
    return float(np.hypot(*xy))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--campaign", help="reuse this campaign folder")
    ap.add_argument("--out", help="new folder for the campaign (default: a temporary one)")
    ap.add_argument("--backend", choices=("twin", "direct"), default="twin")
    ap.add_argument("--seed", type=int, default=12)
    ap.add_argument("--plan", help="plan file (default: the default plan)")
    ap.add_argument("--shear", action="store_true",
                    help="the default plan plus the shear pushes of SHEAR_PUSHES")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if args.plan and args.shear:
        ap.error("--plan and --shear exclude each other")
    if args.campaign:
        folder = Path(args.campaign)
        wall = None
    else:
        from calibration.twin_runner import make_runner

        folder = Path(args.out or tempfile.mkdtemp(prefix="talus-cal-")) / "campaign"
        plate = load_plate(TWIN_PLATE_FILE)
        plan = (load_plan(args.plan) if args.plan
                else default_plan(shear=list(SHEAR_PUSHES)) if args.shear else default_plan())
        runner, truth = make_runner(args.backend, plate, args.seed, plan.registration,
                                    plan.level_sigma_rad())
        t0 = time.perf_counter()
        campaign.run_campaign(plan, TWIN_PLATE_FILE, runner, folder, truth)
        wall = time.perf_counter() - t0
    out = {"campaign": str(folder), **figures(folder)}
    if wall is not None:
        out["run_wall_time_s"] = round(wall, 1)
        out["backend"] = args.backend
        out["plan"] = args.plan or ("default + shear" if args.shear else "default")
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"campaign {folder}  robot time {out['robot_time_s']:.0f} s  "
          f"processing {out['processing_time_s']:.1f} s  (twin figures, held-out points)")
    for key in ("cop_rms_mm", "cop_max_mm", "force_pct_fs", "moment_pct_fs", "crosstalk_pct"):
        v = out[key]
        print(f"  {key:<15} before {v['before']:8.3f}   linear {v['linear']:8.3f}   "
              f"nonlinear {v['nonlinear']:8.3f}")
    if "matrix_recovery_pct_fs" in out:
        r = out["matrix_recovery_pct_fs"]
        print(f"  matrix: max |fitted - true| over identified entries {r['max_identified']:.3f} "
              f"% FS; {r['not_identified']} entries not identified")
        o = out["origin_offset_mm"]
        print(f"  origin offset (mm): true {o['true']}; COP bias at the centre "
              f"{o['cop_bias_at_centre']}")
    print(f"  verdict {out['verdict']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
