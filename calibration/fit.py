"""The fit: a 6×N calibration matrix with load-misalignment angles, then a position-dependent
correction.

Linear stage (Cedraro 2008, Cappello 2004). Model: ``R(θ_s) w_ref = C v + e`` for the samples
of site s, where θ_s (rotations about F's x and y, rad; a direction has two degrees of
freedom, and a rotation about z would only turn the small shear, indistinguishable from
Fx/Fy crosstalk) is the misalignment of the load's direction at that site (registration
error, tool out of square): the reference force is rotated by R(θ_s) about the load point, so
its moment about O follows. Unknowns: C (6×N) and every θ_s,
solved by alternating least squares (C given θ: linear per row; θ given C: 3×3 linear per site,
linearized about the current angles), ``iterations`` times. A constant misalignment shared by
every site cannot be told from crosstalk with loads that all point the same way: the angles
have a zero-mean prior (``PRIOR_ANGLE_RAD``, what the registration allows), so that common
part goes to the matrix (whose prior is much wider) and to the uncertainty budget, and the
angles the loads cannot reach (a rotation about a vertical load's own line) stay at zero.

Each row of C is a Bayesian linear regression with a prior centred on the nominal matrix
(``PRIOR_PCT_FS`` of the axis's full scale at the channel's full range, 1 σ): an entry the
excitation does not reach keeps its nominal value and its prior standard error, and is
reported *not identified* (its posterior standard error is more than ``IDENTIFIED_RATIO`` of
its prior one). Standard errors: ``σ_i² (VᵀV + σ_i² Λ_i)⁻¹`` with σ_i the row's residual RMS —
block means of static plateaus have correlated errors, so these are lower bounds; the
held-out validation is the honest figure.

Nonlinear stage (after Cappello 2011's position-dependent matrix). From the linearly
calibrated wrench: COP error ΔCOP(x, y) and vertical-force gain g(x, y) + k Fz as bivariate
polynomials of the (linearly calibrated) COP, normalized to the plate's half-sizes, fitted on
loaded training samples (Fz ≥ ``COP_MIN_LOAD_N``); the corrected moments follow from the
corrected COP and forces, the free moment kept.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from calibration.dataset import Samples
from calibration.plate import PlateDescription, cop_F
from calibration.registration import small_rotation

PRIOR_PCT_FS = 5.0
#: Prior on the misalignment angles (rad, 1 σ): a load direction out by more than a few
#: degrees is a set-up error, not something to fit away. It also pins the angles the loads do
#: not reach (a rotation about a vertical load's own line).
PRIOR_ANGLE_RAD = math.radians(2.0)
#: Residual floor, as a fraction of the axis's full scale (noise-free synthetic data).
RESIDUAL_FLOOR_FS = 1e-7
IDENTIFIED_RATIO = 0.2
COP_MIN_LOAD_N = 150.0


@dataclass
class LinearFit:
    C: np.ndarray                         # (6, N)
    standard_error: np.ndarray            # (6, N)
    identified: np.ndarray                # (6, N) bool
    angles_rad: dict[str, np.ndarray]     # site -> (3,)
    residual_rms: np.ndarray              # (6,) N, N·m on the training samples
    iterations: int = 0

    def record_entry(self, plate: PlateDescription) -> dict:
        return {"cal_matrix": self.C.tolist(), "standard_error": self.standard_error.tolist(),
                "identified": self.identified.tolist(),
                "channel_order": plate.channel_labels(),
                "row_order": ["Fx", "Fy", "Fz", "Mx", "My", "Mz"], "moment_unit": "N·m",
                "force_unit": "N", "channel_unit": [c.unit for c in plate.channels],
                "about": "transducer origin O (plate.origin_m), axes of the plate frame F",
                "misalignment_deg": {k: np.degrees(v).tolist()
                                     for k, v in self.angles_rad.items()},
                "residual_rms": self.residual_rms.tolist()}


def rotate_reference(w: np.ndarray, p: np.ndarray, origin: np.ndarray, R: np.ndarray
                     ) -> np.ndarray:
    """The reference wrench with its force direction rotated by R about the load point."""
    f = w[:, :3]
    lever = p - origin
    free = w[:, 3:] - np.cross(lever, f)
    f2 = f @ R.T
    return np.hstack([f2, np.cross(lever, f2) + free @ R.T])


def _prior_sigma(plate: PlateDescription) -> np.ndarray:
    """(6, N) prior standard deviation of each entry."""
    fs = plate.full_scale()
    return PRIOR_PCT_FS / 100.0 * fs[:, None] / plate.channel_ranges()[None, :]


def _solve_rows(V: np.ndarray, W: np.ndarray, C0: np.ndarray, prior: np.ndarray,
                fs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per row: posterior mean, standard errors and residual RMS (Bayesian LS, prior C0)."""
    n, N = V.shape
    C = np.empty_like(C0)
    se = np.empty_like(C0)
    rms = np.empty(6)
    G = V.T @ V
    for i in range(6):
        y = W[:, i]
        # Two passes: the residual variance sets the prior's weight.
        floor = (RESIDUAL_FLOOR_FS * fs[i]) ** 2
        s2 = max(float(np.var(y - V @ C0[i])), floor)
        for _ in range(3):
            A = G + s2 * np.diag(1.0 / prior[i] ** 2)
            C[i] = C0[i] + np.linalg.solve(A, V.T @ (y - V @ C0[i]))
            r = y - V @ C[i]
            s2 = max(float(r @ r) / max(n - N, 1), floor)
        A = G + s2 * np.diag(1.0 / prior[i] ** 2)
        se[i] = np.sqrt(np.abs(np.diag(s2 * np.linalg.inv(A))))
        rms[i] = math.sqrt(float(np.mean(r ** 2)))
    return C, se, rms


def fit_linear(plate: PlateDescription, s: Samples, estimate_angles: bool = True,
               iterations: int = 8) -> LinearFit:
    """The linear stage (module docstring) on training samples ``s``."""
    origin = np.array(plate.origin_m)
    C0 = plate.nominal_C()
    prior = _prior_sigma(plate)
    angles = {name: np.zeros(3) for name in s.site_names}
    sites = np.unique(s.site)
    W = s.w_ref.copy()
    fs = plate.full_scale()
    C, se, rms = _solve_rows(s.v, W, C0, prior, fs)
    done = 0
    for done in range(1, (iterations if estimate_angles else 0) + 1):
        for k in sites:
            m = s.site == k
            name = s.site_names[k]
            target = s.v[m] @ C.T
            # Linearize R(θ + δ) w about θ: derivative by finite rotations of each axis.
            base = rotate_reference(s.w_ref[m], s.p_ref[m], origin, small_rotation(angles[name]))
            J = np.empty((base.size, 2))
            h = 1e-6
            for a in range(2):
                d = angles[name].copy()
                d[a] += h
                J[:, a] = ((rotate_reference(s.w_ref[m], s.p_ref[m], origin, small_rotation(d))
                            - base) / h).ravel()
            # Weight the rows by the inverse residual scale of each axis.
            wts = np.tile(1.0 / np.maximum(rms, RESIDUAL_FLOOR_FS * fs), base.shape[0])
            # The prior on the angles enters as three extra rows: (θ + δ)/σ_θ ≈ 0.
            A = np.vstack([J * wts[:, None], np.eye(2) / PRIOR_ANGLE_RAD])
            b = np.concatenate([(target - base).ravel() * wts,
                                -angles[name][:2] / PRIOR_ANGLE_RAD])
            delta, *_ = np.linalg.lstsq(A, b, rcond=None)
            angles[name][:2] += delta
        for k in sites:
            m = s.site == k
            W[m] = rotate_reference(s.w_ref[m], s.p_ref[m], origin,
                                    small_rotation(angles[s.site_names[k]]))
        C, se, rms = _solve_rows(s.v, W, C0, prior, fs)
    identified = se < IDENTIFIED_RATIO * prior
    return LinearFit(C, se, identified, {s.site_names[k]: angles[s.site_names[k]]
                                         for k in sites}, rms, done)


# ------------------------------------------------------------------------------ nonlinear
def _poly_terms(u: np.ndarray, w: np.ndarray, degree: int) -> np.ndarray:
    return np.column_stack([u ** i * w ** j for i in range(degree + 1)
                            for j in range(degree + 1 - i)])


@dataclass
class NonlinearCorrection:
    """COP and vertical-force correction as functions of the linearly calibrated COP."""

    degree: int
    half_size_m: tuple[float, float]
    origin_m: tuple[float, float, float]
    cop_x: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cop_y: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gain: np.ndarray = field(default_factory=lambda: np.zeros(0))
    fz_quadratic: float = 0.0
    full_scale_fz_n: float = 1.0

    def apply(self, w_lin: np.ndarray) -> np.ndarray:
        """Corrected wrenches (n, 6) about O from linearly calibrated ones."""
        cop, tz = cop_F(w_lin, self.origin_m)
        ok = np.isfinite(cop[:, 0])
        out = w_lin.copy()
        if not ok.any():
            return out
        u = cop[ok, 0] / self.half_size_m[0]
        v = cop[ok, 1] / self.half_size_m[1]
        T = _poly_terms(u, v, self.degree)
        px = cop[ok, 0] + T @ self.cop_x
        py = cop[ok, 1] + T @ self.cop_y
        f = w_lin[ok, :3].copy()
        fz = f[:, 2]
        f[:, 2] = fz * (1.0 + _poly_terms(u, v, 2) @ self.gain
                        + self.fz_quadratic * fz / self.full_scale_fz_n)
        ox, oy, oz = self.origin_m
        out[ok, :3] = f
        out[ok, 3] = (py - oy) * f[:, 2] + oz * f[:, 1]
        out[ok, 4] = -oz * f[:, 0] - (px - ox) * f[:, 2]
        out[ok, 5] = tz[ok] + (px - ox) * f[:, 1] - (py - oy) * f[:, 0]
        return out

    @classmethod
    def from_record(cls, entry: dict, origin_m: tuple[float, float, float]
                    ) -> "NonlinearCorrection":
        """Rebuild the correction from the record's ``nonlinear_correction`` block."""
        return cls(int(entry["degree"]), tuple(entry["half_size_m"]),  # type: ignore[arg-type]
                   origin_m, np.array(entry["cop_x_m"]), np.array(entry["cop_y_m"]),
                   np.array(entry["fz_gain"]), float(entry["fz_quadratic"]),
                   float(entry["full_scale_fz_n"]))

    def record_entry(self) -> dict:
        return {"model": "polynomial_cop_correction", "degree": self.degree,
                "variables": "u = COPx/half_x, v = COPy/half_y of the linearly calibrated COP; "
                             "terms u^i v^j, i + j <= degree, ordered by i then j",
                "half_size_m": list(self.half_size_m), "cop_x_m": self.cop_x.tolist(),
                "cop_y_m": self.cop_y.tolist(), "fz_gain_degree": 2,
                "fz_gain": self.gain.tolist(), "fz_quadratic": self.fz_quadratic,
                "full_scale_fz_n": self.full_scale_fz_n,
                "applies_to": "wrench = cal_matrix · channels, then COP and Fz corrected, "
                              "moments recomputed about O with the free moment kept"}


def fit_nonlinear(plate: PlateDescription, lin: LinearFit, s: Samples, degree: int = 3
                  ) -> NonlinearCorrection:
    """The position-dependent stage on training samples ``s`` (module docstring)."""
    hx, hy = plate.size_m[0] / 2, plate.size_m[1] / 2
    corr = NonlinearCorrection(degree, (hx, hy), tuple(plate.origin_m),  # type: ignore[arg-type]
                               full_scale_fz_n=float(plate.force_range_n[2]))
    w_lin = s.v @ lin.C.T
    cop, _ = cop_F(w_lin, plate.origin_m)
    use = (s.w_ref[:, 2] >= COP_MIN_LOAD_N) & np.isfinite(cop[:, 0])
    if use.sum() < 3 * (degree + 1) * (degree + 2) // 2:
        corr.cop_x = np.zeros((degree + 1) * (degree + 2) // 2)
        corr.cop_y = corr.cop_x.copy()
        corr.gain = np.zeros(6)
        return corr
    u, v = cop[use, 0] / hx, cop[use, 1] / hy
    T = _poly_terms(u, v, degree)
    corr.cop_x, *_ = np.linalg.lstsq(T, s.p_ref[use, 0] - cop[use, 0], rcond=None)
    corr.cop_y, *_ = np.linalg.lstsq(T, s.p_ref[use, 1] - cop[use, 1], rcond=None)
    fz = w_lin[use, 2]
    G = np.column_stack([_poly_terms(u, v, 2) * fz[:, None],
                         fz ** 2 / corr.full_scale_fz_n])
    coef, *_ = np.linalg.lstsq(G, s.w_ref[use, 2] - fz, rcond=None)
    corr.gain, corr.fz_quadratic = coef[:-1], float(coef[-1])
    return corr
