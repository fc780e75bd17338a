"""The compiled model kernels of this tree against those of another revision, interleaved
batch by batch in one process (A/B): did a refactor of the kernels (tidy3: one set of 3 × 3
helpers in ``rt/model/small_linalg.py`` in place of unrolled copies) cost any speed?

    .venv/bin/python bench/kernels_ab.py --base REV [--rounds 200] [--calls 20]

Both versions of the kernel files (``rt/model/{small_linalg,rigid_body,kernels,ik_kernels}``,
``protocols/reference_kernels``; REV's from ``git show``, this tree's from the working
files) are copied into a temporary directory under their own module names (their imports
among each other rewritten), so the two compile and run side by side on the same inputs.
Each round times one batch of ``calls`` calls per version, in ABBA order, so a change of the
machine's load (other engineers' runs) falls on both alike; short batches (a few hundred µs)
keep a preemption to few of them. A loaded machine still inflates both, so read the ratios.
Printed per kernel: per-call µs over the rounds' batches for each version, median [p90] and
minimum (the cost without interference), and the ratios new/base of the medians and of the
minima. The first batches compile (numba, cached in the temporary directory): a warm-up,
not timed.
"""
from __future__ import annotations

import argparse
import importlib
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: (path in the tree, module stem) of the kernel files, in import order.
FILES = (("rt/model/small_linalg.py", "small_linalg"), ("rt/model/rigid_body.py", "rigid_body"),
         ("rt/model/kernels.py", "kernels"), ("rt/model/ik_kernels.py", "ik_kernels"),
         ("protocols/reference_kernels.py", "reference_kernels"))


def _source(rev: str | None, path: str) -> str | None:
    if rev is None:
        file = ROOT / path
        return file.read_text() if file.exists() else None
    done = subprocess.run(["git", "show", f"{rev}:{path}"], cwd=ROOT, check=False,
                          capture_output=True, text=True)
    return done.stdout if done.returncode == 0 else None


def _load(rev: str | None, tag: str, where: Path) -> dict[str, ModuleType]:
    """The kernel modules of ``rev`` (None: the working tree) as ``ab_<tag>_<stem>``."""
    modules = {}
    for path, stem in FILES:
        text = _source(rev, path)
        if text is None:
            continue
        text = re.sub(r"from rt\.model import (\w+) as (\w+)", rf"import ab_{tag}_\1 as \2", text)
        text = re.sub(r"from rt\.model\.(\w+) import", rf"from ab_{tag}_\1 import", text)
        (where / f"ab_{tag}_{stem}.py").write_text(text)
    sys.path.insert(0, str(where))
    for _, stem in FILES:
        if (where / f"ab_{tag}_{stem}.py").exists():
            modules[stem] = importlib.import_module(f"ab_{tag}_{stem}")
    return modules


def _calls(m: dict[str, ModuleType]) -> dict[str, Callable[[], object]]:
    """Each kernel of one version bound to fixed inputs at a tilted, moving state."""
    from rt.model import RobotModel

    K, rb, ik, rk = m["kernels"], m["rigid_body"], m["ik_kernels"], m["reference_kernels"]
    model = RobotModel.load()
    geom, limits = model.kin.geom, model.kin.limits_array
    ti, tf = model.dyn.tree_i, model.dyn.tree_f
    n = ti.shape[0] // 3
    row = np.empty(ik.IK_ROW)
    assert ik.ik_pose(geom, 0.64, 0.12, -0.08, row) == ik.IK_OK
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
    samples = 50
    t = np.linspace(0.0, 0.5, samples)
    path = np.zeros((samples, 7))
    path[:, 0], path[:, 2], path[:, 4] = (0.2 * np.sin(2 * t), 0.4 * np.cos(2 * t),
                                          -0.8 * np.sin(2 * t))
    path[:, 1], path[:, 3], path[:, 5] = (0.1 * np.sin(3 * t), 0.3 * np.cos(3 * t),
                                          -0.9 * np.sin(3 * t))
    pq, pqd, pqdd = np.zeros((samples, 3)), np.zeros((samples, 3)), np.zeros((samples, 3))
    pz, horiz = np.zeros(samples), np.zeros(samples)
    heave = np.array([1.0, 0.72, 0.01, -0.02, 0.07])
    centre = np.array([0.01, 0.02, 0.07])
    zero3 = np.zeros(3)

    def model_state() -> object:
        guess[:] = phi
        return K.model_state(geom, limits, guess, q, qd, stb, 1e-12, 25, ms_work)

    return {
        "mixed_torque (3 RNEA)": lambda: rb.mixed_torque(ti, tf, pi, stb, u_acc, u_vel, True,
                                                         work, out),
        "param_gradient": lambda: rb.param_gradient(v, a, u, 0.5, grad, e),
        "assemble": lambda: K.assemble(geom, q, phi, rot, pos, sph),
        "tree_maps_work": lambda: K.tree_maps_work(geom, q, phi, rot, qd, S, Sd, tw, tm_work),
        "model_state": model_state,
        f"path_references ({samples})": lambda: rk.path_references(
            geom, limits, 0.63, heave, path, 1e-3, pq, pqd, pqdd, pz),
        f"ankle_horizontal ({samples})": lambda: rk.ankle_horizontal(
            geom, 0.63, zero3, centre, path[:, 0], path[:, 1], horiz),
    }


def _batch(fn: Callable[[], object], calls: int) -> float:
    t0 = time.perf_counter_ns()
    for _ in range(calls):
        fn()
    return (time.perf_counter_ns() - t0) / calls / 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", required=True, help="git revision (e.g. HEAD~2)")
    parser.add_argument("--rounds", type=int, default=200)
    parser.add_argument("--calls", type=int, default=20, help="calls per batch")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="kernels_ab_") as tmp:
        versions = {"base": _calls(_load(args.base, "base", Path(tmp))),
                    "new": _calls(_load(None, "new", Path(tmp)))}
        times: dict[str, dict[str, list[float]]] = {v: {} for v in versions}
        for name in versions["new"]:
            for label in versions:                 # compile and warm, not timed
                _batch(versions[label][name], 3)
                times[label][name] = []
            for r in range(args.rounds):
                for label in (("base", "new", "new", "base") if r % 2 == 0
                              else ("new", "base", "base", "new")):
                    times[label][name].append(_batch(versions[label][name], args.calls))
    print(f"base = {args.base}, new = working tree; {args.rounds} rounds (ABBA) of batches of "
          f"{args.calls} calls. Per-call µs over batches: median [p90] min")
    print(f"{'kernel':26s} {'base':>26s} {'new':>26s} {'median n/b':>10s} {'min n/b':>8s}")
    for name in times["new"]:
        b, n = np.array(times["base"][name]), np.array(times["new"][name])
        print(f"{name:26s} {np.median(b):9.3f} [{np.percentile(b, 90):7.2f}] {b.min():7.3f} "
              f"{np.median(n):9.3f} [{np.percentile(n, 90):7.2f}] {n.min():7.3f} "
              f"{np.median(n) / np.median(b):10.3f} {n.min() / b.min():8.3f}")


if __name__ == "__main__":
    main()
