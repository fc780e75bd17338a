"""Compiled reference generation (issue 16): the IK kernels equal ``Kinematics.ik``, and every
precomputed kind's table equals the interpreted reference implementation's to round-off (the
central differences amplify an ulp of q by 1/h²: ≈ 1e-10 m/s² at most, hence the tolerances);
refusals are worded by the interpreted path, unchanged."""
from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from protocols import base, generators
from protocols.generators import make_generator
from protocols.library import LIBRARY_DIR, load_protocol
from protocols.output import GeneratorInput
from protocols.schema import validate_protocol_data
from rt.errors import WorkspaceError
from rt.model import RobotModel
from rt.model.ankle import AnkleSetup
from rt.model.ik_kernels import (
    IK_NONFINITE,
    IK_OK,
    IK_ROW,
    IK_UNREACHABLE,
    ik_pose,
    ik_three,
    in_workspace,
)

MODEL = RobotModel.load()
KIN = MODEL.kin
SETUP = AnkleSetup(side="right", height_above_sole_m=0.07)
#: q (m) and q̇ (m/s) agree to a few ulps; q̈ = Δ²q/h² carries an ulp of q times 1e6.
TOL_Q, TOL_QD, TOL_QDD = 1e-14, 1e-10, 1e-7


def _interpreted(gen, monkeypatch):
    """The same generator's table through the interpreted reference path (what the compiled
    one hands a refused path to)."""
    with monkeypatch.context() as m:
        m.setattr(base, "path_joint_references", base.joint_references)
        m.setattr(generators, "fk_path", lambda *args: 0)
        report = gen.validate()
        return report, gen.samples()


def _compare(a: dict, b: dict) -> None:
    assert np.max(np.abs(a["q"] - b["q"])) <= TOL_Q
    assert np.max(np.abs(a["qd"] - b["qd"])) <= TOL_QD
    assert np.max(np.abs(a["qdd"] - b["qdd"])) <= TOL_QDD
    assert np.allclose(a["pose"], b["pose"], rtol=0.0, atol=1e-14)
    assert np.allclose(a["pose_dot"], b["pose_dot"], rtol=0.0, atol=1e-10, equal_nan=True)
    assert np.array_equal(a["fz"], b["fz"], equal_nan=True)


def test_ik_pose_is_kinematics_ik_term_for_term() -> None:
    rng = np.random.default_rng(1)
    row = np.empty(IK_ROW)
    worst = 0.0
    for _ in range(500):
        z, r, p = rng.uniform(0.55, 0.75), rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3)
        c = KIN.ik(z, r, p, check=False)
        assert ik_pose(KIN.geom, z, r, p, row) == IK_OK
        expected = np.r_[c.q, c.phi, c.x, c.y, c.yaw, c.rotation]
        worst = max(worst, float(np.max(np.abs(row - expected))))
    assert worst <= 1e-15


def test_ik_pose_refuses_what_kinematics_ik_refuses() -> None:
    row = np.empty(IK_ROW)
    assert ik_pose(KIN.geom, math.nan, 0.0, 0.0, row) == IK_NONFINITE
    assert ik_pose(KIN.geom, 0.63, math.inf, 0.0, row) == IK_NONFINITE
    # Turned over: a sphere lies farther from its guide than the rod (Kinematics.ik raises).
    with pytest.raises(WorkspaceError, match="unreachable"):
        KIN.ik(0.63, -3.1, -0.7, check=False)
    assert ik_pose(KIN.geom, 0.63, -3.1, -0.7, row) == IK_UNREACHABLE


def test_the_workspace_test_agrees_with_kinematics_on_both_sides_of_every_limit() -> None:
    """Poses across the roll/pitch limits and the stroke: the same inside/outside decision."""
    rng = np.random.default_rng(2)
    row = np.empty(IK_ROW)
    inside = outside = 0
    for _ in range(3000):
        z = rng.uniform(0.35, 0.95)
        r, p = rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6)
        if ik_pose(KIN.geom, z, r, p, row) != IK_OK:
            continue
        expected = KIN.in_workspace(KIN.ik(z, r, p, check=False))
        assert in_workspace(KIN.geom, KIN.limits_array, r, p, row) == expected
        inside += expected
        outside += not expected
    assert inside > 100 and outside > 100           # both sides were exercised


@pytest.mark.parametrize("name,ankle", [("ankle_rom.yaml", None), ("ankle_rom.yaml", SETUP),
                                        ("isometric.yaml", None), ("isometric.yaml", SETUP)])
def test_library_position_tables_equal_the_interpreted_references(name, ankle,
                                                                  monkeypatch) -> None:
    gen = make_generator(load_protocol(LIBRARY_DIR / name), kinematics=KIN, ankle=ankle)
    fast = gen.validate()
    assert fast.ok, fast.violations
    a = gen.samples()
    slow, b = _interpreted(gen, monkeypatch)
    _compare(a, b)
    assert fast.ankle_peak_displacement_m == pytest.approx(slow.ankle_peak_displacement_m,
                                                          rel=1e-12, nan_ok=True)
    assert fast.ankle_rms_displacement_m == pytest.approx(slow.ankle_rms_displacement_m,
                                                         rel=1e-12, nan_ok=True)
    assert fast.peak_slider_accel_m_s2 == pytest.approx(slow.peak_slider_accel_m_s2, rel=1e-9)


def test_playback_table_equals_the_interpreted_one(monkeypatch) -> None:
    """Forward kinematics of every sample: the pose within Newton's tolerance (1e-12 rad)."""
    gen = make_generator(load_protocol(LIBRARY_DIR / "position_playback.yaml"), kinematics=KIN)
    assert gen.validate().ok
    a = gen.samples()
    _, b = _interpreted(gen, monkeypatch)
    assert np.array_equal(a["q"], b["q"]) and np.array_equal(a["qd"], b["qd"])
    assert np.allclose(a["pose"], b["pose"], rtol=0.0, atol=1e-12)
    assert np.allclose(a["pose_dot"], b["pose_dot"], rtol=0.0, atol=1e-8)


def test_a_refused_path_is_worded_exactly_as_before(monkeypatch) -> None:
    """Beyond the robot's ±25° pitch: the compiled path hands over, the sentence is the
    same."""
    gen = make_generator(validate_protocol_data(
        {"schema_version": 1, "kind": "ankle_rom", "name": "too far", "pose": {"z_m": 0.63},
         "sequence": ["dorsi_plantar"],
         "amplitude_deg": {"dorsiflexion": 28.0, "plantarflexion": 28.0},
         "speed_deg_s": 40.0, "hold_s": 0.1, "max_acceleration_deg_s2": 400.0,
         "max_jerk_deg_s3": 4000.0}), kinematics=KIN)
    fast = gen.validate()
    with monkeypatch.context() as m:
        m.setattr(base, "path_joint_references", base.joint_references)
        slow = gen.validate()
    assert not fast.ok and fast.violations == slow.violations
    assert "pitch" in fast.violations[0]


def test_ankle_displacements_equal_the_per_sample_ankle_kinematics() -> None:
    gen = make_generator(load_protocol(LIBRARY_DIR / "ankle_rom.yaml"), kinematics=KIN,
                         ankle=SETUP)
    assert gen.validate().ok
    pose = gen.samples()["pose"]
    rolls, pitches = pose[::25, 1].copy(), pose[::25, 2].copy()
    d = gen.ankle.horizontal_displacements(rolls, pitches)
    ak = gen.ankle.kinematics
    expected = [ak.pose_for_platform_angles(float(r), float(p)).horizontal_m
                for r, p in zip(rolls, pitches, strict=True)]
    assert np.allclose(d, expected, rtol=1e-13, atol=1e-16)


def test_active_assist_references_are_the_ik_of_its_pose_and_path() -> None:
    """The online generator's compiled IK: q is ``Kinematics.ik`` of the emitted pose, q̇ and
    q̈ its central differences along the local path, whatever the patient's torque."""
    doc = load_protocol(LIBRARY_DIR / "active_assist.yaml").model_dump(mode="json")
    doc["ankle_displacement_limit_mm"] = 45.0     # its +15° moves the centre 38.9 mm
    gen = make_generator(validate_protocol_data(doc), kinematics=KIN, ankle=SETUP)
    assert gen.validate().ok
    out, inp = gen.new_output(), GeneratorInput()
    h = base.DERIVATIVE_STEP_S
    for k in range(3000):
        inp.tau_pitch_nm = 4.0 * math.sin(k * 2e-3)
        assert gen.update(out, inp) >= 0
        if k % 250:
            continue
        b = out.buf
        z, r, p = b[9], b[10], b[11]
        assert np.allclose(b[0:3], KIN.ik(z, r, p, check=False).q, rtol=0.0, atol=1e-15)
        vr, vp, ar, ap = gen._w_r, gen._w_p, gen._a_r, gen._a_p
        hv = gen.ankle.heave
        rp_, pp_ = r + h * vr + 0.5 * h * h * ar, p + h * vp + 0.5 * h * h * ap
        rm_, pm_ = r - h * vr + 0.5 * h * h * ar, p - h * vp + 0.5 * h * h * ap
        gp = np.array(KIN.ik(hv.z_for(rp_, pp_), rp_, pp_, check=False).q)
        gm = np.array(KIN.ik(hv.z_for(rm_, pm_), rm_, pm_, check=False).q)
        assert np.allclose(b[3:6], (gp - gm) / (2 * h), rtol=0.0, atol=TOL_QD)
        assert np.allclose(b[6:9], (gp - 2 * b[0:3] + gm) / (h * h), rtol=0.0, atol=TOL_QDD)


def test_active_assist_compiles_before_its_cycles_and_survives_pickling() -> None:
    """The pre-flight worker sends the generator pickled to the RT process: unpickled, it has
    its kernel ready (no compile in a cycle) and streams the same references."""
    gen = make_generator(load_protocol(LIBRARY_DIR / "active_assist.yaml"), kinematics=KIN)
    assert gen.validate().ok
    copy = pickle.loads(pickle.dumps(gen))
    before = len(ik_three.signatures)
    assert before >= 1
    a, b, inp = gen.new_output(), copy.new_output(), GeneratorInput()
    for k in range(500):
        inp.tau_pitch_nm = 2.0 * math.cos(k * 1e-2)
        assert gen.update(a, inp) == copy.update(b, inp)
        assert np.array_equal(a.buf, b.buf, equal_nan=True)
    assert len(ik_three.signatures) == before
