"""The ankle centre: setup validation, platform poses about it, residual displacement, and the
sensor's wrench moved to it (rt.model.ankle), each against a hand calculation."""
from __future__ import annotations

import math

import pytest

from rt.errors import InputError
from rt.model import RobotModel
from rt.model.ankle import (
    AnkleKinematics,
    AnkleSetup,
    ankle_torques,
    parse_ankle_setup,
    transfer_wrench,
)

MODEL = RobotModel.load()
RP = MODEL.description.geometry.platform_radius_m          # 0.18 m
SENSOR_Z = MODEL.description.sensor.offset_m[2]            # 0.080 m
Z0 = 0.633
H = 0.07                                                   # ankle 70 mm above the sole
H_P = SENSOR_Z + H                                         # ankle centre above P's origin


def kin(side: str = "right", **kw) -> AnkleKinematics:
    setup = AnkleSetup(side=side, height_above_sole_m=H, **kw)
    return AnkleKinematics(MODEL.kin, setup, MODEL.description.sensor.offset_m, (Z0, 0.0, 0.0))


# ------------------------------------------------------------------------------ setup
def test_a_plausible_setup_is_accepted() -> None:
    s = parse_ankle_setup({"side": "left", "height_above_sole_m": 0.075, "offset_x_m": 0.02},
                          RP, side="left")
    assert s.height_above_sole_m == 0.075 and s.offset_x_m == 0.02 and s.source == "entered"


@pytest.mark.parametrize("data, words", [
    (None, ["missing", "height above the sole"]),
    ({"side": "right"}, ["height_above_sole_m", "Field required"]),
    ({"side": "right", "height_above_sole_m": -0.02}, ["height_above_sole_m", "below the sole"]),
    ({"side": "right", "height_above_sole_m": 0.0}, ["below the sole"]),
    ({"side": "right", "height_above_sole_m": 7.0}, ["not a plausible", "unit"]),
    ({"side": "right", "height_above_sole_m": 0.07, "offset_x_m": 0.25},
     ["outside the platform", "250 mm"]),
    ({"side": "right", "height_above_sole_m": 0.07, "offset_x_m": 0.15, "offset_y_m": 0.15},
     ["outside the platform"]),
    ({"side": "middle", "height_above_sole_m": 0.07}, ["side"]),
    ({"side": "right", "height_above_sole_m": float("nan")}, ["height_above_sole_m"]),
])
def test_a_missing_or_implausible_setup_is_refused_naming_the_field(data, words) -> None:
    with pytest.raises(InputError) as err:
        parse_ankle_setup(data, RP)
    for w in words:
        assert w in str(err.value)


def test_a_setup_for_the_other_foot_is_refused() -> None:
    with pytest.raises(InputError, match="left foot but the session is for the right"):
        parse_ankle_setup({"side": "left", "height_above_sole_m": 0.07}, RP, side="right")


# ------------------------------------------------------------------------------ kinematics
@pytest.mark.parametrize("deg", [20.0, -20.0, 7.5])
def test_pitch_about_the_ankle_matches_the_hand_calculation(deg: float) -> None:
    """Pitch β alone: yaw 0, parasitic (x, y) = (0, R_p (1 - cos β) / 2) (derived from the
    constraint (x, y) = -(2/3) Σ t_i (r_i · t_i) with legs at 90°, 210°, 330°), the centre at
    (h sin β, 0, h cos β) from P's origin: z = z0 + h (1 - cos β) keeps its height and the
    residual is (h sin β, R_p (1 - cos β)/2, 0)."""
    b = math.radians(deg)
    pose = kin().pose(b, 0.0)
    assert pose.pitch_rad == pytest.approx(b, abs=1e-15)
    assert pose.roll_rad == 0.0
    assert pose.z_m == pytest.approx(Z0 + H_P * (1.0 - math.cos(b)), abs=1e-12)
    dx, dy, dz = pose.displacement_m
    assert dx == pytest.approx(H_P * math.sin(b), abs=1e-12)
    assert dy == pytest.approx(RP * (1.0 - math.cos(b)) / 2.0, abs=1e-12)
    assert dz == pytest.approx(0.0, abs=1e-12)
    # About the platform's centre (z held) the centre also drops by h (1 - cos β).
    plain = kin().pose(b, 0.0, compensate=False)
    assert plain.z_m == Z0
    assert plain.displacement_m[2] == pytest.approx(-H_P * (1.0 - math.cos(b)), abs=1e-12)
    assert plain.residual_m > pose.residual_m


def test_twenty_degrees_of_plantarflexion_in_millimetres() -> None:
    """h = 150 mm above P, 20°: residual 150 sin 20° = 51.30 mm along x, 5.43 mm of parasitic
    y; without compensation the centre also drops 150 (1 - cos 20°) = 9.05 mm."""
    pose = kin().pose(math.radians(20.0), 0.0)
    assert pose.displacement_m[0] * 1e3 == pytest.approx(51.303, abs=1e-3)
    assert pose.displacement_m[1] * 1e3 == pytest.approx(5.428, abs=1e-3)
    assert kin().pose(math.radians(20.0), 0.0, False).displacement_m[2] * 1e3 == \
        pytest.approx(-9.046, abs=1e-3)


@pytest.mark.parametrize("side, sign", [("right", 1.0), ("left", -1.0)])
def test_inversion_about_the_ankle_matches_the_hand_calculation(side: str, sign: float) -> None:
    """Roll γ alone: parasitic (x, y) = (0, -R_p (1 - cos γ) / 2), the centre at
    (0, -h sin γ, h cos γ): the parasitic y adds to the swing; z = z0 + h (1 - cos γ)."""
    inv = math.radians(15.0)
    pose = kin(side).pose(0.0, inv)
    g = sign * inv
    assert pose.roll_rad == pytest.approx(g, abs=1e-15)
    assert pose.z_m == pytest.approx(Z0 + H_P * (1.0 - math.cos(g)), abs=1e-12)
    dx, dy, dz = pose.displacement_m
    assert dx == pytest.approx(0.0, abs=1e-12)
    assert dy == pytest.approx(-H_P * math.sin(g) - RP * (1.0 - math.cos(g)) / 2.0, abs=1e-12)
    assert dz == pytest.approx(0.0, abs=1e-12)


def test_the_compensated_pose_is_reachable_and_its_centre_is_where_fk_puts_it() -> None:
    """Round trip through the robot: IK of the compensated pose, FK of its sliders, the ankle
    centre from the FK pose keeps its height."""
    k = kin(offset_x_m=0.03, offset_y_m=-0.01)
    pose = k.pose(math.radians(12.0), math.radians(-8.0))
    q = MODEL.kin.ik(pose.z_m, pose.roll_rad, pose.pitch_rad).q
    c = MODEL.kin.fk(q)
    a = k.centre(c.z, c.roll, c.pitch)
    assert a[2] == pytest.approx(k.start[2], abs=1e-9)
    assert k.angles(c.roll, c.pitch) == pytest.approx((math.radians(12.0), math.radians(-8.0)),
                                                      abs=1e-9)


# ------------------------------------------------------------------------------ statics
def test_wrench_transfer_matches_hand_statics() -> None:
    """The foot pushes 100 N down 0.10 m in front of the ankle and 20 N forward at the sole.
    About the ankle (H above the sole): plantarflexion 100·0.10 - 20·H N m, nothing else."""
    ox, oy = 0.02, -0.01
    setup = AnkleSetup(side="right", height_above_sole_m=H, offset_x_m=ox, offset_y_m=oy)
    # The two forces act at the sole (sensor origin plane): their moments about the origin.
    px, py = ox + 0.10, oy
    f = (20.0, 0.0, -100.0)
    m_s = (py * f[2], -(px * f[2]), -(py * f[0]))   # r × f with r = (px, py, 0)
    w = (*f, *m_s)
    plantar, inversion, abduction = ankle_torques(w, setup)
    assert plantar == pytest.approx(100.0 * 0.10 - 20.0 * H, abs=1e-12)
    assert inversion == pytest.approx(0.0, abs=1e-12)
    assert abduction == pytest.approx(0.0, abs=1e-12)


def test_lateral_push_is_an_eversion_torque_on_a_right_foot_and_inversion_on_a_left() -> None:
    """60 N down under the medial border (+y for a right foot) 0.04 m from the ankle: an
    eversion effort of 2.4 N m; the same push on a left foot (+y lateral) is inversion."""
    w = (0.0, 0.0, -60.0, 0.04 * -60.0, 0.0, 0.0)   # r = (0, 0.04, 0): m_x = r_y f_z
    right = AnkleSetup(side="right", height_above_sole_m=H)
    left = AnkleSetup(side="left", height_above_sole_m=H)
    assert ankle_torques(w, right)[1] == pytest.approx(-2.4, abs=1e-12)
    assert ankle_torques(w, left)[1] == pytest.approx(2.4, abs=1e-12)


def test_transfer_keeps_the_force_and_the_power() -> None:
    """Moving the reference point keeps f and changes m by r × f: f · m is invariant."""
    w = (3.0, -4.0, -50.0, 1.5, -2.0, 0.3)
    t = transfer_wrench(w, (0.01, -0.02, 0.09))
    assert t[:3] == w[:3]
    dot = sum(w[i] * w[3 + i] for i in range(3))
    assert sum(t[i] * t[3 + i] for i in range(3)) == pytest.approx(dot, abs=1e-12)


# ------------------------------------------------------------------------------ twin's ankle
def _twin_wrench(env, z: float, roll: float, pitch: float):
    """The twin ankle's wrench on the platform (sensor frame) and its state, at rest."""
    import numpy as np

    from rt.twin import physics
    from rt.twin.plant import TwinPlant

    plant = TwinPlant(MODEL.description, env)
    c = MODEL.kin.ik(z, roll, pitch)
    rot = np.array(c.rotation).reshape(3, 3)
    pos = np.array([c.x, c.y, c.z])
    state = np.zeros(physics.ENV_STATE_SIZE)
    wrench, tau = np.zeros(6), np.zeros(3)
    physics.environment_wrench(env.pack(), plant.bodies, rot, pos, np.zeros((6, 3)),
                               np.zeros(3), state, wrench, tau)
    return wrench, state


def test_twin_ankle_about_its_joint_centre_matches_hand_statics() -> None:
    """Pitch 10° about the platform's centre with the twin's ankle 70 mm above the sole: the
    centre moves (h_P sin β, R_p (1 - cos β)/2, -h_P (1 - cos β)); the shank pushes back with
    k_h, k_h, k_z times that; the joint's torque is -K β (1 + (β/θ_end)²); and the sensor's
    wrench moved back to the ankle gives that torque."""
    from rt.twin.environment import CompliantAnkle

    env = CompliantAnkle.at_pose(MODEL.kin, Z0, 0.0, 0.0, limb_weight_n=0.0)
    b = math.radians(10.0)
    wrench, state = _twin_wrench(env, Z0, 0.0, b)
    d = (H_P * math.sin(b), RP * (1.0 - math.cos(b)) / 2.0, -H_P * (1.0 - math.cos(b)))
    f = (-3e3 * d[0], -3e3 * d[1], -1e5 * d[2])
    assert tuple(state[4:7]) == pytest.approx(f, abs=1e-9)
    k_true = -45.0 * b * (1.0 + (b / 0.3491) ** 2)
    assert tuple(state[1:4]) == pytest.approx((0.0, k_true, 0.0), abs=1e-9)
    # Sensor frame = R_yᵀ of the base-frame force.
    cb, sb = math.cos(b), math.sin(b)
    assert wrench[0] == pytest.approx(cb * f[0] - sb * f[2], abs=1e-9)
    assert wrench[2] == pytest.approx(sb * f[0] + cb * f[2], abs=1e-9)
    plantar, inversion, _ = ankle_torques(tuple(wrench), AnkleSetup(side="right",
                                                                    height_above_sole_m=H))
    assert plantar == pytest.approx(k_true, abs=1e-9)
    assert inversion == pytest.approx(0.0, abs=1e-9)


def test_about_the_ankle_the_twin_ankle_feels_only_the_horizontal_residual() -> None:
    from rt.twin.environment import CompliantAnkle

    env = CompliantAnkle.at_pose(MODEL.kin, Z0, 0.0, 0.0, limb_weight_n=0.0)
    pose = kin().pose(math.radians(10.0), 0.0)
    _, state = _twin_wrench(env, pose.z_m, pose.roll_rad, pose.pitch_rad)
    assert state[6] == pytest.approx(0.0, abs=1e-9)
    assert state[4] == pytest.approx(-3e3 * pose.displacement_m[0], abs=1e-9)


def test_setup_from_the_malleoli_markers() -> None:
    """Markers 70 mm apart across a right foot, the medial one 10 mm higher (as anatomy has
    it): the centre is their midpoint; height above the sole (at the sensor's origin + 5 mm
    plate) and offsets follow."""
    from rt.model.ankle import setup_from_malleoli

    s = MODEL.description.sensor.offset_m
    lat = (0.02, -0.035, s[2] + 0.005 + 0.065)
    med = (0.02, 0.035, s[2] + 0.005 + 0.075)
    setup = setup_from_malleoli(lat, med, "right", s, sole_above_sensor_m=0.005)
    assert setup.source == "camera" and setup.side == "right"
    assert setup.height_above_sole_m == pytest.approx(0.070, abs=1e-12)
    assert (setup.offset_x_m, setup.offset_y_m) == pytest.approx((0.02, 0.0), abs=1e-12)
    with pytest.raises(InputError, match="medial marker is on the lateral side of a left"):
        setup_from_malleoli(lat, med, "left", s)
    with pytest.raises(InputError, match="250 mm apart"):
        setup_from_malleoli((0.0, -0.125, 0.15), (0.0, 0.125, 0.15), "right", s)
    with pytest.raises(InputError, match="below the sole"):
        setup_from_malleoli((0.0, -0.035, 0.05), (0.0, 0.035, 0.05), "right", s)
