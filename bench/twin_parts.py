"""Where the twin's 1 ms period goes (issue 16): its parts timed on states captured from a
pre-flight (twin figures).

Run:  PYTHONPATH=<tree> .venv/bin/python bench/twin_parts.py [--protocol sine60] [--every 97]
      [--reps 20] [--json]

The pre-flight of ``--protocol`` (``bench/preflight.py``'s protocols) runs through the loop
(``TALUS_PREFLIGHT_DRIVER=0``) and every ``--every``-th cycle the twin's whole state is
copied (its block, the encoder card's, the ATI's packed array and random block, the DAC
codes). Compiled loops then run each part on every captured state, ``--reps`` times, with the
state restored before each call, and report the median over 5 rounds of µs per call (this
thread's CPU time), the restore's own cost taken off:

* ``period n=5`` / ``period n=1``: ``kernels.period_block`` with the pre-flight's 5 substeps
  and with one: their difference / 4 is a substep, the rest the period's fixed part
  (amplifier input, brakes, heat, sensors, encoder card, ATI sample);
* a substep's parts at the captured state (q moved one substep ahead, so the FK's Newton
  starts where it does in a substep): ``fk_solve``, ``mass_and_bias_work``, it and
  ``environment_wrench``, ``friction_force`` (the slider's share with its Coulomb part),
  ``acceleration`` (all of those, end stops and the solve) and ``mass_and_bias_work`` with
  ``coulomb_step`` (the implicit Coulomb friction).

Compare two trees by running it with each ``PYTHONPATH``, alternated (a loaded machine: ratios
within one run only).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time

import numpy as np
from numba import njit

from rt.model.kernels import fk_solve
from rt.twin import kernels as K
from rt.twin import physics as ph

#: Parts of :func:`_part` (index = its ``part`` argument).
PARTS = ("fk_solve", "mass_and_bias", "mass_and_bias+environment", "friction_force",
         "acceleration", "mass_and_bias+coulomb_step")
_NOTHING = len(PARTS)


def capture(protocol: str, every: int) -> dict[str, np.ndarray]:
    """The twin's state every ``every`` cycles of ``protocol``'s pre-flight (70 kg)."""
    import preflight as pb  # bench/preflight.py, beside this file

    from protocols import session
    from rt.components.twin_step import TwinStep
    from rt.model import RobotModel

    states: dict[str, list] = {"B": [], "port": [], "codes": [], "ati": []}
    block: list[np.ndarray] = []
    update = TwinStep.update
    count = [0]

    def snap(self, t: float, dt: float) -> int:
        count[0] += 1
        if count[0] % every == 0:
            tw = self.twin
            card = 0 if tw.card_enabled[0] else (1 if tw.card_enabled[1] else -1)
            states["B"].append(tw.plant.B.copy())
            states["port"].append(tw.encoder_port._st.copy())
            states["codes"].append((tw.dac_libs[card].codes3 if card >= 0 else tw._codes).copy())
            states["ati"].append(tw.ati._packed.copy())
            if not block:
                block.append(tw.ati._state.block.copy())
        return update(self, t, dt)

    old = os.environ.get("TALUS_PREFLIGHT_DRIVER")
    os.environ["TALUS_PREFLIGHT_DRIVER"] = "0"
    TwinStep.update = snap                                     # type: ignore[method-assign]
    try:
        setup = session.SessionSetup(protocol=pb.protocols()[protocol], base_dir=pb.LIBRARY,
                                     patient_weight_kg=pb.PATIENT_KG)
        session.preflight(setup, RobotModel.load())
    finally:
        TwinStep.update = update                               # type: ignore[method-assign]
        if old is None:
            del os.environ["TALUS_PREFLIGHT_DRIVER"]
        else:
            os.environ["TALUS_PREFLIGHT_DRIVER"] = old
    out = {k: np.array(v) for k, v in states.items()}
    out["block"] = block[0]
    return out


@njit
def _restore(Bs, ports, atis, B, port, ati, reps):
    acc = 0.0
    for _ in range(reps):
        for j in range(Bs.shape[0]):
            B[:] = Bs[j]
            port[:] = ports[j]
            ati[:] = atis[j]
            acc += B[0]
    return acc


@njit
def _period(Bs, ports, codes, atis, B, port, ati, block, n, reps):
    acc = 0.0
    for _ in range(reps):
        for j in range(Bs.shape[0]):
            B[:] = Bs[j]
            port[:] = ports[j]
            ati[:] = atis[j]
            acc += K.period_block(B, port, codes[j], ati, block, 1e-3, n, j % block.shape[0],
                                  1e-3)
    return acc


@njit
def _part(Bs, B, part, reps):
    acc = 0.0
    rot = np.empty((3, 3))
    pos = np.empty(3)
    s_map = np.empty((12, 3))
    sd = np.empty((12, 3))
    tw = np.empty((6, 3))
    m = np.empty((3, 3))
    hb = np.empty(3)
    te = np.empty(3)
    fr = np.empty(3)
    work = np.empty(ph.WORK_SIZE)
    ws = np.empty(6)
    qdd = np.zeros(3)
    q = np.empty(3)
    qd = np.empty(3)
    phi = np.empty(3)
    force = np.zeros(3)
    for _ in range(reps):
        for j in range(Bs.shape[0]):
            B[:] = Bs[j]
            S = B[K.B_S:K.B_S + K.S_SIZE]
            P = B[K.B_P:K.B_P + K.P_SIZE]
            geom = B[K.B_GEOM:K.B_GEOM + K.GEOM_SIZE]
            env = B[K.B_ENV:K.B_ENV + ph.ENV_SIZE]
            bodies = P[K.P_BODIES:K.P_BODIES + ph.N_BODY_PARAMS]
            fric = P[K.P_FRICTION_SLIDER:K.P_FRICTION_SLIDER + ph.N_FRICTION]
            es = S[K.S_ENV_STATE:K.S_ENV_STATE + ph.ENV_STATE_SIZE]
            for i in range(3):
                q[i] = S[K.S_Q + i] + 2e-4 * S[K.S_QD + i]
                qd[i] = S[K.S_QD + i]
                phi[i] = S[K.S_PHI + i]
            if part == 0:
                acc += fk_solve(geom, q, phi, 1e-12, 25)
            elif part == 1 or part == 2 or part == 5:
                ph.mass_and_bias_work(geom, bodies, q, qd, phi, rot, pos, s_map, sd, tw, m, hb,
                                      work)
                if part == 2:
                    ph.environment_wrench(env, bodies, rot, pos, tw, qd, es, ws, te)
                elif part == 5:
                    ph.coulomb_step(m, qd, qdd, 2e-4, ph.coulomb_level(q[0], qd[0], fric, 0),
                                    ph.coulomb_level(q[1], qd[1], fric, 1),
                                    ph.coulomb_level(q[2], qd[2], fric, 2))
                acc += hb[0] + te[0] + qd[0]
            elif part == 3:
                ph.friction_force(q, qd, fric, fr)
                acc += fr[0]
            elif part == 4:
                acc += ph.acceleration(geom, bodies, fric, env, q, qd, phi, force, es, qdd, ws,
                                       rot, pos, s_map, sd, tw, m, hb, te, fr, work)
    return acc


def _us(fn, args: tuple, reps: int, calls: int) -> float:
    """Median over 5 rounds of µs (thread CPU) per call of ``fn(*args, reps)``."""
    fn(*args, 1)
    rounds = []
    for _ in range(5):
        c = time.thread_time()
        fn(*args, reps)
        rounds.append(time.thread_time() - c)
    return statistics.median(rounds) / (reps * calls) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--protocol", default="sine60", help="sine60, rom or gait")
    parser.add_argument("--every", type=int, default=97)
    parser.add_argument("--reps", type=int, default=20)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    if args.every < 1 or args.reps < 1:
        parser.error("--every and --reps must be at least 1")
    st = capture(args.protocol, args.every)
    Bs, ports, codes, atis, block = st["B"], st["port"], st["codes"], st["ati"], st["block"]
    B, port, ati = Bs[0].copy(), ports[0].copy(), atis[0].copy()
    n = Bs.shape[0]
    restore = _us(_restore, (Bs, ports, atis, B, port, ati), args.reps, n)
    out = {"states": n, "restore_us": restore}
    for substeps in (5, 1):
        out[f"period n={substeps}"] = _us(_period, (Bs, ports, codes, atis, B, port, ati, block,
                                                   substeps), args.reps, n) - restore
    out["substep"] = (out["period n=5"] - out["period n=1"]) / 4.0
    out["period fixed part"] = out["period n=1"] - out["substep"]
    nothing = _us(_part, (Bs, B, _NOTHING), args.reps, n)
    for k, name in enumerate(PARTS):
        out[name] = _us(_part, (Bs, B, k), args.reps, n) - nothing
    if args.json:
        print(json.dumps(out))
        return
    print(f"the twin's period on {n} states of a {args.protocol} pre-flight, µs per call "
          "(thread CPU, median of 5 rounds; twin figures)")
    for key, value in out.items():
        if key != "states":
            print(f"  {key:<28} {value:8.3f}")


if __name__ == "__main__":
    main()
