"""Adaptive control (thesis 3.6.3) as the Slotine-Li passivity-based law, with projection.

    s = ė + Λ e,   q̇_r = q̇_d − Λ e,   q̈_r = q̈_d − Λ ė
    τ = Y(q, q̇, q̇_r, q̈_r) θ̂ − K_D s
    θ̂̇ = −Γ Yᵀ s, then θ̂ projected onto its box [θ_lo, θ_hi]

Y is the base-parameter regressor in Christoffel form (``Regressor.mixed``), so Ṁ − 2C is
skew-symmetric and V = ½ sᵀ M s + ½ θ̃ᵀ Γ⁻¹ θ̃ gives V̇ = −sᵀ K_D s ≤ 0 (the projection only
removes energy). Which parameters adapt, and their boxes, are derived from the payloads the
robot is specified for: every base parameter that a payload of up to ``max_payload_kg`` (COM
anywhere in a box on the platform) changes adapts inside the range those payloads span (plus
margin), and the friction coefficients adapt within [½, 2]× nominal. Everything else stays at
its nominal value (Γ = 0). The initial estimate is the nominal model, as in the thesis.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, ClassVar

import numpy as np
from pydantic import Field

from rt.control import kernels as ck
from rt.control.base import STATUS_OK, Controller, GainRange, Gains, register
from rt.control.laws import PD_RANGES
from rt.epoch import bump
from rt.model import rigid_body as rb
from rt.model.dynamics import Payload
from rt.model.kernels import TREE_DOF
from rt.model.regressor import Regressor

Positive = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


class AdaptiveGains(Gains):
    lambda_per_s: Positive = 20.0
    kd_n_s_per_m: Positive = 1.7e4
    #: Adaptation rate: Γ_ii = rate · (half-width of parameter i's box)² (dimensionless rate
    #: times the parameter's natural scale, so every parameter adapts on a similar time scale).
    #: Tuned on the twin's payload-step experiment: 0.1-0.4 converge in ~1 s with no chatter;
    #: above ~1 the estimates chase encoder quantization noise and tracking degrades.
    adaptation_rate: NonNegative = 0.3
    max_payload_kg: Positive = 150.0
    payload_com_box_m: tuple[Positive, Positive, Positive] = (0.15, 0.15, 0.30)


@register
class Adaptive(Controller):
    name = "adaptive"
    gains: AdaptiveGains
    gains_type = AdaptiveGains
    #: Λ sets the sliding surface's bandwidth (same 5-150 rad/s family as the PD laws, capped
    #: at 100 since K_D Λ acts as a stiffness); adaptation above 1 chases quantization noise
    #: (see ``AdaptiveGains``); payloads up to 250 kg (the thesis stepped 100 kg).
    gain_ranges: ClassVar[Mapping[str, GainRange]] = {
        "lambda_per_s": GainRange(1.0, 100.0, "1/s"),
        "kd_n_s_per_m": PD_RANGES["kd_n_s_per_m"],
        "adaptation_rate": GainRange(0.0, 1.0, ""),
        "max_payload_kg": GainRange(1.0, 250.0, "kg"),
        "payload_com_box_m": GainRange(0.01, 0.5, "m")}

    def __init__(self, model, gains=None, compiled: bool = True):
        self.regressor = Regressor(model.dyn)
        super().__init__(model, gains, compiled=compiled)

    def _gains_changed(self) -> None:
        self._set_bounds()
        self._pack_estimate(self.theta)

    def _pack_gains(self) -> None:
        self._gain_array[0] = self.gains.lambda_per_s
        self._gain_array[1] = self.gains.kd_n_s_per_m
        if hasattr(self, "_est"):              # the kernel reads them from its estimate array
            self._est[self._gains_at:self._gains_at + 2] = self._gain_array[0:2]

    def _set_bounds(self) -> None:
        g = self.gains
        reg = self.regressor
        dyn = self.dyn
        saved = dyn.payload
        nominal = reg.theta_base().copy()
        lo, hi = nominal.copy(), nominal.copy()
        box = g.payload_com_box_m
        for mass in (0.25 * g.max_payload_kg, g.max_payload_kg):
            for cx in (-box[0], 0.0, box[0]):
                for cy in (-box[1], 0.0, box[1]):
                    for cz in (0.0, box[2]):
                        # A solid payload: inertia of a 0.3 m cube about its COM.
                        i = mass * 0.3 ** 2 / 6.0
                        dyn.set_payload(Payload(mass, (cx, cy, cz),
                                                ((i, 0, 0), (0, i, 0), (0, 0, i))))
                        theta = reg.theta_base()
                        lo = np.minimum(lo, theta)
                        hi = np.maximum(hi, theta)
        dyn.set_payload(saved)
        names = reg.base.names
        for k, name in enumerate(names):
            if name[:2] in ("fv", "fc"):
                lo[k], hi[k] = 0.5 * nominal[k], 2.0 * nominal[k]
        width = hi - lo
        adapt = width > 1e-9 * (1.0 + np.abs(nominal))
        margin = 0.1 * width
        self.theta_lo = np.where(adapt, lo - margin, nominal)
        self.theta_hi = np.where(adapt, hi + margin, nominal)
        half = 0.5 * (self.theta_hi - self.theta_lo)
        self.gamma = np.where(adapt, g.adaptation_rate * half ** 2, 0.0)
        self.nominal = nominal
        self.adapted_names = [n for n, a in zip(names, adapt) if a]

    def reset(self) -> None:
        super().reset()
        if not hasattr(self, "theta_lo"):
            self._set_bounds()
        self._pack_estimate(self.nominal)
        self._qd_r = np.zeros(3)
        self._qdd_r = np.zeros(3)
        self._s = np.zeros(3)
        self._step = np.zeros(len(self.theta))

    def _law(self, st, ref, dt, out, dry_run):
        g = self.gains
        lam = g.lambda_per_s
        kd = g.kd_n_s_per_m
        q = st.cfg.q
        qd = st.qd
        s, qd_r, qdd_r = self._s, self._qd_r, self._qdd_r
        # Plain floats on 3-vectors (PLATFORM.md: small numpy calls cost µs each).
        for i in range(3):
            e = q[i] - ref.q[i]
            ed = qd[i] - ref.qd[i]
            s[i] = ed + lam * e
            qd_r[i] = ref.qd[i] - lam * e
            qdd_r[i] = ref.qdd[i] - lam * ed
        y = self.regressor.mixed(st, qd_r, qdd_r)
        np.dot(y, self.theta, out=out)
        out[0] -= kd * s[0]
        out[1] -= kd * s[1]
        out[2] -= kd * s[2]
        if not dry_run and dt > 0.0:
            step = self._step
            np.dot(s, y, out=step)                        # Yᵀ s
            step *= self.gamma
            step *= dt
            self.theta -= step
            np.clip(self.theta, self.theta_lo, self.theta_hi, out=self.theta)
        return STATUS_OK

    def _pack_estimate(self, theta: np.ndarray) -> None:
        """The kernel's arrays (``rt.control.kernels.adaptive``): the index map of the base
        parameters and one buffer holding θ̂ (``self.theta`` is a view of it), Γ, the box and
        scratch."""
        nb = len(self.nominal)
        reg = self.regressor
        rigid_pos, rigid_joint, rigid_param = [], [], []
        for pos, col in zip(reg._base_rigid_pos, reg._base_rigid_tree):
            rigid_pos.append(int(pos))
            rigid_joint.append(int(col) // rb.N_PARAMS)
            rigid_param.append(int(col) % rb.N_PARAMS)
        drive = [(int(pos), kind, axis) for pos, (kind, axis)
                 in zip(reg._base_drive_pos, reg._base_drive)]
        self._amap = np.array([nb, len(rigid_pos), len(drive), *rigid_pos, *rigid_joint,
                               *rigid_param, *(d[0] for d in drive), *(d[1] for d in drive),
                               *(d[2] for d in drive)], dtype=np.int64)
        est = np.zeros(ck.adaptive_est_size(nb, TREE_DOF))
        est[0:nb] = theta
        est[nb:2 * nb] = self.gamma
        est[2 * nb:3 * nb] = self.theta_lo
        est[3 * nb:4 * nb] = self.theta_hi
        self._gains_at = 5 * nb + rb.N_PARAMS * TREE_DOF + 9
        est[self._gains_at:self._gains_at + 2] = self._gain_array[0:2]
        self._est = est
        self._nb = nb
        bump()                        # a new estimate array: the fused cycle binds it again
        self.theta = est[0:nb]

    def _law_compiled(self, st, ref, dt, out, dry_run):
        d = self.dyn
        ck.adaptive(d.tree_i, d.tree_f, st.buf, ref.q, ref.qd, ref.qdd, self._amap, self._est,
                    dt, dry_run, out)
        return STATUS_OK

    def _bound_kernel(self, st, ref, out):
        d = self.dyn
        kernel, ti, tf, stb, q, qd, qdd = ck.adaptive, d.tree_i, d.tree_f, st.buf, ref.q, \
            ref.qd, ref.qdd

        def cycle(dt: float) -> int:
            # The estimate's arrays are rebuilt by a reset or new gains: read at call time.
            kernel(ti, tf, stb, q, qd, qdd, self._amap, self._est, dt, False, out)
            return STATUS_OK
        return cycle

    def estimate(self, name: str) -> float:
        """Current estimate of base parameter ``name``."""
        return float(self.theta[self.regressor.base.names.index(name)])


