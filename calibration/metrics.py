"""Accuracy figures of a plate against the reference, and the verdict (ASTM F3109, CalTester).

All on block-mean samples (``calibration.dataset``), for one stage's wrenches ``w_plate``:

* ``force_pct_fs`` [6] — max |error| per axis over loaded samples, % of the axis's full scale;
* ``force_pct_applied`` [6] — max |error| per axis / |applied force| (samples ≥ 150 N), %;
* ``cop_rms_mm``, ``cop_max_mm`` — distance between the plate's COP and the load point,
  samples with Fz ≥ 150 N (CalTester uses ≥ 200 N loads);
* ``crosstalk_pct`` — max |Fx|, |Fy| error per applied Fz, %;
* ``linearity_pct_fs`` — max deviation of the static plateaus' Fz from their best line (per
  trial, loading branch), % FS;
* ``hysteresis_pct_fs`` — max difference of the Fz error between the loading and unloading
  plateaus of one level, % FS;
* ``repeatability_pct_fs`` — max spread of the Fz error at one level and site over repeated
  trials, % FS (null when the samples hold no repeat).
"""
from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from calibration.dataset import Samples
from calibration.plate import PlateDescription, cop_F

COP_MIN_LOAD_N = 150.0
#: A block belongs to a static plateau when its commanded force is this close to a load level.
PLATEAU_TOLERANCE_N = 0.5


@dataclass(frozen=True)
class Thresholds:
    """Acceptance thresholds (configurable on the command line)."""

    cop_rms_mm: float = 1.0
    cop_max_mm: float = 3.0
    force_pct_fs: float = 0.5
    crosstalk_pct: float = 1.0

    def record_entry(self) -> dict:
        return {"cop_rms_mm": self.cop_rms_mm, "cop_max_mm": self.cop_max_mm,
                "force_pct_fs": self.force_pct_fs, "crosstalk_pct": self.crosstalk_pct,
                "force_pct_fs_axes": ["Fx", "Fy", "Fz"]}


def _nan_to_none(x: float) -> float | None:
    return None if not math.isfinite(x) else float(x)


def _plateaus(s: Samples, levels: list[float]) -> dict[tuple[int, float, int], np.ndarray]:
    """(trial, level, branch 0 up / 1 down) → sample indices of that static plateau."""
    out: dict[tuple[int, float, int], list[int]] = defaultdict(list)
    for trial in np.unique(s.trial):
        idx = np.flatnonzero(s.trial == trial)
        seen: dict[float, int] = {}
        prev_level: float | None = None
        for i in idx:
            hit = [lv for lv in levels if abs(s.f_cmd[i] - lv) <= PLATEAU_TOLERANCE_N]
            level = hit[0] if hit else None
            if level is not None and level != prev_level:
                seen[level] = seen.get(level, -1) + 1
            if level is not None and seen[level] <= 1:
                out[(int(trial), level, seen[level])].append(int(i))
            prev_level = level
    return {k: np.array(v) for k, v in out.items() if len(v) >= 3}


def stage_metrics(plate: PlateDescription, s: Samples, w_plate: np.ndarray,
                  levels: list[float]) -> dict:
    """The metrics block ``M`` of the record for one stage (module docstring)."""
    fs = plate.full_scale()
    e = w_plate - s.w_ref
    f_mag = np.linalg.norm(s.w_ref[:, :3], axis=1)
    big = s.w_ref[:, 2] >= COP_MIN_LOAD_N
    out: dict = {"samples": len(s), "cop_samples": int(big.sum())}
    out["force_pct_fs"] = (np.max(np.abs(e), axis=0) / fs * 100.0).tolist() if len(s) \
        else [None] * 6
    out["force_pct_applied"] = (np.max(np.abs(e[big]) / f_mag[big, None], axis=0) * 100.0
                                ).tolist() if big.any() else [None] * 6
    cop, _ = cop_F(w_plate, plate.origin_m)
    d = np.linalg.norm(cop[big] - s.p_ref[big, :2], axis=1) * 1e3
    out["cop_rms_mm"] = _nan_to_none(float(np.sqrt(np.mean(d ** 2)))) if d.size else None
    out["cop_max_mm"] = _nan_to_none(float(np.max(d))) if d.size else None
    out["crosstalk_pct"] = float(np.max(np.abs(e[big, :2]) / s.w_ref[big, 2:3]) * 100.0) \
        if big.any() else None
    plat = _plateaus(s, levels)
    lin, hyst = [], []
    by_trial: dict[int, list[tuple[float, float]]] = defaultdict(list)
    err_at: dict[tuple[int, float], dict[int, float]] = defaultdict(dict)
    for (trial, level, branch), idx in plat.items():
        ref, meas = float(np.mean(s.w_ref[idx, 2])), float(np.mean(w_plate[idx, 2]))
        err_at[(trial, level)][branch] = meas - ref
        if branch == 0:
            by_trial[trial].append((ref, meas))
    for pts in by_trial.values():
        if len(pts) >= 3:
            x, y = np.array(pts).T
            a, b = np.polyfit(x, y, 1)
            lin.append(float(np.max(np.abs(y - (a * x + b)))))
    for errs in err_at.values():
        if 0 in errs and 1 in errs:
            hyst.append(abs(errs[0] - errs[1]))
    out["linearity_pct_fs"] = max(lin) / fs[2] * 100.0 if lin else None
    out["hysteresis_pct_fs"] = max(hyst) / fs[2] * 100.0 if hyst else None
    # Repeats: the same site and level in several trials of the same profile.
    groups: dict[tuple[int, float], list[float]] = defaultdict(list)
    for (trial, level), errs in err_at.items():
        if 0 in errs:
            groups[(int(s.site[np.flatnonzero(s.trial == trial)[0]]), level)].append(errs[0])
    spreads = [max(v) - min(v) for v in groups.values() if len(v) >= 2]
    out["repeatability_pct_fs"] = max(spreads) / fs[2] * 100.0 if spreads else None
    return out


def verdict(m: dict, thresholds: Thresholds, stage: str) -> dict:
    """Pass/fail of one stage's metrics against the thresholds; ``failed`` names the figures."""
    failed = []
    force = [x for x in m["force_pct_fs"][:3] if x is not None]
    for name, value, limit in (("cop_rms_mm", m["cop_rms_mm"], thresholds.cop_rms_mm),
                               ("cop_max_mm", m["cop_max_mm"], thresholds.cop_max_mm),
                               ("force_pct_fs", max(force) if force else None,
                                thresholds.force_pct_fs),
                               ("crosstalk_pct", m["crosstalk_pct"], thresholds.crosstalk_pct)):
        if value is None or not value <= limit:
            failed.append(name)
    return {"pass": not failed, "stage": stage, "failed": failed}


@dataclass
class CopMap:
    x_m: list[float] = field(default_factory=list)
    y_m: list[float] = field(default_factory=list)
    grids: dict[str, list[list[float | None]]] = field(default_factory=dict)


def cop_error_map(plate: PlateDescription, s: Samples, stages: dict[str, np.ndarray],
                  site_xy: dict[str, tuple[float, float]]) -> CopMap:
    """Mean COP error (mm) per site on the grid of the sites' distinct x and y; None where no
    site lies."""
    xs = sorted({round(xy[0], 6) for xy in site_xy.values()})
    ys = sorted({round(xy[1], 6) for xy in site_xy.values()})
    out = CopMap(xs, ys)
    big = s.w_ref[:, 2] >= COP_MIN_LOAD_N
    for stage, w in stages.items():
        cop, _ = cop_F(w, plate.origin_m)
        err = np.linalg.norm(cop - s.p_ref[:, :2], axis=1) * 1e3
        grid: list[list[float | None]] = [[None] * len(xs) for _ in ys]
        for k, name in enumerate(s.site_names):
            m = big & (s.site == k) & np.isfinite(err)
            if name in site_xy and m.any():
                x, y = site_xy[name]
                grid[ys.index(round(y, 6))][xs.index(round(x, 6))] = float(np.mean(err[m]))
        out.grids[stage] = grid
    return out
