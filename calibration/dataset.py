"""From raw trials to the fit's samples: reference wrench in the plate frame, zeroing, clocks.

For each trial:

1. Zero both sensors on the unloaded baselines at the start and the end of the trial (the
   offset interpolated linearly in between removes the slow drift of both).
2. The reference: the ATI's wrench is the environment's on the platform at S, so the load on
   the plate is ``-ati``; it is rotated into F (``R_FS = R_BFᵀ R_BS``) and its moment moved to
   the plate's stated transducer origin O: ``M_O = R_FS m_S + (p_S - O) × F``. The load's point
   (the tool tip, ``tool_length`` along S's z) in F is the reference centre of pressure.
3. The plate's samples are put on the robot's clock (:mod:`calibration.alignment`) and
   interpolated at the robot's sample times; an instant in a gap of the plate's scans longer
   than :data:`MAX_PLATE_GAP_S` is not (its block is dropped).
4. Block means over ``block_s`` (default 20 ms): the fit works on these (less noise, less
   data; the loads change slowly against 20 ms).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calibration.alignment import ClockModel, clock_model, trial_lag
from calibration.plate import PlateDescription
from calibration.trial import TrialData
from rt.errors import InputError

BLOCK_S = 0.02
#: Samples at the start/end of a trial averaged to zero the sensors (s).
BASELINE_S = 0.5
#: Below this reference load (N) a block is "unloaded" and not used.
MIN_LOAD_N = 20.0
#: A robot instant whose bracketing plate scans are further apart than this (s) is not
#: interpolated, and its block not used: a software-timed DAQ on a loaded host leaves gaps
#: (127 ms measured at a load of 20), and a straight line across a gap on a ramp is tens of N
#: off. 10 ms costs < 0.3 N on the plans' fastest ramps (raised cosine, 600 N in 0.4 s).
MAX_PLATE_GAP_S = 0.010
#: The same for the robot's rows (s): a late RT loop re-phases and skips cycles (92 ms seen at
#: a load of 14); a block spanning that is not a block of ``block_s``.
MAX_ROBOT_GAP_S = 0.010


@dataclass
class Samples:
    """Block-mean samples of many trials (one row per block)."""

    v: np.ndarray               # (n, N) plate channels, zeroed
    w_ref: np.ndarray           # (n, 6) reference wrench about O, axes of F
    p_ref: np.ndarray           # (n, 3) load point in F
    f_cmd: np.ndarray           # (n,) commanded force (N)
    trial: np.ndarray           # (n,) trial index
    site: np.ndarray            # (n,) site index
    trial_ids: list[str] = field(default_factory=list)
    site_names: list[str] = field(default_factory=list)

    def select(self, mask: np.ndarray) -> Samples:
        return Samples(self.v[mask], self.w_ref[mask], self.p_ref[mask], self.f_cmd[mask],
                       self.trial[mask], self.site[mask], self.trial_ids, self.site_names)

    def __len__(self) -> int:
        return len(self.f_cmd)


def _block_means(x: np.ndarray, m: int, n_per: int) -> np.ndarray:
    """Means of ``m`` consecutive blocks of ``n_per`` samples along the first axis."""
    x = x[:m * n_per]
    return x.reshape(m, n_per, *x.shape[1:]).mean(axis=1)


def _zeroed(t: np.ndarray, x: np.ndarray, span_s: float) -> np.ndarray:
    """x minus the offset line through its first and last ``span_s`` means."""
    head = t <= t[0] + span_s
    tail = t >= t[-1] - span_s
    x0, x1 = x[head].mean(axis=0), x[tail].mean(axis=0)
    t0, t1 = t[head].mean(), t[tail].mean()
    u = ((t - t0) / (t1 - t0))[:, None] if t1 > t0 else np.zeros((len(t), 1))
    return x - (x0 + (x1 - x0) * u)


def zeroed_channels(d: TrialData) -> np.ndarray:
    """The trial's plate channels zeroed on its unloaded baselines (module docstring, 1)."""
    return _zeroed(d.t_plate, d.channels, BASELINE_S)


def reference_in_plate(d: TrialData, origin_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(w_ref (n,6) about O in F, load point (n,3) in F) of a trial (module docstring)."""
    ati = _zeroed(d.t_robot, d.ati, BASELINE_S)
    R_FB = d.T_BF[:3, :3].T
    R_BS = d.R_BS.reshape(-1, 3, 3)
    R_FS = np.einsum("ij,njk->nik", R_FB, R_BS)
    f = -np.einsum("nij,nj->ni", R_FS, ati[:, :3])
    m = -np.einsum("nij,nj->ni", R_FS, ati[:, 3:])
    p_S = (d.p_BS - d.T_BF[:3, 3]) @ R_FB.T
    tip = p_S + d.tool_length_m * R_FS[:, :, 2]
    m_O = m + np.cross(p_S - origin_m, f)
    return np.hstack([f, m_O]), tip


def nominal_fz(plate: PlateDescription, channels: np.ndarray) -> np.ndarray:
    return channels @ plate.nominal_C()[2]


def align_clocks(plate: PlateDescription, trials: list[TrialData],
                 max_offset_s: float = 2.0) -> ClockModel:
    lags = []
    for d in trials:
        w, _ = reference_in_plate(d, np.array(plate.origin_m))
        lags.append(trial_lag(d.trial_id, d.t_robot, w[:, 2], d.t_plate,
                              nominal_fz(plate, zeroed_channels(d)),
                              max_offset_s))
    return clock_model(lags)


def build_samples(plate: PlateDescription, trials: list[TrialData], sites: list[str],
                  clock: ClockModel, block_s: float = BLOCK_S) -> Samples:
    """Block means of every trial's loaded part, on the robot's clock (module docstring)."""
    origin = np.array(plate.origin_m)
    site_names = sorted(set(sites))
    rows: dict[str, list[np.ndarray]] = {k: [] for k in ("v", "w", "p", "f", "trial", "site")}
    for k, (d, site) in enumerate(zip(trials, sites)):
        w, p = reference_in_plate(d, origin)
        v_plate = zeroed_channels(d)
        t_on_robot = clock.to_robot(d.t_plate)
        inside = (d.t_robot >= t_on_robot[0]) & (d.t_robot <= t_on_robot[-1])
        if inside.sum() < 10:
            raise InputError(f"trial {d.trial_id}: the plate's recording does not overlap the "
                             "robot's once the clocks are aligned")
        t = d.t_robot[inside]
        v = np.column_stack([np.interp(t, t_on_robot, v_plate[:, j])
                             for j in range(v_plate.shape[1])])
        right = np.clip(np.searchsorted(t_on_robot, t), 1, len(t_on_robot) - 1)
        bracketed = ((t_on_robot[right] - t_on_robot[right - 1]) <= MAX_PLATE_GAP_S) \
            & np.r_[True, np.diff(t) <= MAX_ROBOT_GAP_S]
        n_per = max(1, round(block_s / float(np.median(np.diff(t)))))
        m = len(t) // n_per
        if m == 0:
            continue
        whole = _block_means(bracketed.astype(float), m, n_per) == 1.0
        rows["v"].append(_block_means(v, m, n_per)[whole])
        rows["w"].append(_block_means(w[inside], m, n_per)[whole])
        rows["p"].append(_block_means(p[inside], m, n_per)[whole])
        rows["f"].append(_block_means(d.force_ref[inside], m, n_per)[whole])
        rows["trial"].append(np.full(int(whole.sum()), k))
        rows["site"].append(np.full(int(whole.sum()), site_names.index(site)))
    if not rows["v"]:
        raise InputError("no trial has data to fit")
    s = Samples(np.vstack(rows["v"]), np.vstack(rows["w"]), np.vstack(rows["p"]),
                np.concatenate(rows["f"]), np.concatenate(rows["trial"]),
                np.concatenate(rows["site"]), [d.trial_id for d in trials], site_names)
    return s.select(s.w_ref[:, 2] >= MIN_LOAD_N)
