"""What receiving a prepared session costs the RT process, with the GIL held (issue 14).

The pre-flight worker sends the validated generator back to the RT process. Before branch
rtloop3 it came pickled whole (the pool's default pickling): ``pickle.loads`` then copied its
reference table (2 MB for a 60 s sine) and rebuilt its robot kinematics (65 pydantic models)
with the GIL held, a stall of the loop. Now its large arrays travel in shared memory
(``protocols.rt_session.to_shared`` / ``from_shared``), the receiving side maps them, and the
kinematics go by reference (the RT process has its own). Prints median / p99 / max of each receive over ``--reps`` (ms), for a
sine of ``--seconds`` s, and the bytes that cross the pipe.

    .venv/bin/python bench/session_transfer.py [--seconds 60] [--reps 30]
"""
from __future__ import annotations

import argparse
import sys
import time
from multiprocessing.reduction import ForkingPickler
from pathlib import Path

import numpy as np

_HERE = str(Path(__file__).resolve().parent)
sys.path[:] = [p for p in sys.path if str(Path(p or ".").resolve()) != _HERE]


def main() -> int:
    from protocols.generators import make_generator
    from protocols.library import LIBRARY_DIR
    from protocols.rt_session import from_shared, protocol_document, to_shared
    from protocols.schema import validate_protocol_data
    from rt.model import RobotModel

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=int, default=60, help="sine cycles at 1 Hz")
    ap.add_argument("--reps", type=int, default=30)
    args = ap.parse_args()
    model = RobotModel.load()
    doc = protocol_document(LIBRARY_DIR / "sine_fz.yaml")
    doc.update(cycles=args.seconds, ramp_in_s=1.0, ramp_out_s=1.0)
    gen = make_generator(validate_protocol_data(doc, "bench"), dt=1e-3, kinematics=model.kin,
                         patient_weight_kg=70.0, base_dir=LIBRARY_DIR)
    if not gen.validate().ok:
        raise SystemExit("the bench's sine does not validate")
    whole = bytes(ForkingPickler.dumps(gen))
    t_whole, t_shared, c_whole, c_shared = [], [], [], []
    shared_bytes = 0
    for _ in range(args.reps):          # interleaved, so both see the same load
        # Each result is kept until its timing is taken: freeing it is not receiving it.
        t0, c0 = time.perf_counter(), time.thread_time()
        kept = ForkingPickler.loads(whole)
        t_whole.append(time.perf_counter() - t0)
        c_whole.append(time.thread_time() - c0)
        del kept
        payload = to_shared(gen, references={"kinematics": model.kin})   # worker's side
        shared_bytes = len(ForkingPickler.dumps(payload))
        t0, c0 = time.perf_counter(), time.thread_time()
        kept = from_shared(payload, {"kinematics": model.kin})
        t_shared.append(time.perf_counter() - t0)
        c_shared.append(time.thread_time() - c0)
        del kept

    def fig(xs: list[float]) -> str:
        a = np.asarray(xs) * 1e3
        return (f"median {np.median(a):7.3f}  p99 {np.percentile(a, 99):7.3f}  "
                f"max {a.max():7.3f} ms")
    print(f"sine of {args.seconds} s, {args.reps} receives each; wall time includes the time "
          "the process was descheduled (a loaded machine), CPU time does not")
    print(f"  pickled whole   {len(whole):>9d} B through the pipe")
    print(f"      wall  {fig(t_whole)}\n      CPU   {fig(c_whole)}")
    print(f"  shared memory   {shared_bytes:>9d} B through the pipe")
    print(f"      wall  {fig(t_shared)}\n      CPU   {fig(c_shared)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
