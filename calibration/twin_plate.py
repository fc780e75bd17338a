"""The digital twin's force plate: a plate whose truth is known, so a calibration can be judged.

What the truth holds (all drawn once from ``seed``, magnitudes configurable):

* sensitivity errors (diagonal, ±3 %) and crosstalk (off-diagonal, ±2 %) of the channels:
  ``v = (I + E) C_nom⁻¹ w_eff`` in the channels' units, so the matrix a perfect linear
  calibration finds is ``C_true = C_nom (I + E)⁻¹`` (about the true transducer origin);
* an offset of the true transducer origin from the one the plate's file states (mm);
* top-plate bending: the plate responds as if a load at p acted at ``p + δ(p)``, δ growing
  towards the edges (``bending_corner_mm`` at the corners, odd in x and y, not polynomial);
* mild nonlinearity (``v += k v |v| / range``) and hysteresis (a play operator of half-width
  ``hysteresis`` × range) per channel;
* noise (V, white), zero offset and drift (V/s), 16-bit quantization over ± range;
* its own clock: ``t_plate = clock_offset_s + (1 + clock_drift_ppm 1e-6) t_robot``.

:meth:`TwinPlate.sample` turns the true load (force in F at a point of F, at robot times) into
the channels a DAQ would have recorded at the plate's sample rate on the plate's clock.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from calibration.plate import PlateDescription, wrench_at_point

DAQ_BITS = 16


@dataclass(frozen=True)
class TruthSettings:
    """Magnitudes of the twin plate's imperfections (module docstring)."""

    sensitivity: float = 0.03
    crosstalk: float = 0.02
    origin_offset_mm: tuple[float, float, float] = (1.5, -2.0, 3.0)
    bending_corner_mm: float = 10.0
    bending_shape: float = 2.0
    nonlinearity: float = 0.003
    hysteresis: float = 0.0001
    noise_v: float = 5e-4
    zero_offset_v: float = 5e-3
    drift_v_per_s: float = 2e-5
    quantize: bool = True
    clock_offset_s: float = 0.2371
    clock_drift_ppm: float = 80.0

    @classmethod
    def ideal(cls, **overrides: float) -> TruthSettings:
        """A plate that is exactly linear (for exact-recovery tests): no bending, noise,
        nonlinearity, hysteresis, drift, quantization or clock error."""
        base = {"origin_offset_mm": (1.5, -2.0, 3.0), "bending_corner_mm": 0.0,
                    "nonlinearity": 0.0, "hysteresis": 0.0, "noise_v": 0.0, "zero_offset_v": 0.0,
                    "drift_v_per_s": 0.0, "quantize": False, "clock_offset_s": 0.0, "clock_drift_ppm": 0.0}
        base.update(overrides)
        return cls(**base)  # type: ignore[arg-type]


@dataclass
class PlateTruth:
    """The drawn truth (module docstring). ``E`` is N×N, ``origin_true_m`` in F."""

    settings: TruthSettings
    E: np.ndarray
    origin_true_m: np.ndarray
    zero_offset_v: np.ndarray
    drift_v_per_s: np.ndarray
    C_true: np.ndarray = field(default_factory=lambda: np.zeros((6, 6)))

    def bending_F(self, plate: PlateDescription, point_F: np.ndarray) -> np.ndarray:
        """δ(p) (m) for points (..., 3) of F: where the plate 'feels' a load at p."""
        s = self.settings
        out = np.zeros_like(point_F)
        if s.bending_corner_mm == 0.0:
            return out
        hx, hy = plate.size_m[0] / 2, plate.size_m[1] / 2
        u, w = point_F[..., 0] / hx, point_F[..., 1] / hy
        k = s.bending_shape
        gx = np.sinh(k * u) / math.sinh(k) * (0.7 + 0.3 * w * w)
        gy = np.sinh(k * w) / math.sinh(k) * (0.7 + 0.3 * u * u)
        # 10 mm at a corner split along the diagonal.
        corner = s.bending_corner_mm * 1e-3
        out[..., 0] = corner * hx / math.hypot(hx, hy) * gx
        out[..., 1] = corner * hy / math.hypot(hx, hy) * gy
        return out


def draw_truth(plate: PlateDescription, settings: TruthSettings | None = None,
               seed: int = 12) -> PlateTruth:
    """Draw a plate truth; the same seed gives the same plate."""
    s = settings or TruthSettings()
    rng = np.random.default_rng(seed)
    n = plate.n_channels
    E = rng.uniform(-s.crosstalk, s.crosstalk, (n, n))
    np.fill_diagonal(E, rng.uniform(-s.sensitivity, s.sensitivity, n))
    origin = np.array(plate.origin_m) + np.array(s.origin_offset_mm) * 1e-3
    ranges = plate.channel_ranges()
    truth = PlateTruth(
        settings=s, E=E, origin_true_m=origin,
        zero_offset_v=rng.uniform(-1.0, 1.0, n) * s.zero_offset_v,
        drift_v_per_s=rng.uniform(-1.0, 1.0, n) * s.drift_v_per_s * ranges / ranges.max())
    C_nom = plate.nominal_C()
    # v = (I+E) C_nom⁺ w  ⇒  w = C_nom (I+E)⁻¹ v on the range of C_nom⁺.
    truth.C_true = C_nom @ np.linalg.inv(np.eye(n) + E)
    return truth


def expected_matrix(plate: PlateDescription, truth: PlateTruth) -> np.ndarray:
    """The matrix a perfect linear calibration finds for a bending-free plate: C_true with its
    moments moved from the true origin to the stated one (``origin_m``)."""
    d = truth.origin_true_m - np.array(plate.origin_m)
    shift = np.eye(6)
    # M about O_nom = M about O_true + (O_true - O_nom) × F
    shift[3:, :3] = np.array([[0.0, -d[2], d[1]], [d[2], 0.0, -d[0]], [-d[1], d[0], 0.0]])
    return shift @ truth.C_true


class TwinPlate:
    """Turns true loads into recorded channels (module docstring)."""

    def __init__(self, plate: PlateDescription, truth: PlateTruth, seed: int = 0) -> None:
        self.plate = plate
        self.truth = truth
        self.rng = np.random.default_rng(seed)
        self._to_channels = (np.eye(plate.n_channels) + truth.E) @ np.linalg.pinv(plate.nominal_C())
        self.ranges = plate.channel_ranges()

    def plate_time(self, t_robot: np.ndarray | float) -> np.ndarray:
        s = self.truth.settings
        return s.clock_offset_s + (1.0 + s.clock_drift_ppm * 1e-6) * np.asarray(t_robot)

    def robot_time(self, t_plate: np.ndarray) -> np.ndarray:
        s = self.truth.settings
        return (np.asarray(t_plate) - s.clock_offset_s) / (1.0 + s.clock_drift_ppm * 1e-6)

    def channels(self, force_F: np.ndarray, point_F: np.ndarray,
                 t_plate: np.ndarray, quantized: bool = True,
                 play_state: np.ndarray | None = None) -> np.ndarray:
        """Channel values (n, N) for loads (n, 3) at points (n, 3), at plate times (n,).

        ``quantized=False`` leaves the 16-bit quantization to a DAQ that reads the values (the
        twin plate behind a comedi double, :mod:`calibration.twin_plate_daq`); ``play_state``
        (N,) carries the hysteresis across calls that feed one sample at a time (updated in
        place; None: the loop starts at the first sample)."""
        s = self.truth.settings
        felt = point_F + self.truth.bending_F(self.plate, point_F)
        w_eff = wrench_at_point(force_F, felt, self.truth.origin_true_m)
        v = w_eff @ self._to_channels.T
        if s.nonlinearity:
            v = v + s.nonlinearity * v * np.abs(v) / self.ranges
        if s.hysteresis:
            v = _play(v, s.hysteresis * self.ranges, play_state)
        v = v + self.truth.zero_offset_v + np.outer(t_plate, self.truth.drift_v_per_s)
        if s.noise_v:
            v = v + self.rng.normal(0.0, s.noise_v, v.shape)
        if s.quantize and quantized:
            v = quantize(v, self.ranges)
        return v

    def sample(self, t_robot: np.ndarray, force_F: np.ndarray, point_F: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """Record a trial: (t_plate (m,), channels (m, N)) at the plate's rate on its clock,
        covering the robot-time span of ``t_robot`` (loads interpolated linearly)."""
        fs = self.plate.sample_rate_hz
        tp0, tp1 = self.plate_time(t_robot[0]), self.plate_time(t_robot[-1])
        k0, k1 = math.ceil(tp0 * fs - 1e-9), math.floor(tp1 * fs + 1e-9)
        t_plate = np.arange(k0, k1 + 1) / fs
        tr = self.robot_time(t_plate)
        f = np.column_stack([np.interp(tr, t_robot, force_F[:, k]) for k in range(3)])
        p = np.column_stack([np.interp(tr, t_robot, point_F[:, k]) for k in range(3)])
        return t_plate, self.channels(f, p, t_plate)


def quantize(v: np.ndarray, ranges: np.ndarray, bits: int = DAQ_BITS) -> np.ndarray:
    """A bipolar ``bits`` ADC over ± range: round to the code, clip, back to the unit."""
    top = 2 ** bits - 1
    code = np.clip(np.rint((v + ranges) / (2.0 * ranges) * top), 0, top)
    return code / top * 2.0 * ranges - ranges


def _play(v: np.ndarray, half_width: np.ndarray, state: np.ndarray | None = None
          ) -> np.ndarray:
    """Play (backlash) operator per column: the output moves only when the input pulls it
    further than ``half_width`` — a rate-independent hysteresis loop of width 2 half_width.
    ``state``: the output before ``v[0]`` (updated in place); None starts at ``v[0]``."""
    out = np.empty_like(v)
    y = v[0].copy() if state is None or not np.isfinite(state).all() else state.copy()
    for k in range(v.shape[0]):
        y = np.minimum(np.maximum(y, v[k] - half_width), v[k] + half_width)
        out[k] = y
    if state is not None:
        state[:] = y
    return out
