"""The force-mode approach bounded by the contact it expects (issue 15): from a force-mode
entry until the first touch (F > ``CONTACT_TOUCH_N``) the explicit-force law closes the gap no
faster than v_a = margin / √(k m) (``rt.control.kernels.approach_speed``: the impact of a mass
m at v onto a spring k peaks v √(k m) above the reference), k the remembered contact's
stiffness or the gains' guess. The bound is latched off after that touch until the next entry:
within a hold the sensor unloading (an overload sinking the platform away from the foot) must
meet the law unbounded.

400 N pushes on the twin's calibration plate (2e6 N/m through the tool tip, the tip 0.5 mm
above it), the loop of ``tests/test_force_contact_memory.py``. Fast mode: deterministic.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from test_force_contact_memory import MODEL, POSE, _plate_loop, _push

from rt.control import kernels as ck
from rt.control.force import ExplicitForce, ForceReference
from rt.errors import ConfigurationError

CONTACT_N = 5.0         # the tip touches: a few N above the ATI's noise (σ 0.25 N)


def _run_push(margin_n: float | None = None, pushes: int = 1, memory: bool = False):
    """Per push: (max ż before contact (m/s), the approach's bound v_a (m/s), ms from the
    force-mode entry to contact, max |τ| (N) over the 0.2 s after the first loaded cycle,
    force-mode cycles whose latch (``FS_TOUCHED``) disagreed with "F > ``CONTACT_TOUCH_N``
    since the entry", cycles after the touch with F ≤ ``CONTACT_TOUCH_N`` (a rebound))."""
    pl = _plate_loop()
    try:
        ctl = pl.graph.component("controller")
        ctl.remember_contact = memory
        law = ctl.force_law
        if margin_n is not None:
            law.set_gains(approach_force_margin_n=margin_n)
        ref = pl.reference
        out = []
        for _ in range(pushes):
            ref.request(_push())
            entry, contact, loaded, vmax, v_a, taus = None, None, None, 0.0, math.nan, []
            touched, wrong, rebound = False, 0, 0
            for i in range(4000):
                pl.loop.run(seconds=0.001)
                assert pl.supervisor.reaction < 2, pl.events.snapshot()
                if ref.ctrl_mode.data[0] < 0.5:
                    if entry is not None and not ref.busy:
                        break
                    continue
                if entry is None:
                    entry = i
                    st = ctl.state_in.data
                    m_z = law.axis_inertia * float(np.sum(st.inverse_jacobian()[:, 0] ** 2))
                    v_a = ck.approach_speed.py_func(law.gains.approach_force_margin_n,
                                                    float(law._fs[ck.FS_K_APPROACH]), m_z)
                f = -pl.graph.output("force.wrench")[2]
                st = ctl.state_in.data
                rebound += touched and not f > ck.CONTACT_TOUCH_N
                touched = touched or f > ck.CONTACT_TOUCH_N
                wrong += (law._fs[ck.FS_TOUCHED] == 1.0) != touched
                if contact is None:
                    if f > CONTACT_N:
                        contact = i - entry
                    else:
                        vmax = max(vmax, float(st.S[8] @ st.qd))
                if loaded is None and f > ck.CONTACT_LOADED_N:
                    loaded = i
                if loaded is not None and i - loaded < 200:
                    taus.append(float(np.max(np.abs(pl.graph.output("controller.tau")))))
            out.append((vmax, v_a, contact, max(taus), wrong, rebound))
        return out, law
    finally:
        pl.graph.stop()


def _slack(law: ExplicitForce, v_a: float) -> float:
    """The approach's bound as the twin can keep it: v_a, plus preload / D (the law never
    commands less than the preload, 0.5 mm/s), plus 5 % of v_a (the bound acts through the
    damping D on the measured ż one cycle late, with the model's friction feedforward at
    ż_ff, not the twin's friction at ż)."""
    g = law.gains
    return 1.05 * v_a + g.preload_n / g.damping_n_s_per_m


def test_the_approach_speed_is_the_impact_margin_over_sqrt_k_m() -> None:
    """5.7 mm/s for 200 N onto the plate (2e6 N/m, ≈ 616 kg the drives reflect in z); 25 mm/s
    onto the guess's 1e5 N/m: a stiffer contact is met slower."""
    v = ck.approach_speed.py_func(200.0, 2e6, 616.0)
    assert v == pytest.approx(200.0 / math.sqrt(2e6 * 616.0))
    assert ck.approach_speed.py_func(200.0, 2e6, 616.0) == pytest.approx(5.70e-3, rel=1e-3)
    assert ck.approach_speed(200.0, 1e5, 616.0) == ck.approach_speed.py_func(200.0, 1e5, 616.0)


def test_the_bounded_approach_does_not_saturate_the_drives() -> None:
    """Default margin (200 N) on the guess (1e5 N/m): the gap is closed at ≤ v_a (``_slack``)
    and the impact's first 0.2 s stay under
    the drives' limit (2036 N). Unbounded (margin 0, the law before) the tip arrives at
    ≈ 45 mm/s, well above v_a, and the braking asks > 2.5 kN of a drive."""
    ((vmax, v_a, contact, tau, _, _),), law = _run_push()
    assert 0.02 < v_a < 0.03
    assert 0.5 * v_a < vmax <= _slack(law, v_a)
    assert contact <= 60                   # ms (unbounded: 31; 0.5 mm at 25 mm/s is 20 ms)
    assert tau < law.drive_force_limit_n
    ((vmax0, _, contact0, tau0, _, _),), _ = _run_push(margin_n=0.0)
    assert vmax0 > 1.5 * v_a
    assert tau0 > law.drive_force_limit_n
    assert contact0 < contact


def test_a_remembered_contact_is_approached_at_its_own_bound() -> None:
    """With memory on the second push's approach is bounded for push 1's learnt stiffness
    (≥ 1e6 N/m: v_a ≤ 8 mm/s) while its gains are still the guess's, so its gap takes longer
    and its impact stays well under the drives' limit."""
    (p1, p2), law = _run_push(pushes=2, memory=True)
    assert p2[1] < 0.4 * p1[1] and p2[1] < 8e-3
    assert p2[0] <= _slack(law, p2[1])
    assert p2[2] > p1[2]
    assert p2[3] < 0.5 * law.drive_force_limit_n


@pytest.mark.parametrize("bad", [-1.0, 5001.0, math.nan])
def test_a_bad_margin_is_refused_and_changes_nothing(bad: float) -> None:

    law = ExplicitForce(MODEL, compiled=False)
    fg = law._fg.copy()
    with pytest.raises(ConfigurationError, match="approach_force_margin_n"):
        law.set_gains(approach_force_margin_n=bad)
    assert law.gains.approach_force_margin_n == 200.0
    assert np.array_equal(law._fg, fg)


def _step(law: ExplicitForce, st, force_n: float) -> np.ndarray:
    """One cycle of a 400 N push's reference at ``force_n`` measured: τ (N per axis)."""
    out = np.zeros(3)
    law.update(st, force_n, ForceReference(f=400.0, f_dot=1000.0), 1e-3, out)
    return out


def _unbounded(law: ExplicitForce, st, force_n: float) -> np.ndarray:
    """τ of the same law with the approach unbounded (margin 0), from the same state."""
    free = ExplicitForce(MODEL, {**law.gains.model_dump(), "approach_force_margin_n": 0.0},
                         compiled=law.compiled)
    free._fs[:] = law._fs
    return _step(free, st, force_n)


@pytest.mark.parametrize("compiled", [True, False])
def test_the_bound_is_latched_off_after_the_first_touch_until_the_next_entry(
        compiled: bool) -> None:
    """The 700 kg landing's failure, at the law: after the entry's first touch the measured
    force falling back to ≈ 0 (the overload sinking the platform away from the foot), a pull
    or a lost reading leave the law unbounded — its command the unbounded law's from the same
    state — and a new entry (``reset``) bounds the approach again. The compiled and the
    interpreted law run the same sequence to 1e-9 N (not bit for bit: G and J_ik come from
    the compiled tree and ``inv3`` in one, Pinocchio and LAPACK in the other; the bound moves
    the command by ≥ 30 N per axis here)."""
    st = MODEL.dyn.state(np.asarray(MODEL.kin.ik(*POSE).q), np.zeros(3))
    law = ExplicitForce(MODEL, compiled=compiled)
    twin = ExplicitForce(MODEL, compiled=not compiled)

    def step(force_n: float) -> np.ndarray:
        out = _step(law, st, force_n)
        np.testing.assert_allclose(out, _step(twin, st, force_n), rtol=0.0, atol=1e-9)
        np.testing.assert_allclose(law._fs, twin._fs, rtol=1e-12, atol=1e-12, equal_nan=True)
        return out

    for _ in range(2):                                  # two force-mode entries
        assert law._fs[ck.FS_TOUCHED] == 0.0            # armed at the entry
        for f in (0.0, 1.0, math.nan, -1.0, ck.CONTACT_TOUCH_N):
            # Before the touch (no reading, noise, the touch threshold itself): bounded, the
            # integral held.
            free = _unbounded(law, st, f)
            held = law.integral
            out = step(f)
            assert np.all(out < free - 30.0), (f, out, free)
            assert law.integral == held
            assert law._fs[ck.FS_TOUCHED] == 0.0
        step(ck.CONTACT_TOUCH_N + 0.5)                  # the touch
        assert law._fs[ck.FS_TOUCHED] == 1.0
        for f in (0.0, 1.0, math.nan, -1.0, -50.0, 0.0):
            # Unloaded again, a pull, a lost reading: the law as if unbounded.
            free = _unbounded(law, st, f)
            np.testing.assert_allclose(step(f), free, rtol=0.0, atol=1e-9, err_msg=str(f))
            assert law._fs[ck.FS_TOUCHED] == 1.0
        law.reset()
        twin.reset()


def test_every_entry_is_approached_at_the_bound_and_the_contact_is_not() -> None:
    """Two pushes without memory, each its own force-mode entry: both gaps are closed at ≤ v_a
    (the second entry is bounded again), each contact is as fast as the first (the guess's
    bound both times), and within each push the law stays unbounded from its first touch on
    (``FS_TOUCHED`` set on every later force-mode cycle; an entry re-arms it)."""
    (p1, p2), law = _run_push(pushes=2)
    for vmax, v_a, contact, tau, wrong, rebound in (p1, p2):
        assert 0.02 < v_a < 0.03
        assert 0.5 * v_a < vmax <= _slack(law, v_a)
        assert contact <= 60
        assert tau < law.drive_force_limit_n
        assert wrong == 0
        print("rebound cycles (F ≤ touch after the touch):", rebound)
    assert p2[2] == pytest.approx(p1[2], abs=3)


def test_an_overload_unloading_the_sensor_mid_hold_meets_the_law_unbounded() -> None:
    """The failure the latch mends, on the twin: 700 kg lands under the fault matrix's 200 N
    hold on the strapped foot; the platform sinks away from the foot, whose force passes
    through ≈ 0 into a pull. On every force-mode cycle until the ``pulling`` stop the latch
    is set (the hold's entry touched at once) and the drives stay at their limit pushing
    back; re-engaged there (approach7) the bound cut the command to 0.6-1.1 kN per drive
    and the stop chain of ``tests/test_force_hold_payload.py`` failed."""
    from test_force_hold_payload import _hold_loop

    from rt.components.protocol_blocks import HybridController
    from rt.model.dynamics import Payload

    twin, pl = _hold_loop(MODEL)
    ctl = pl.graph.component("controller")
    assert isinstance(ctl, HybridController)
    law = ctl.force_law
    assert law._fs[ck.FS_TOUCHED] == 1.0
    twin.plant.set_payload(Payload(700.0, (0.0, 0.0, 0.10)))
    wrench, tau = pl.graph.output("force.wrench"), pl.graph.output("controller.tau")
    unloaded = 0
    for i in range(100):
        pl.loop.run(cycles=1)
        if pl.supervisor.reaction >= 1:
            break
        assert law._fs[ck.FS_TOUCHED] == 1.0
        if -wrench[2] <= ck.CONTACT_TOUCH_N:
            unloaded += 1
            assert float(np.min(tau)) > law.drive_force_limit_n, (i, -wrench[2], list(tau))
    assert unloaded >= 3, unloaded
    assert next(e.cause for e in pl.events.snapshot() if e.kind == "fault") == "pulling"
