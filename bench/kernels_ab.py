"""The compiled model kernels of this tree against those of another revision, interleaved
(A/B): did a refactor of the kernels (tidy3: one set of 3 × 3 helpers in
``rt/model/small_linalg.py`` in place of unrolled copies) cost any speed?

    .venv/bin/python bench/kernels_ab.py --base REV [--rounds 6] [--batches 200]

``REV`` is exported with ``git archive`` into a temporary directory; each round runs one
child process per tree (PYTHONPATH selects the tree; the order alternates ABBA so a drift
of the machine's load hits both alike), which times every kernel in batches of 100 calls on
fixed inputs and prints the per-call median of its batches. Printed: per kernel, the median
over rounds of each tree's per-call median (µs), its p90 over rounds, and the ratio new/base.
The first child of each tree only warms numba's cache (a cold one compiles for minutes).
On a machine shared with others, read the ratios, not the absolute figures.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PER_BATCH = 100


def _kernels() -> dict[str, Callable[[], object]]:
    """Each kernel bound to fixed inputs at a tilted, moving state (imports from the tree on
    sys.path)."""
    from protocols import reference_kernels as rk
    from rt.model import RobotModel
    from rt.model import kernels as K
    from rt.model import rigid_body as rb
    from rt.model.ik_kernels import IK_OK, IK_ROW, ik_pose

    model = RobotModel.load()
    geom, limits = model.kin.geom, model.kin.limits_array
    ti, tf = model.dyn.tree_i, model.dyn.tree_f
    n = ti.shape[0] // 3
    row = np.empty(IK_ROW)
    assert ik_pose(geom, 0.64, 0.12, -0.08, row) == IK_OK
    q, phi = row[0:3].copy(), row[3:6].copy()
    qd = np.array([0.03, -0.02, 0.01])
    stb = np.zeros(rb.STATE_SIZE)
    ms_work = np.empty(K.MODEL_STATE_WORK)
    guess = phi.copy()
    assert K.model_state(geom, limits, guess, q, qd, stb, 1e-12, 25, ms_work) >= 0
    rot, pos, sph = np.empty((3, 3)), np.empty(3), np.empty((3, 3))
    S, Sd, tw = np.empty((12, 3)), np.empty((12, 3)), np.empty((6, 3))
    tm_work = np.empty(K.TREE_MAPS_WORK)
    work = np.zeros(rb.work_size(n))
    pi = rb.unpack_tree(ti, tf)[5]
    u_acc, u_vel, out = np.array([0.5, -0.2, 0.1]), qd.copy(), np.zeros(3)
    rng = np.random.default_rng(0)
    v, a, u = rng.normal(0, 1, (n, 6)), rng.normal(0, 1, (n, 6)), rng.normal(0, 1, (n, 6))
    grad, e = np.zeros((n, rb.N_PARAMS)), np.zeros((1, rb.N_PARAMS))
    m = 200
    t = np.linspace(0.0, 2.0, m)
    path = np.zeros((m, 7))
    path[:, 0], path[:, 2], path[:, 4] = 0.2 * np.sin(2 * t), 0.4 * np.cos(2 * t), \
        -0.8 * np.sin(2 * t)
    path[:, 1], path[:, 3], path[:, 5] = 0.1 * np.sin(3 * t), 0.3 * np.cos(3 * t), \
        -0.9 * np.sin(3 * t)
    pq, pqd, pqdd, pz = np.zeros((m, 3)), np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m)
    heave = np.array([1.0, 0.72, 0.01, -0.02, 0.07])
    horiz = np.zeros(m)

    def model_state() -> object:
        guess[:] = phi
        return K.model_state(geom, limits, guess, q, qd, stb, 1e-12, 25, ms_work)

    return {
        "rnea x3 (mixed_torque)": lambda: rb.mixed_torque(ti, tf, pi, stb, u_acc, u_vel, True,
                                                          work, out),
        "param_gradient": lambda: rb.param_gradient(v, a, u, 0.5, grad, e),
        "assemble": lambda: K.assemble(geom, q, phi, rot, pos, sph),
        "tree_maps_work": lambda: K.tree_maps_work(geom, q, phi, rot, qd, S, Sd, tw, tm_work),
        "model_state": model_state,
        "path_references (200 samples)": lambda: rk.path_references(
            geom, limits, 0.63, heave, path, 1e-3, pq, pqd, pqdd, pz),
        "ankle_horizontal (200 samples)": lambda: rk.ankle_horizontal(
            geom, 0.63, np.zeros(3), np.array([0.01, 0.02, 0.07]), path[:, 0], path[:, 1],
            horiz),
    }


def child(batches: int) -> None:
    """Time every kernel of the tree on sys.path; print {name: per-call median µs}."""
    result = {}
    for name, fn in _kernels().items():
        for _ in range(PER_BATCH):
            fn()
        times = np.empty(batches)
        for b in range(batches):
            t0 = time.perf_counter_ns()
            for _ in range(PER_BATCH):
                fn()
            times[b] = (time.perf_counter_ns() - t0) / PER_BATCH / 1e3
        result[name] = float(np.median(times))
    print(json.dumps(result))


def _run(tree: Path, batches: int) -> dict[str, float]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child",
                          "--batches", str(batches)], env=env, cwd=tree, check=True,
                         capture_output=True, text=True).stdout
    return dict(json.loads(out.strip().splitlines()[-1]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", help="git revision to compare against (e.g. HEAD~2)")
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--batches", type=int, default=200)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.batches)
        return
    if not args.base:
        parser.error("--base REV is required")
    with tempfile.TemporaryDirectory(prefix="kernels_ab_") as tmp:
        base = Path(tmp)
        archive = subprocess.run(["git", "archive", args.base], cwd=ROOT, check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(base)], input=archive, check=True)
        trees = {"base": base, "new": ROOT}
        for tree in trees.values():       # warm numba's caches (not timed)
            _run(tree, 2)
        runs: dict[str, list[dict[str, float]]] = {"base": [], "new": []}
        for r in range(args.rounds):
            order = ("base", "new") if r % 2 == 0 else ("new", "base")
            for label in order:
                runs[label].append(_run(trees[label], args.batches))
    print(f"{args.rounds} rounds (ABBA), {args.batches} batches of {PER_BATCH} calls each; "
          f"base = {args.base}, new = working tree. Per-call µs: median over rounds "
          "[p90 over rounds]")
    print(f"{'kernel':32s} {'base':>16s} {'new':>16s} {'new/base':>9s}")
    for name in runs["base"][0]:
        b = np.array([x[name] for x in runs["base"]])
        n = np.array([x[name] for x in runs["new"]])
        print(f"{name:32s} {np.median(b):8.3f} [{np.percentile(b, 90):6.3f}] "
              f"{np.median(n):8.3f} [{np.percentile(n, 90):6.3f}] "
              f"{np.median(n) / np.median(b):9.3f}")


if __name__ == "__main__":
    main()
