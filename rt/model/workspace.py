"""Workspace extents and conditioning, for ``talus model describe`` and the demo."""
from __future__ import annotations

import math

import numpy as np

from rt.errors import KinematicsError
from rt.model.dynamics import Dynamics
from rt.model.kernels import constraint_terms
from rt.model.kinematics import Configuration, Kinematics


def conditioning(dyn: Dynamics, cfg: Configuration) -> dict[str, float]:
    """Conditioning indices in [0, 1] (1 = isotropic, 0 = singular).

    ``inverse``: σ_min/σ_max of the IK Jacobian ∂q/∂(z, R_p γ, R_p β) (angles scaled by the
    platform radius so all columns are lengths); it falls to 0 where the sliders lose control of
    the platform. ``forward``: the same ratio for the forward-kinematics constraint Jacobian
    ∂f/∂φ; it falls to 0 at a forward (assembly) singularity, where Newton fails.
    """
    st = dyn.state(cfg.q, cfg=cfg)
    j_fk = st.S[[8, 11, 10]]                 # rows z, roll, pitch of ∂Q/∂q
    rp = dyn.kin.platform_radius
    j_fk_scaled = j_fk * np.array([1.0, rp, rp])[:, None]
    s = np.linalg.svd(j_fk_scaled, compute_uv=False)
    inverse = float(s[-1] / s[0])
    _, _, _, a00, a01, a11, a12, a22, a20 = constraint_terms(dyn.kin.geom, np.array(cfg.q),
                                                             *cfg.phi)
    jac = np.array([[a00, a01, 0.0], [0.0, a11, a12], [a20, 0.0, a22]])
    sf = np.linalg.svd(jac, compute_uv=False)
    return {"inverse": inverse, "forward": float(sf[-1] / sf[0])}


def heave_range(kin: Kinematics, roll: float = 0.0, pitch: float = 0.0,
                step: float = 0.001) -> tuple[float, float]:
    """Lowest and highest platform z (m) reachable at the given roll/pitch (scan at ``step``)."""
    level = kin.ik(0.0, roll, pitch, check=False)
    # z shifts every slider equally: scan the slider-stroke window.
    z0 = -min(level.q)
    z_lo = z0 + kin.stroke[0] - 0.05
    z_hi = z0 + kin.stroke[1] + 0.05
    inside = [z for z in np.arange(z_lo, z_hi, step) if _reachable(kin, z, roll, pitch)]
    if not inside:
        raise KinematicsError(f"no reachable heave at roll {roll} rad, pitch {pitch} rad")
    return float(inside[0]), float(inside[-1])


def max_tilt(kin: Kinematics, z: float, axis: str, step_deg: float = 0.1) -> float:
    """Largest |roll| or |pitch| (rad) reachable at heave z with the other angle zero."""
    best = 0.0
    a = step_deg
    while a < 60.0:
        ang = math.radians(a)
        ok = all(_reachable(kin, z, s * ang if axis == "roll" else 0.0,
                            s * ang if axis == "pitch" else 0.0) for s in (1.0, -1.0))
        if not ok:
            break
        best = ang
        a += step_deg
    return best


def _reachable(kin: Kinematics, z: float, roll: float, pitch: float) -> bool:
    try:
        kin.ik(z, roll, pitch)
        return True
    except KinematicsError:
        return False
