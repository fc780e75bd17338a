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
every site cannot be told from crosstalk with loads that all point the same way: the sites'
mean angle is held at zero (``MEAN_ANGLE_SIGMA_RAD``), so that common part goes to the
matrix and to the uncertainty budget (the registration's rotation uncertainty); each angle
has a zero-mean prior: the registration's rotation uncertainty at that site combined with
the tool's squareness (``TOOL_SQUARENESS_RAD``). The prior matters: angles free to move far
would soak up what the linear matrix cannot model (the top plate's bending leaks into the
shear channels through crosstalk) and bias the matrix at the other sites.

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
loaded training samples (Fz ≥ ``COP_MIN_LOAD_N``); the COP polynomial's degree is chosen by
leave-one-site-out cross-validation (a degree with as many terms as sites would interpolate
the sites and swing between them); the corrected moments follow from the corrected COP and
forces, the free moment kept.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from calibration.dataset import Samples
from calibration.plate import PlateDescription, cop_F
from calibration.registration import small_rotation

PRIOR_PCT_FS = 5.0
#: The load applicator's squareness on the ATI (rad, 1 σ), added to the registration's
#: rotation uncertainty in the prior of each site's misalignment angles.
TOOL_SQUARENESS_RAD = math.radians(0.1)
#: The sites' mean misalignment is held at zero to within this (rad): a misalignment shared
#: by every site is indistinguishable from crosstalk and is given to the matrix.
MEAN_ANGLE_SIGMA_RAD = math.radians(0.001)
#: Residual floor, as a fraction of the axis's full scale (noise-free synthetic data).
RESIDUAL_FLOOR_FS = 1e-6
IDENTIFIED_RATIO = 0.2
#: A channel direction whose RMS excitation is below this fraction of the channel's range is
#: "not excited" (noise and crosstalk only).
MIN_EXCITATION = 1e-3
#: A column is not identified when more than this share of its unit direction is unexcited.
MAX_UNEXCITED_SHARE = 0.3
#: Weight (in prior units) holding the unexcited directions at the nominal matrix.
HOLD_WEIGHT = 1e6
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


def _rotation_jacobian(w: np.ndarray, p: np.ndarray, origin: np.ndarray, angles: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The reference rotated by ``angles`` (n, 6) and its derivative (n, 6, 2) with respect to
    the rotations about x and y (finite differences of the exact rotation)."""
    base = rotate_reference(w, p, origin, small_rotation(angles))
    J = np.empty((*base.shape, 2))
    h = 1e-7
    for a in range(2):
        d = angles.copy()
        d[a] += h
        J[:, :, a] = (rotate_reference(w, p, origin, small_rotation(d)) - base) / h
    return base, J


def fit_linear(plate: PlateDescription, s: Samples, estimate_angles: bool = True,
               iterations: int = 6, angle_prior_rad: dict[str, float] | float | None = None
               ) -> LinearFit:
    """The linear stage (module docstring) on training samples ``s``.

    Gauss-Newton on the joint unknowns x = (C row by row, θ per site), the rotation linearized
    about the current angles; the rows of each wrench axis weighted by that axis' residual
    RMS; the priors (nominal matrix, zero angles) as extra rows. The posterior covariance
    (the inverse of the normal matrix) gives the standard errors, the angles' uncertainty
    included. ``angle_prior_rad``: per site name (or one for all) the angles' prior σ;
    default ``TOOL_SQUARENESS_RAD``.
    """
    origin = np.array(plate.origin_m)
    C0 = plate.nominal_C()
    n_ch = plate.n_channels
    prior = _prior_sigma(plate)
    fs = plate.full_scale()
    sites = [int(k) for k in np.unique(s.site)] if estimate_angles else []
    n_c, n_x = 6 * n_ch, 6 * n_ch + 2 * len(sites)
    angles = {s.site_names[k]: np.zeros(3) for k in np.unique(s.site)}
    prior_theta = np.array([
        (angle_prior_rad.get(s.site_names[k], TOOL_SQUARENESS_RAD)
         if isinstance(angle_prior_rad, dict) else
         (TOOL_SQUARENESS_RAD if angle_prior_rad is None else float(angle_prior_rad)))
        for k in sites for _ in range(2)])
    # Channel directions the loads do not excite (in units of each channel's range): their
    # columns cannot be identified; the fit keeps the nominal matrix along them.
    ranges = plate.channel_ranges()
    _, sv, vt = np.linalg.svd(s.v / ranges / math.sqrt(max(len(s), 1)), full_matrices=False)
    null = vt[sv < MIN_EXCITATION]                     # rows: unexcited unit directions
    null_proj = null.T @ null                          # projector, channel/range units
    unexcited_share = np.sqrt(np.diag(null_proj))      # of each channel's unit direction
    C = C0.copy()
    sigma = fs * 1e-3                       # axis residual scale, refined each iteration
    V = s.v
    G = V.T @ V
    cov = np.eye(n_x)
    done = 0
    for done in range(1, iterations + 1):
        W = s.w_ref.copy()
        Js: dict[int, np.ndarray] = {}
        for k in np.unique(s.site):
            m = s.site == k
            W[m], J = _rotation_jacobian(s.w_ref[m], s.p_ref[m], origin,
                                         angles[s.site_names[k]])
            Js[int(k)] = J
        N = np.zeros((n_x, n_x))
        rhs = np.zeros(n_x)
        x0 = np.concatenate([C.ravel(), np.concatenate([angles[s.site_names[k]][:2]
                                                        for k in sites]) if sites else []])
        R = V @ C.T - W                      # residual (n, 6) at the current point
        for i in range(6):
            wi = 1.0 / sigma[i] ** 2
            ci = slice(i * n_ch, (i + 1) * n_ch)
            N[ci, ci] += G * wi
            rhs[ci] -= V.T @ R[:, i] * wi
            for q, k in enumerate(sites):
                m = s.site == k
                ti = slice(n_c + 2 * q, n_c + 2 * q + 2)
                Ji = -Js[k][:, i, :]           # d r / d θ = -d W / d θ
                cross = V[m].T @ Ji * wi
                N[ci, ti] += cross
                N[ti, ci] += cross.T
                N[ti, ti] += Ji.T @ Ji * wi
                rhs[ti] -= Ji.T @ R[m, i] * wi
        # Priors: (C - C0)/σ_p and θ/σ_θ; the unexcited channel directions held at nominal.
        p_c = 1.0 / prior.ravel() ** 2
        N[:n_c, :n_c] += np.diag(p_c)
        rhs[:n_c] -= (x0[:n_c] - C0.ravel()) * p_c
        for i in range(6):
            ci = slice(i * n_ch, (i + 1) * n_ch)
            hold = null_proj / prior[i][:, None] / prior[i][None, :] * HOLD_WEIGHT
            N[ci, ci] += hold
            rhs[ci] -= hold @ (C[i] - C0[i])
        if sites:
            N[n_c:, n_c:] += np.diag(1.0 / prior_theta ** 2)
            rhs[n_c:] -= x0[n_c:] / prior_theta ** 2
            # The sites' mean angle is held at zero: the common part is crosstalk.
            for a in range(2):
                e = np.zeros(n_x)
                e[n_c + a::2] = 1.0
                N += np.outer(e, e) / MEAN_ANGLE_SIGMA_RAD ** 2
                rhs -= e * (e @ x0) / MEAN_ANGLE_SIGMA_RAD ** 2
        # Solve in units of the prior standard deviations (the prior block becomes the
        # identity), by eigen-decomposition: the directions the data do not reach keep their
        # prior accurately however stiff the others are.
        D = np.concatenate([prior.ravel(), prior_theta])
        lam, Q = np.linalg.eigh(N * D[:, None] * D[None, :])
        lam = np.maximum(lam, 1e-12)
        cov_scaled = (Q / lam) @ Q.T
        cov = cov_scaled * D[:, None] * D[None, :]
        step = D * (cov_scaled @ (D * rhs))
        x = x0 + step
        C = x[:n_c].reshape(6, n_ch)
        for q, k in enumerate(sites):
            angles[s.site_names[k]][:2] = x[n_c + 2 * q:n_c + 2 * q + 2]
        W = s.w_ref.copy()
        for k in np.unique(s.site):
            m = s.site == k
            W[m] = rotate_reference(s.w_ref[m], s.p_ref[m], origin,
                                    small_rotation(angles[s.site_names[k]]))
        resid = V @ C.T - W
        rms = np.sqrt(np.mean(resid ** 2, axis=0))
        sigma = np.maximum(rms, RESIDUAL_FLOOR_FS * fs)
        if np.max(np.abs(step[n_c:]), initial=0.0) < 1e-9 and done > 1:
            break
    se = np.sqrt(np.abs(np.diag(cov)[:n_c])).reshape(6, n_ch)
    # A column along an unexcited direction is held, not known: its uncertainty is the prior.
    held = np.broadcast_to(unexcited_share > MAX_UNEXCITED_SHARE, se.shape)
    se = np.where(held, prior, se)
    identified = (se < IDENTIFIED_RATIO * prior) & ~held
    return LinearFit(C, se, identified, {s.site_names[k]: angles[s.site_names[k]]
                                         for k in np.unique(s.site)}, rms, done)


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
    #: Degree of the Fz gain's polynomial in (u, v): 2, or the COP's degree when the sites
    #: support fewer terms (:func:`fit_nonlinear`).
    gain_degree: int = 2
    cross_validation_mm: dict[int, float] = field(default_factory=dict)

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
        px = cop[ok, 0] + (T @ self.cop_x if self.degree > 0 else 0.0)
        py = cop[ok, 1] + (T @ self.cop_y if self.degree > 0 else 0.0)
        f = w_lin[ok, :3].copy()
        fz = f[:, 2]
        f[:, 2] = fz * (1.0 + _poly_terms(u, v, self.gain_degree) @ self.gain
                        + self.fz_quadratic * fz / self.full_scale_fz_n)
        ox, oy, oz = self.origin_m
        out[ok, :3] = f
        out[ok, 3] = (py - oy) * f[:, 2] + oz * f[:, 1]
        out[ok, 4] = -oz * f[:, 0] - (px - ox) * f[:, 2]
        out[ok, 5] = tz[ok] + (px - ox) * f[:, 1] - (py - oy) * f[:, 0]
        return out

    @classmethod
    def from_record(cls, entry: dict, origin_m: tuple[float, float, float]
                    ) -> NonlinearCorrection:
        """Rebuild the correction from the record's ``nonlinear_correction`` block."""
        return cls(int(entry["degree"]), tuple(entry["half_size_m"]),
                   origin_m, np.array(entry["cop_x_m"]), np.array(entry["cop_y_m"]),
                   np.array(entry["fz_gain"]), float(entry["fz_quadratic"]),
                   float(entry["full_scale_fz_n"]),
                   gain_degree=int(entry.get("fz_gain_degree", 2)))

    def record_entry(self) -> dict:
        return {"model": "polynomial_cop_correction", "degree": self.degree,
                "variables": "u = COPx/half_x, v = COPy/half_y of the linearly calibrated COP; "
                             "terms u^i v^j, i + j <= degree, ordered by i then j",
                "half_size_m": list(self.half_size_m), "cop_x_m": self.cop_x.tolist(),
                "cop_y_m": self.cop_y.tolist(), "fz_gain_degree": self.gain_degree,
                "fz_gain": self.gain.tolist(), "fz_quadratic": self.fz_quadratic,
                "full_scale_fz_n": self.full_scale_fz_n,
                "degree_cross_validation_mm": {str(k): v
                                               for k, v in self.cross_validation_mm.items()},
                "applies_to": "wrench = cal_matrix · channels, then COP and Fz corrected, "
                              "moments recomputed about O with the free moment kept"}


def _n_terms(degree: int) -> int:
    return (degree + 1) * (degree + 2) // 2


def _cop_polys(T: np.ndarray, target: np.ndarray) -> np.ndarray:
    coef, *_ = np.linalg.lstsq(T, target, rcond=None)
    return coef


def choose_degree(u: np.ndarray, v: np.ndarray, dx: np.ndarray, dy: np.ndarray,
                  site: np.ndarray, max_degree: int) -> tuple[int, dict[int, float]]:
    """The COP polynomial's degree by leave-one-site-out cross-validation (RMS COP error of
    each left-out site predicted from the others, m); degrees whose term count would not
    leave at least two sites over are not tried."""
    sites = np.unique(site)
    scores: dict[int, float] = {}
    for d in range(1, max_degree + 1):
        if _n_terms(d) > len(sites) - 2:
            break
        err = []
        for k in sites:
            out = site == k
            T = _poly_terms(u[~out], v[~out], d)
            T_out = _poly_terms(u[out], v[out], d)
            ex = T_out @ _cop_polys(T, dx[~out]) - dx[out]
            ey = T_out @ _cop_polys(T, dy[~out]) - dy[out]
            err.append(np.concatenate([ex, ey]))
        scores[d] = float(np.sqrt(np.mean(np.concatenate(err) ** 2)))
    if not scores:
        return 0, scores
    return min(scores, key=lambda d: scores[d]), scores


def fit_nonlinear(plate: PlateDescription, lin: LinearFit, s: Samples, degree: int = 3
                  ) -> NonlinearCorrection:
    """The position-dependent stage on training samples ``s`` (module docstring); ``degree``
    is the highest tried, the one used is chosen by leave-one-site-out cross-validation
    (:func:`choose_degree`); 0 (no COP correction) when the sites are too few."""
    hx, hy = plate.size_m[0] / 2, plate.size_m[1] / 2
    w_lin = s.v @ lin.C.T
    cop, _ = cop_F(w_lin, plate.origin_m)
    use = (s.w_ref[:, 2] >= COP_MIN_LOAD_N) & np.isfinite(cop[:, 0])
    u, v = cop[use, 0] / hx, cop[use, 1] / hy
    dx, dy = s.p_ref[use, 0] - cop[use, 0], s.p_ref[use, 1] - cop[use, 1]
    chosen, scores = choose_degree(u, v, dx, dy, s.site[use], degree)
    corr = NonlinearCorrection(chosen, (hx, hy), tuple(plate.origin_m),  # type: ignore[arg-type]
                               full_scale_fz_n=float(plate.force_range_n[2]))
    corr.cross_validation_mm = {d: e * 1e3 for d, e in scores.items()}
    T = _poly_terms(u, v, chosen)
    if chosen == 0:
        corr.cop_x = corr.cop_y = np.zeros(1)
    else:
        corr.cop_x, corr.cop_y = _cop_polys(T, dx), _cop_polys(T, dy)
    fz = w_lin[use, 2]
    # The gain's polynomial is capped by the degree the sites support (the cross-validated
    # COP degree): with few sites (a 2×2 grid and corners) u² and v² barely vary over the
    # fitted sites, a full quadratic gain is collinear with the constant, and it extrapolated
    # to the held-out sites by tens of % of Fz (seen on a kistler8 twin campaign).
    corr.gain_degree = min(2, chosen)
    G = np.column_stack([_poly_terms(u, v, corr.gain_degree) * fz[:, None],
                         fz ** 2 / corr.full_scale_fz_n])
    coef, *_ = np.linalg.lstsq(G, s.w_ref[use, 2] - fz, rcond=None)
    corr.gain, corr.fz_quadratic = coef[:-1], float(coef[-1])
    return corr
