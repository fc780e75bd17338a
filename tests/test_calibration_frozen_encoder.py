"""The frozen-encoder check against calibration pushes on the twin (issue 12's closing note,
issue 15), with the twin's amplifier offsets on (the default).

A push's contact onset: the tool tip meets the plate, bounces and presses; the sliders stall
against it before the ATI shows the force (its filter and sample age) while the command says
they should move. A shear push: 600 N at the level pose, then a 2° roll in 1 s under load, the
tip held by the plate (static friction under 600 N), so the sliders stall while their
references move. The supervisor used to hard-stop both with ``encoder_frozen_*``: first the
reference-speed criterion counted the stalled slider (this file's strict xfail until issue
15); then the force balance (branch twin15) judged the law's command where the drives were
saturated, and learnt a braking's inertia as carried load. Now a still axis is judged by its
force balance with the force its drive applies (saturated at the DAC's limit), the measured
contact's share and the sensor's lag, against the static load learnt while quasi-static
(``rt.safety.supervisor``): both pushes complete.

The hybrid force/angle loop used to fall into a 28 Hz limit cycle during the roll against the
stuck tip (drives saturated both ways, commands ±10 kN, the ATI force bouncing 0-1.1 kN), and
the roll reached its 2° only because the bouncing tip let go. The force law now scales its
gains with the contact's stiffness (k̂ ≈ 2e6 N/m here against the 2.5e5 N/m schedule point)
and holds the angles with integral action (the tip dragged at its friction cone resists with
μ N h ≈ 58 N m): the force stays within 600 ± 20 N and the roll reaches its command.

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
from calibration.trial import TrialData
from calibration.twin_plate import TwinPlate, draw_truth
from calibration.twin_runner import TwinTrialRunner
from rt.errors import SafetyTrip
from rt.twin.realism import RigImperfections

DT = 1e-3


def _run(kind: ProfileKind, **shear) -> TrialData:
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


@pytest.fixture(scope="module")
def fast_tilt() -> TrialData | SafetyTrip:
    """The shear push of the old strict xfail: 600 N, then a 2° roll in 1 s, held 0.5 s; or
    the supervisor's stop, returned so that each test fails naming it (the push must complete)."""
    try:
        return _run(ProfileKind.SHEAR, roll_deg=2.0, load_n=600.0, tilt_ramp_s=1.0, hold_s=0.5)
    except SafetyTrip as stop:
        return stop


def test_a_push_through_its_contact_onset_is_not_taken_for_a_frozen_encoder() -> None:
    assert RigImperfections().amplifier_offset_v > 0.0       # the default twin's offsets on
    data = _run(ProfileKind.STEPS)
    # Completed: every load step held (the plan's highest level reached on the ATI).
    loaded = data.force_ref > 0.0
    assert loaded.any()
    peak = float(np.max(data.force_ref))
    assert float(np.max(-data.ati[:, 2])) == pytest.approx(peak, rel=0.05)


def test_a_fast_tilt_under_load_is_not_taken_for_a_frozen_encoder(fast_tilt) -> None:
    """Completed: the load held on average through the tilt, and the platform reached the 2°
    roll; no stop at all (before the force law's stiffness schedule the loop fell into a limit
    cycle against the stuck tip, which the sustained-saturation check then stopped as
    ``drive_saturated_*``: a frozen-encoder stop here would be the old false positive)."""
    assert not isinstance(fast_tilt, SafetyTrip), str(fast_tilt)
    loaded = fast_tilt.force_ref > 590.0
    assert np.median(-fast_tilt.ati[loaded, 2]) == pytest.approx(600.0, rel=0.05)
    rolls = [math.degrees(math.atan2(-R[5], R[8])) for R in fast_tilt.R_BS[loaded]]
    assert max(rolls) == pytest.approx(2.0, abs=0.3)


def test_the_contact_holds_through_a_fast_tilt(fast_tilt) -> None:
    """While loaded the ATI force stays within 600 ± 30 N (measured 583-613 N; before the gain
    schedule it bounced 0-1.1 kN), and the roll holds its 2° without a bounce to free the
    tip."""
    assert not isinstance(fast_tilt, SafetyTrip), str(fast_tilt)
    loaded = fast_tilt.force_ref > 590.0
    fz = -fast_tilt.ati[loaded, 2]
    assert float(np.min(fz)) > 570.0 and float(np.max(fz)) < 630.0
    rolls = np.array([math.degrees(math.atan2(-R[5], R[8])) for R in fast_tilt.R_BS[loaded]])
    # Past the ramp (2° reached in 1 s, then held 0.5 s): within 0.2° of it.
    assert float(np.max(np.abs(rolls - 2.0)[np.argmax(rolls > 1.8):][:400])) < 0.2
