"""Two dynamics kernels rewritten for speed (issue 16) against their definitions: the
parameter gradient A(v, a)ᵀ u in closed form against the body force of every unit inertial
parameter, and the one-pass inverse dynamics against the three-pass mixed torque at u_vel = q̇
(equal up to rounding: the polarized C q̇ is h(Q̇))."""
from __future__ import annotations

import numpy as np

from rt.model import RobotModel
from rt.model import rigid_body as rb
from rt.model.dynamics import State
from rt.model.kernels import TREE_DOF


def _gradient_by_definition(v: np.ndarray, a: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Σ_j u_jᵀ f_j(π_j) is linear in π_j: its gradient is the force of each unit π."""
    n = v.shape[0]
    grad = np.zeros((n, rb.N_PARAMS))
    for j in range(n):
        for k in range(rb.N_PARAMS):
            e = np.zeros((1, rb.N_PARAMS))
            e[0, k] = 1.0
            f = rb.body_force.py_func(e, 0, v[j:j + 1], a[j:j + 1])
            grad[j, k] = float(np.dot(u[j], f))
    return grad


def test_the_closed_form_parameter_gradient_is_the_unit_parameter_forces():
    rng = np.random.default_rng(7)
    e = np.zeros((1, rb.N_PARAMS))
    for _ in range(20):
        scale = rng.uniform(0.01, 10.0, size=3)
        v, a, u = (rng.normal(size=(TREE_DOF, 6)) * s for s in scale)
        want = _gradient_by_definition(v, a, u)
        got = np.full((TREE_DOF, rb.N_PARAMS), 0.5)          # it accumulates
        rb.param_gradient(v, a, u, -0.25, got, e)
        # Sums of a dozen products reassociated: within 1e-13 of the gradient's scale.
        assert np.allclose(got, 0.5 - 0.25 * want, rtol=0.0,
                           atol=1e-13 * max(1.0, np.abs(want).max()))
    assert not e.any()


def test_one_pass_inverse_dynamics_is_the_mixed_torque_at_the_states_velocity():
    model = RobotModel.load()
    dyn = model.dyn
    pi = rb.unpack_tree(dyn.tree_i, dyn.tree_f)[5]
    rng = np.random.default_rng(11)
    work = np.zeros(8 + rb.work_size(TREE_DOF))
    worst = 0.0
    for _ in range(30):
        cfg = model.kin.ik(0.6 + rng.uniform(-0.03, 0.03), rng.uniform(-0.1, 0.1),
                           rng.uniform(-0.1, 0.1))
        st = dyn.state(np.array(cfg.q), rng.normal(size=3) * 0.1, out=State())
        acc = rng.normal(size=3) * 2.0
        three, one = np.zeros(3), np.zeros(3)
        rb.mixed_torque(dyn.tree_i, dyn.tree_f, pi, st.buf, acc, st.qd.copy(), True, work,
                        three)
        rb.inverse_dynamics(dyn.tree_i, dyn.tree_f, pi, st.buf, acc, work, one)
        worst = max(worst, float(np.abs(one - three).max() / np.abs(three).max()))
        # And the interpreted model's M a + C q̇ + G (pinocchio), the laws' reference.
        m, c, g = dyn.mcg(st)
        want = m @ acc + c @ st.qd + g
        assert np.allclose(one, want, rtol=0.0, atol=1e-12 * np.abs(want).max())
    assert worst <= 1e-14
