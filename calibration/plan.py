"""The loading plan of a calibration campaign (``talus calibrate plan``).

A plan file (YAML or JSON, ``schema_version: 1``) names the plate file, the sites (a grid over
the working surface plus the corners, and held-out validation sites between them), the load
levels and which profiles run where. :func:`expand` turns it into the list of trials; every
trial's force profile is :func:`force_profile` (N, ≥ 0, positive pressing the plate).

Profiles (all start and end with ``baseline_s`` unloaded, used to zero both sensors):

* ``steps`` — static steps up through every load level, then down again (hysteresis), each
  reached by a raised-cosine ramp of ``ramp_s`` and held ``hold_s`` (CalTester, ASTM F3109).
* ``sine`` — mean ± amplitude at ``frequency_hz`` for ``cycles``, cosine ramps in and out.
* ``gait`` — a gait-like double-hump vertical force (heel strike, mid-stance valley, push off)
  of ``peak_n`` over ``stance_s``, repeated on a small preload (the tool keeps contact).
* ``tilted`` — static steps with the platform tilted (roll, pitch): the load's line of action
  and its point move, exciting the moments (and shear where the contact's friction allows).
* ``shear`` — a push at the level pose, then, under load, the platform tilts by (roll, pitch)
  and back (:func:`tilt_profile`): the tool tip, stuck to the plate by static friction, is
  dragged sideways and loads the plate in shear up to the friction cone, the excitation the
  Fx/Fy columns need (a 3-PRS cannot push sideways). Off unless the plan lists ``shear``.

Held-out sites and trials are never used by the fit; the metrics are computed on them.
"""
from __future__ import annotations

import math
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from calibration import yaml_files

Pos = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
Load = Annotated[float, Field(gt=0.0, le=5000.0, allow_inf_nan=False)]
Tilt = Annotated[float, Field(ge=-10.0, le=10.0, allow_inf_nan=False)]


class ProfileKind(StrEnum):
    STEPS = "steps"
    SINE = "sine"
    GAIT = "gait"
    TILTED = "tilted"
    SHEAR = "shear"


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Grid(_Model):
    """``nx`` × ``ny`` sites inset ``margin_m`` from the edges, plus the four corners inset
    ``corner_margin_m``; held-out sites: the centres of the grid's cells and the midpoints of
    its outer edges pushed half-way to the plate's edge."""

    nx: Annotated[int, Field(ge=2, le=15)] = 3
    ny: Annotated[int, Field(ge=2, le=15)] = 3
    margin_m: Pos = 0.10
    corners: bool = True
    corner_margin_m: Pos = 0.03
    held_out: bool = True


class Steps(_Model):
    ramp_s: Pos = 0.4
    hold_s: Pos = 1.0


class Sine(_Model):
    mean_n: Load = 700.0
    amplitude_n: Load = 500.0
    frequency_hz: Annotated[float, Field(gt=0.0, le=5.0)] = 1.0
    cycles: Annotated[int, Field(ge=1, le=100)] = 3


class Gait(_Model):
    """Stances of ``stance_s`` peaking at ``peak_n``, separated by ``rest_s`` at ``preload_n``
    (the tool stays in contact: a robot pressing a rigid plate must not let go and come
    back between steps)."""

    peak_n: Load = 1200.0
    stance_s: Annotated[float, Field(ge=0.3, le=3.0)] = 1.0
    repetitions: Annotated[int, Field(ge=1, le=20)] = 3
    rest_s: Pos = 0.5
    preload_n: Annotated[float, Field(ge=0.0, le=500.0)] = 50.0


class TiltedPush(_Model):
    roll_deg: Tilt = 0.0
    pitch_deg: Tilt = 0.0
    load_n: Load = 600.0


class ShearPush(_Model):
    """Load ``load_n`` at the level pose, then tilt by (roll, pitch) under load and back."""

    roll_deg: Tilt = 1.5
    pitch_deg: Tilt = 0.0
    load_n: Load = 600.0
    #: Slow on purpose: the sliders' reference speed stays below the supervisor's frozen-encoder
    #: threshold (4 mm/s), because an axis stalled by the contact under load reads as a frozen
    #: encoder there (the closing note of issue 12 describes the case; issue 15).
    tilt_ramp_s: Pos = 5.0
    hold_s: Pos = 1.0


class Plan(_Model):
    """A campaign's plan (module docstring). Lengths in m, forces in N, angles in degrees."""

    schema_version: Literal[1]
    name: str = "Default calibration campaign"
    plate_file: str = "twin"
    loads_n: list[Load] = Field(default_factory=lambda: [200.0, 500.0, 1000.0, 1500.0],
                                min_length=1, max_length=20)
    baseline_s: Pos = 1.0
    grid: Grid = Grid()
    steps: Steps = Steps()
    sine: Sine = Sine()
    gait: Gait = Gait()
    tilted: list[TiltedPush] = Field(default_factory=lambda: [
        TiltedPush(roll_deg=2.0), TiltedPush(roll_deg=-2.0), TiltedPush(pitch_deg=2.0),
        TiltedPush(pitch_deg=-2.0)])
    shear: list[ShearPush] = Field(default_factory=list, max_length=8)
    sine_sites: Literal["centre_and_corners", "centre", "none"] = "centre_and_corners"
    gait_sites: Literal["centre", "none"] = "centre"
    repeat_centre_steps: bool = True
    pose_z_m: Annotated[float, Field(gt=0.4, lt=1.0)] = 0.63
    registration: Literal["nominal", "camera"] = "camera"
    #: The plate and the robot's base are levelled to within this (deg, 1 σ); the camera's
    #: tilt estimate is fused with it. null: not levelled, the camera's tilt alone.
    level_sigma_deg: Annotated[float, Field(gt=0.0, le=5.0)] | None = 0.1

    def level_sigma_rad(self) -> float | None:
        return None if self.level_sigma_deg is None else math.radians(self.level_sigma_deg)

    @field_validator("loads_n")
    @classmethod
    def _sorted_loads(cls, loads: list[float]) -> list[float]:
        if list(loads) != sorted(set(loads)):
            raise ValueError("must be strictly increasing (steps go up through them, then "
                             "down)")
        return loads


class Site(_Model):
    name: str
    x_m: float
    y_m: float
    held_out: bool


class Trial(_Model):
    """One trial: a profile at a site. ``load_n`` is the tilted push's load."""

    id: str
    site: str
    site_xy_m: tuple[float, float]
    profile: ProfileKind
    held_out: bool
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    load_n: float = 0.0


def sites(plan: Plan, size_m: tuple[float, float]) -> list[Site]:
    """The plan's sites on a plate of ``size_m`` (m); names G<i><j>, K<corner>, H<i>."""
    g = plan.grid
    hx, hy = size_m[0] / 2, size_m[1] / 2
    if g.margin_m >= min(hx, hy) or g.corner_margin_m >= min(hx, hy):
        raise ValueError(f"grid margins must be smaller than half the plate ({hx:.3f} m x "
                         f"{hy:.3f} m)")
    xs = np.linspace(-hx + g.margin_m, hx - g.margin_m, g.nx)
    ys = np.linspace(-hy + g.margin_m, hy - g.margin_m, g.ny)
    out = [Site(name=f"G{i}{j}", x_m=float(x), y_m=float(y), held_out=False)
           for j, y in enumerate(ys) for i, x in enumerate(xs)]
    if g.corners:
        cx, cy = hx - g.corner_margin_m, hy - g.corner_margin_m
        out += [Site(name=f"K{k}", x_m=sx * cx, y_m=sy * cy, held_out=False)
                for k, (sx, sy) in enumerate(((1, 1), (-1, 1), (-1, -1), (1, -1)))]
    if g.held_out:
        held = [((xs[i] + xs[i + 1]) / 2, (ys[j] + ys[j + 1]) / 2)
                for j in range(g.ny - 1) for i in range(g.nx - 1)]
        ex, ey = (xs[-1] + hx) / 2, (ys[-1] + hy) / 2
        held += [(ex, 0.0), (-ex, 0.0), (0.0, ey), (0.0, -ey)]
        out += [Site(name=f"H{k}", x_m=float(x), y_m=float(y), held_out=True)
                for k, (x, y) in enumerate(held)]
    return out


def expand(plan: Plan, size_m: tuple[float, float]) -> list[Trial]:
    """Every trial of the plan, in the order they run."""
    trials: list[Trial] = []

    def add(site: Site, profile: ProfileKind, suffix: str = "", **kw: float) -> None:
        trials.append(Trial(id=f"{site.name}-{profile.value}{suffix}", site=site.name,
                            site_xy_m=(site.x_m, site.y_m), profile=profile,
                            held_out=site.held_out, **kw))

    all_sites = sites(plan, size_m)
    centre = min((s for s in all_sites if not s.held_out), key=lambda s: math.hypot(s.x_m, s.y_m))
    for site in all_sites:
        add(site, ProfileKind.STEPS)
        if site is centre:
            if plan.repeat_centre_steps:
                add(site, ProfileKind.STEPS, "-2")
            for k, tp in enumerate(plan.tilted):
                add(site, ProfileKind.TILTED, f"-{k}", roll_deg=tp.roll_deg,
                    pitch_deg=tp.pitch_deg, load_n=tp.load_n)
            for k, sp in enumerate(plan.shear):
                add(site, ProfileKind.SHEAR, f"-{k}", roll_deg=sp.roll_deg,
                    pitch_deg=sp.pitch_deg, load_n=sp.load_n)
            if plan.gait_sites == "centre":
                add(site, ProfileKind.GAIT)
        if plan.sine_sites != "none" and (site is centre or (
                plan.sine_sites == "centre_and_corners" and site.name.startswith("K"))):
            add(site, ProfileKind.SINE)
    # One held-out dynamic trial: gait at the first held-out site.
    held = [s for s in all_sites if s.held_out]
    if held and plan.gait_sites == "centre":
        add(held[0], ProfileKind.GAIT)
    return trials


def _smooth(t: np.ndarray, t0: float, duration: float) -> np.ndarray:
    """Raised-cosine step 0 → 1 from t0 over ``duration`` (zero slope at both ends)."""
    u = np.clip((t - t0) / duration, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(math.pi * u)


def _shear_push(plan: Plan, trial: Trial) -> ShearPush:
    k = int(trial.id.rsplit("-", 1)[1])
    if not 0 <= k < len(plan.shear):
        raise ValueError(f"trial {trial.id}: the plan has no shear push {k}")
    return plan.shear[k]


def _shear_times(plan: Plan, sp: ShearPush) -> tuple[float, float, float, float]:
    """(loaded at, tilt starts, tilt back at, unloading starts) in s from the trial's start."""
    b, ramp = plan.baseline_s, plan.steps.ramp_s
    loaded = b + ramp + plan.steps.hold_s
    back = loaded + sp.tilt_ramp_s + sp.hold_s
    return loaded, loaded, back, back + sp.tilt_ramp_s + plan.steps.hold_s


def trial_pose(plan: Plan, trial: Trial) -> tuple[float, float, float]:
    """The pose (z m, roll, pitch rad) the robot holds when the push starts (level for a shear
    push: it tilts under load)."""
    if trial.profile == ProfileKind.SHEAR:
        return plan.pose_z_m, 0.0, 0.0
    return plan.pose_z_m, math.radians(trial.roll_deg), math.radians(trial.pitch_deg)


def tilt_profile(plan: Plan, trial: Trial, dt: float) -> np.ndarray | None:
    """A shear push's tilt under load, (n, 2) roll, pitch in rad on the samples of
    :func:`force_profile` (raised-cosine ramps); None for the other profiles (pose held)."""
    if trial.profile != ProfileKind.SHEAR:
        return None
    sp = _shear_push(plan, trial)
    n = len(force_profile(plan, trial, dt))
    t = np.arange(n) * dt
    _, start, back, _ = _shear_times(plan, sp)
    shape = _smooth(t, start, sp.tilt_ramp_s) * (1.0 - _smooth(t, back, sp.tilt_ramp_s))
    return np.column_stack([shape * math.radians(trial.roll_deg),
                            shape * math.radians(trial.pitch_deg)])


def force_profile(plan: Plan, trial: Trial, dt: float) -> np.ndarray:
    """The trial's force reference (N) sampled every ``dt`` s from t = 0."""
    b = plan.baseline_s
    if trial.profile == ProfileKind.SHEAR:
        sp = _shear_push(plan, trial)
        ramp = plan.steps.ramp_s
        _, _, _, unload = _shear_times(plan, sp)
        duration = unload + ramp + b
        t = np.arange(round(duration / dt) + 1) * dt
        return np.maximum(trial.load_n * _smooth(t, b, ramp) * (1.0 - _smooth(t, unload, ramp)),
                          0.0)
    if trial.profile in (ProfileKind.STEPS, ProfileKind.TILTED):
        levels = list(plan.loads_n) if trial.profile == ProfileKind.STEPS else [trial.load_n]
        path = [*levels, *levels[-2::-1], 0.0]
        st = plan.steps
        duration = b + len(path) * (st.ramp_s + st.hold_s) + b
        t = np.arange(round(duration / dt) + 1) * dt
        f = np.zeros_like(t)
        prev, t0 = 0.0, b
        for level in path:
            f += (level - prev) * _smooth(t, t0, st.ramp_s)
            prev, t0 = level, t0 + st.ramp_s + st.hold_s
        return np.maximum(f, 0.0)
    if trial.profile == ProfileKind.SINE:
        s = plan.sine
        ramp = 1.0
        play = s.cycles / s.frequency_hz
        duration = b + ramp + play + ramp + b
        t = np.arange(round(duration / dt) + 1) * dt
        env = _smooth(t, b, ramp) * (1.0 - _smooth(t, b + ramp + play, ramp))
        phase = 2.0 * math.pi * s.frequency_hz * (t - b - ramp)
        inside = (t >= b + ramp) & (t <= b + ramp + play)
        return np.maximum(env * s.mean_n + np.where(inside, s.amplitude_n * np.sin(phase), 0.0),
                          0.0)
    g = plan.gait
    period = g.stance_s + g.rest_s
    ramp = 0.5
    first = b + ramp
    duration = first + g.repetitions * period + ramp + b
    t = np.arange(round(duration / dt) + 1) * dt
    f = np.zeros_like(t)
    for k in range(g.repetitions):
        u = (t - first - k * period) / g.stance_s
        inside = (u >= 0.0) & (u <= 1.0)
        # Double hump: sin(πu) envelope with a mid-stance valley at 75 % of the peak.
        shape = np.sin(math.pi * u) ** 2 * (1.0 - 0.45 * np.sin(math.pi * u) ** 8) \
            + 0.35 * np.sin(2 * math.pi * u) ** 2
        f += np.where(inside, shape, 0.0)
    f = f / max(float(f.max()), 1e-12) * (g.peak_n - g.preload_n)
    # The preload, reached and left by raised-cosine ramps around the stances.
    end = first + g.repetitions * period
    f += g.preload_n * _smooth(t, b, ramp) * (1.0 - _smooth(t, end, ramp))
    return f


def load_plan(path: str | Path) -> Plan:
    """Read and validate a plan file (YAML or JSON)."""
    return yaml_files.load(Plan, path)


def default_plan(**overrides: object) -> Plan:
    return Plan.model_validate({"schema_version": 1, **overrides})
