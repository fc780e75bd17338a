"""One axis of a virtual admittance integrated at the loop rate, bounded in speed, acceleration
and range: what active assist (``protocols.active_assist``) and the ankle-torque holds
(``protocols.torque_hold``) render through the position loop.

Per axis (θ the angle from a reference, rad):
``I θ̈ + B (θ̇ - g θ̇_guide) + g K (θ - θ_guide) = τ`` integrated by semi-implicit Euler at dt;
then, in this order: θ̈ within ±α; θ̇ within ±ω; θ̇ towards a range end within the speed from
which braking at α stops at the end (:func:`stop_speed`); θ clamped to the range as a last
resort (round-off only). Plain floats: it runs every cycle (``PLATFORM.md``: numpy on
3-vectors is slow).
"""
from __future__ import annotations

import math


def stop_speed(distance: float, a_max: float, dt: float) -> float:
    """Largest speed (rad/s) for this step from which braking at ``a_max`` stops within
    ``distance`` (rad): v·dt + v²/(2α) - v·dt/2 ≤ d (the step, then the discrete braking), and
    never more than reaches the end in this step (v·dt ≤ d), so the angle arrives at a range
    end with its rate, not by the clamp."""
    if distance <= 0.0:
        return 0.0
    return min(a_max * (math.sqrt(0.25 * dt * dt + 2.0 * distance / a_max) - 0.5 * dt),
               distance / dt)


def step_axis(th: float, w: float, tau: float, guide: float, guide_rate: float,
              imk: tuple[float, float, float], lo: float, hi: float, gain: float,
              a_max: float, w_max: float, dt: float) -> tuple[float, float, float]:
    """One step of the admittance (module docstring): the new angle (rad), rate (rad/s) and
    the acceleration (rad/s²) that led there, from angle ``th``, rate ``w``, torque ``tau``
    (N·m), the guide's angle and rate, (I kg m², B N m s/rad, K N m/rad), the range [lo, hi]
    (rad) and the gain g."""
    inertia, damping, stiffness = imk
    acc = (tau - damping * (w - gain * guide_rate) - gain * stiffness * (th - guide)) / inertia
    acc = min(max(acc, -a_max), a_max)
    w_new = min(max(w + acc * dt, -w_max), w_max)
    if w_new > 0.0:
        w_new = min(w_new, stop_speed(hi - th, a_max, dt))
    elif w_new < 0.0:
        w_new = max(w_new, -stop_speed(th - lo, a_max, dt))
    th_new = th + w_new * dt
    if th_new > hi:
        th_new, w_new = hi, 0.0
    elif th_new < lo:
        th_new, w_new = lo, 0.0
    return th_new, w_new, (w_new - w) / dt
