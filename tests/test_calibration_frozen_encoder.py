"""The frozen-encoder check against calibration pushes on the twin (issue 12's closing note,
issue 15), with the twin's amplifier offsets on (the default).

A push's contact onset: the tool tip meets the plate, bounces and presses; the sliders stall
against it before the ATI shows the force (its filter and sample age) while the command says
they should move. The supervisor used to hard-stop such pushes with ``encoder_frozen_*`` (the
impulse criterion judged "free" from the lagging ATI force; the ±15 mV amplifier offsets were
switched off for it). Now a still axis is judged by its force balance with the measured
contact's share of its command and the sensor's lag allowed for, and the reference-speed
criterion only while nothing touches (``rt.safety.supervisor``): a push through every load
step completes.

A shear push (600 N, then a 2° roll under load, the tip held by the plate) is still stopped,
and rightly: the hybrid force/angle loop goes unstable against the stuck tip during the roll
(twin figures, with or without the offsets: commands swinging ±5-7 kN, sliders at 40-50 mm/s,
ATI force 200-925 N within 0.2 s; at 1.9 s into a 5 s roll, 0.1 s into a 1 s one). That is
the force law's problem, not a false positive (closing note): the strict xfail below says so
and reports the day the loop holds.

The twin runs in fast mode (simulated time, deterministic): not a CPU-load artefact.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from calibration.plan import (
    ProfileKind,
    default_plan,
    expand,
    force_profile,
    tilt_profile,
    trial_pose,
)
from calibration.plate import TWIN_PLATE_FILE, load_plate
from calibration.twin_plate import TwinPlate, draw_truth
from calibration.twin_runner import TwinTrialRunner
from rt.errors import SafetyTrip
from rt.twin.realism import RigImperfections

DT = 1e-3


def _run(kind: ProfileKind, **shear):
    plan = default_plan(shear=[shear] if shear else [], registration="nominal",
                        baseline_s=0.5)
    plate = load_plate(TWIN_PLATE_FILE)
    trial = next(t for t in expand(plan, plate.size_m) if t.profile == kind)
    truth = draw_truth(plate, seed=12)
    runner = TwinTrialRunner(plate, TwinPlate(plate, truth, seed=13), registration="nominal")
    profile = force_profile(plan, trial, DT)
    tilt = tilt_profile(plan, trial, DT)
    return runner.run(trial.id, trial.site_xy_m, trial_pose(plan, trial), profile, DT,
                      tilt_rad=tilt)


def test_a_push_through_its_contact_onset_is_not_taken_for_a_frozen_encoder() -> None:
    assert RigImperfections().amplifier_offset_v > 0.0       # the default twin's offsets on
    data = _run(ProfileKind.STEPS)
    # Completed: every load step held (the plan's highest level reached on the ATI).
    loaded = data.force_ref > 0.0
    assert loaded.any()
    peak = float(np.max(data.force_ref))
    assert float(np.max(-data.ati[:, 2])) == pytest.approx(peak, rel=0.05)


@pytest.mark.xfail(strict=True, raises=SafetyTrip,
                   reason="the hybrid force/angle loop goes unstable during a roll against the "
                          "plate's stuck tip (a control problem, not the supervisor's)")
def test_a_tilt_under_load_completes() -> None:
    data = _run(ProfileKind.SHEAR, roll_deg=2.0, load_n=600.0, tilt_ramp_s=5.0, hold_s=0.5)
    loaded = data.force_ref > 590.0
    assert np.median(-data.ati[loaded, 2]) == pytest.approx(600.0, rel=0.05)
    rolls = [math.degrees(math.atan2(-R[5], R[8])) for R in data.R_BS[loaded]]
    assert max(rolls) == pytest.approx(2.0, abs=0.3)
