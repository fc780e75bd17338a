"""The twin's discretisation error: the golden closed-loop runs (``tests/test_twin_golden.py``:
the realistic twin, a PD sine on each slider through the device backends, the drives off for
60 ms so the brakes engage) at the twin's physics rate against the same run at ``--factor``
times the substeps (the reference), per environment (twin figures).

Run:  PYTHONPATH=<tree> .venv/bin/python bench/twin_accuracy.py [--rate 5000] [--factor 10]
      [--json]

Run it on two trees (``PYTHONPATH``) to compare a change of the substep's arithmetic with the
code before it: a change that is only round-off leaves every error where it was; the golden
file pins the rows themselves bit for bit. Per environment, over the run's rows (every
25 ms): the largest |Δ| of the slider positions q (µm), of the motor positions at the slider
x_m (µm), of the slider velocities q̇ (mm/s) and of the ATI's force as read (N), and the
encoder counts that differ (20 µm each). ``--golden``: also this tree's run at 5 kHz against
the golden file's rows (what a change moved, in the same units).
"""
from __future__ import annotations

import argparse
import functools
import importlib.util
import json
from pathlib import Path

from rt.twin import kernels
from rt.twin.twin import Twin

GOLDEN_TEST = Path(__file__).resolve().parent.parent / "tests" / "test_twin_golden.py"
#: Golden row columns: t, 3 counts, 3 positions q, the ATI read (11), then the plant's S.
_COUNTS, _ATI, _S = 1, 7, 18


def _golden_module():
    spec = importlib.util.spec_from_file_location("twin_golden", GOLDEN_TEST)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def rows(module, env: str, rate_hz: float) -> list[list[float]]:
    """The golden run of ``env`` with the twin's physics at ``rate_hz``, as floats."""
    module.Twin = functools.partial(Twin, physics_rate_hz=rate_hz)
    try:
        return [[float.fromhex(v) for v in row] for row in module.trajectory(env)]
    finally:
        module.Twin = Twin


def errors(run: list[list[float]], ref: list[list[float]]) -> dict[str, float]:
    def worst(col: int, scale: float) -> float:
        return max(max(abs(a[col + i] - b[col + i]) for i in range(3)) for a, b in
                   zip(run, ref)) * scale
    return {"q_um": worst(_S + kernels.S_Q, 1e6), "xm_um": worst(_S + kernels.S_XM, 1e6),
            "qd_mm_s": worst(_S + kernels.S_QD, 1e3), "force_n": worst(_ATI, 1.0),
            "counts_differing": sum(a[_COUNTS + i] != b[_COUNTS + i] for a, b in zip(run, ref)
                                    for i in range(3))}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rate", type=float, default=5000.0, help="the twin's rate (Hz)")
    parser.add_argument("--factor", type=int, default=10,
                        help="the reference's substeps per substep")
    parser.add_argument("--golden", action="store_true",
                        help="also compare this tree's 5 kHz runs with the golden file")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.factor < 2:
        parser.error("--factor must be at least 2")
    module = _golden_module()
    out = {}
    golden = json.loads(module.GOLDEN.read_text()) if args.golden else {}
    for env in module.ENVS:
        run = rows(module, env, args.rate)
        out[env] = errors(run, rows(module, env, args.rate * args.factor))
        if golden:
            ref = [[float.fromhex(v) for v in row] for row in golden[env]]
            out[env + " vs golden"] = errors(run, ref)
    if args.json:
        print(json.dumps(out))
        return
    print(f"golden runs at {args.rate:g} Hz against {args.rate * args.factor:g} Hz (largest "
          "|difference| over the rows)")
    for env, e in out.items():
        print(f"  {env:<11} q {e['q_um']:.4g} µm, x_m {e['xm_um']:.4g} µm, q̇ "
              f"{e['qd_mm_s']:.4g} mm/s, force {e['force_n']:.4g} N, "
              f"{e['counts_differing']} encoder counts differ")


if __name__ == "__main__":
    main()
