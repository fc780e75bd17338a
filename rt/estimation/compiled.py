"""The Kalman velocity estimator's cycle compiled with numba.

Same filter, statuses and arithmetic as :class:`rt.estimation.velocity.KalmanVelocityEstimator`
(the interpreted reference; ``tests/test_compiled_cycle.py`` replays encoder streams through
both), with its state in one float64 array so the cycle is one call without Python objects.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from rt.estimation.velocity import N_AXES, EstimatorStatus, KalmanConfig

# Layout of the state array.
_X = 0            # x (3 axes × [q, q̇, q̈])
_P = 9            # posterior covariance p00, p01, p02, p11, p12, p22
_PRIOR = 15       # prior covariance, same order
_K = 21           # gain k0, k1, k2
_S = 24           # innovation variance
_DT_GAIN = 25     # period of the current gain (-1 forces a recursion step)
_PENDING = 26     # time carried from unfused samples (s)
_STEADY = 27      # 1.0 once the gain converged
_INIT = 28        # 1.0 once initialised
_LATCHED = 29     # 1.0 from a JUMP until a sample is fused
_GATE = 30        # the gate latched at the jump (m)
_SIZE = 31
# Layout of the parameter array.
_C_DT_MAX, _C_JERK, _C_R, _C_FLOOR, _C_VEL, _C_SIGMA, _C_TOL, _C_P11, _C_P22 = range(9)

_OK = int(EstimatorStatus.OK)
_INITIALISED = int(EstimatorStatus.INITIALISED)
_ERROR_NAN = int(EstimatorStatus.ERROR_NAN)
_ERROR_DT = int(EstimatorStatus.ERROR_DT)
_JUMP = int(EstimatorStatus.JUMP)


@njit(cache=True)
def _publish(s, out):
    for i in range(3):
        out[i] = s[_X + 3 * i]
        out[3 + i] = s[_X + 3 * i + 1]
        out[6 + i] = s[_X + 3 * i + 2]


@njit(cache=True)
def kalman_update(c, s, z, dt, out):
    """One sample: ``c`` parameters, ``s`` state (both layouts above), ``z`` the measured
    positions (m), ``dt`` (s); ``out`` = [q (3), q̇ (3), q̈ (3), innovation (3)]. Returns the
    ``EstimatorStatus`` value."""
    if not (0.0 < dt <= c[_C_DT_MAX]):
        return _ERROR_DT
    z0 = z[0]
    z1 = z[1]
    z2 = z[2]
    if not (math.isfinite(z0) and math.isfinite(z1) and math.isfinite(z2)):
        s[_PENDING] += dt
        return _ERROR_NAN
    if s[_INIT] == 0.0:
        for i in range(3):
            s[_X + 3 * i] = z[i]
            s[_X + 3 * i + 1] = 0.0
            s[_X + 3 * i + 2] = 0.0
        s[_P] = c[_C_R]
        s[_P + 1] = 0.0
        s[_P + 2] = 0.0
        s[_P + 3] = c[_C_P11]
        s[_P + 4] = 0.0
        s[_P + 5] = c[_C_P22]
        s[_STEADY] = 0.0
        s[_INIT] = 1.0
        s[_PENDING] = 0.0
        _publish(s, out)
        for i in range(3):
            out[9 + i] = 0.0
        return _INITIALISED
    t = dt + s[_PENDING]
    h = 0.5 * t * t
    if s[_STEADY] != 0.0 and t == s[_DT_GAIN]:
        k0 = s[_K]
        k1 = s[_K + 1]
        k2 = s[_K + 2]
        sv = s[_S]
    else:
        p00 = s[_P]
        p01 = s[_P + 1]
        p02 = s[_P + 2]
        p11 = s[_P + 3]
        p12 = s[_P + 4]
        p22 = s[_P + 5]
        a0 = p00 + t * p01 + h * p02
        a1 = p01 + t * p11 + h * p12
        a2 = p02 + t * p12 + h * p22
        b1 = p11 + t * p12
        b2 = p12 + t * p22
        sj = c[_C_JERK]
        t2 = t * t
        t3 = t2 * t
        m00 = a0 + t * a1 + h * a2 + sj * t3 * t2 / 20.0
        m01 = a1 + t * a2 + sj * t2 * t2 / 8.0
        m02 = a2 + sj * t3 / 6.0
        m11 = b1 + t * b2 + sj * t3 / 3.0
        m12 = b2 + sj * h
        m22 = p22 + sj * t
        sv = m00 + c[_C_R]
        k0 = m00 / sv
        k1 = m01 / sv
        k2 = m02 / sv
        s[_PRIOR] = m00
        s[_PRIOR + 1] = m01
        s[_PRIOR + 2] = m02
        s[_PRIOR + 3] = m11
        s[_PRIOR + 4] = m12
        s[_PRIOR + 5] = m22
        s[_S] = sv
        ok0 = s[_K]
        ok1 = s[_K + 1]
        ok2 = s[_K + 2]
        tol = c[_C_TOL]
        steady = (t == s[_DT_GAIN] and abs(k0 - ok0) <= tol * abs(k0)
                  and abs(k1 - ok1) <= tol * abs(k1) and abs(k2 - ok2) <= tol * abs(k2))
        s[_STEADY] = 1.0 if steady else 0.0
        s[_K] = k0
        s[_K + 1] = k1
        s[_K + 2] = k2
        s[_DT_GAIN] = t
    gate = c[_C_FLOOR] + c[_C_VEL] * t + c[_C_SIGMA] * math.sqrt(sv)
    if s[_LATCHED] != 0.0 and gate > s[_GATE]:
        gate = s[_GATE]
    r0 = z0 - (s[_X] + t * s[_X + 1] + h * s[_X + 2])
    r1 = z1 - (s[_X + 3] + t * s[_X + 4] + h * s[_X + 5])
    r2 = z2 - (s[_X + 6] + t * s[_X + 7] + h * s[_X + 8])
    out[9] = r0
    out[10] = r1
    out[11] = r2
    if abs(r0) > gate or abs(r1) > gate or abs(r2) > gate:
        s[_PENDING] = t
        s[_STEADY] = 0.0
        s[_DT_GAIN] = -1.0
        if s[_LATCHED] == 0.0:
            s[_LATCHED] = 1.0
            s[_GATE] = gate
        return _JUMP
    for i in range(3):
        r = out[9 + i]
        x0 = s[_X + 3 * i]
        x1 = s[_X + 3 * i + 1]
        x2 = s[_X + 3 * i + 2]
        v = x1 + t * x2
        s[_X + 3 * i] = x0 + t * x1 + h * x2 + k0 * r
        s[_X + 3 * i + 1] = v + k1 * r
        s[_X + 3 * i + 2] = x2 + k2 * r
    if s[_STEADY] == 0.0:
        m00 = s[_PRIOR]
        m01 = s[_PRIOR + 1]
        m02 = s[_PRIOR + 2]
        s[_P] = m00 - k0 * m00
        s[_P + 1] = m01 - k0 * m01
        s[_P + 2] = m02 - k0 * m02
        s[_P + 3] = s[_PRIOR + 3] - k1 * m01
        s[_P + 4] = s[_PRIOR + 4] - k1 * m02
        s[_P + 5] = s[_PRIOR + 5] - k2 * m02
    s[_PENDING] = 0.0
    s[_LATCHED] = 0.0
    _publish(s, out)
    return _OK


@njit(cache=True)
def block_update(c, s, z, dt, out, io):
    """:func:`kalman_update`, then the estimation block's outputs in one arena ``io`` = [q (3),
    q̇ (3), q̈ (3), status]: the status always, the estimate unless the sample was refused
    (a flagged jump is published: it is the supervisor's business)."""
    status = kalman_update(c, s, z, dt, out)
    io[9] = status
    if status < 0 and status != _JUMP:
        return status
    for i in range(9):
        io[i] = out[i]
    return status


class CompiledKalmanEstimator:
    """:class:`KalmanVelocityEstimator`'s interface (``q``, ``qd``, ``qdd``, ``innovation``,
    ``update``, ``reset``, ``gain``, ``converged``, ``jump_latched``) over the compiled cycle.
    ``update`` returns the status as an int (the ``EstimatorStatus`` value)."""

    def __init__(self, config: KalmanConfig | None = None) -> None:
        self.config = config if config is not None else KalmanConfig()
        self.config.check()
        c = self.config
        self._c = np.array([c.dt_max_s, c.jerk_psd, c.resolution_m ** 2 / 12.0, c.jump_floor_m,
                            c.jump_velocity_m_s, c.jump_sigma, c.steady_gain_tol,
                            c.initial_velocity_std_m_s ** 2,
                            c.initial_acceleration_std_m_s2 ** 2])
        self._s = np.zeros(_SIZE)
        self._out = np.zeros(4 * N_AXES)
        self.q = self._out[0:3]
        self.qd = self._out[3:6]
        self.qdd = self._out[6:9]
        self.innovation = self._out[9:12]
        self.reset()
        # Compile (or load from numba's cache) now, not in a cycle, for the loop's read-only
        # port views and for writable arrays (numba types them apart).
        z = np.zeros(3)
        kalman_update(self._c, self._s.copy(), z, c.dt_s, self._out.copy())
        z.flags.writeable = False
        kalman_update(self._c, self._s.copy(), z, c.dt_s, self._out.copy())
        for zz in (z, z.copy()):
            block_update(self._c, self._s.copy(), zz, c.dt_s, self._out.copy(), np.zeros(10))

    def reset(self) -> None:
        """Forget the state; the next valid sample re-initialises the filter."""
        self._s[:] = 0.0
        self._s[_DT_GAIN] = -1.0
        self._out[:] = 0.0

    def update(self, q_measured: np.ndarray, dt: float) -> int:
        """See :meth:`KalmanVelocityEstimator.update`."""
        return kalman_update(self._c, self._s, q_measured, dt, self._out)

    def update_into(self, q_measured: np.ndarray, dt: float, io: np.ndarray) -> int:
        """:meth:`update`, then [q, q̇, q̈, status] written into ``io`` (10,) in the same call:
        the status always, the estimate unless the sample was refused (``block_update``)."""
        return block_update(self._c, self._s, q_measured, dt, self._out, io)

    @property
    def gain(self) -> tuple[float, float, float]:
        return (float(self._s[_K]), float(self._s[_K + 1]), float(self._s[_K + 2]))

    @property
    def converged(self) -> bool:
        return bool(self._s[_STEADY] != 0.0)

    @property
    def jump_latched(self) -> bool:
        return bool(self._s[_LATCHED] != 0.0)
