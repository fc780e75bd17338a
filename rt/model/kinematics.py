"""Kinematics of the 3-PRS robot, written on plain floats (PLATFORM.md: numpy costs µs per call
on 3-vectors; this module runs every control cycle).

Coordinates (frames in ``rt/data/robot_nominal.yaml``):

* ``q_i`` slider positions (m) along the vertical guides, 0 at the bottom of the stroke.
* ``phi_i`` rod angles (rad) about each leg's tangent axis, 0 = rod vertical, < 0 leaning inward.
* Platform pose: heave ``z`` (m), roll ``γ`` about x and pitch ``β`` about y (rad), fixed-axis
  X-Y-Z so R = Rz(α) Ry(β) Rx(γ). The parasitic yaw α and translations x, y follow from the
  constraints (each sphere stays in its leg's vertical plane):
  α = atan2(sβ sγ, cβ + cγ) (thesis eq. 9, equivalently R[1,0] = R[0,1]) and
  (x, y) = -(2/3) Σ t_i (r_i · t_i) with t_i the legs' tangents and r_i = R b_i.

Inverse kinematics is closed form. Forward kinematics (the Newton loop compiled with numba in
``rt.model.kernels.fk_solve``, shared with the twin) solves the thesis's three rigid-triangle
equations |B_i - B_j|² = 3 R_p² for the rod angles by Newton-Raphson (quadratic convergence,
warm-started from the previous solution), then builds the platform frame from the three sphere
centres.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rt.errors import ConvergenceError, WorkspaceError
from rt.model.description import RobotDescription
from rt.model.kernels import FK_SINGULAR, assemble, fk_rows, fk_solve, pack_geometry

FK_MAX_ITERATIONS = 25
# Newton stops when the largest rod-angle update is below this (rad). 1e-12 rad on a 0.45 m rod
# is 4.5e-13 m, far below the 2e-5 m encoder resolution and above float round-off (~1e-16).
FK_STEP_TOL_RAD = 1e-12


@dataclass(slots=True)
class Configuration:
    """One assembled configuration of the robot: actuated, passive and platform coordinates.

    Lengths in m, angles in rad. ``rotation`` is R_BP row-major (9 floats), ``spheres`` the three
    sphere centres B_i in the base frame, ``normal`` the platform z axis in the base frame.
    """

    q: tuple[float, float, float]
    phi: tuple[float, float, float]
    z: float
    roll: float
    pitch: float
    x: float
    y: float
    yaw: float
    rotation: tuple[float, ...] = field(repr=False)
    spheres: tuple[tuple[float, float, float], ...] = field(repr=False)
    iterations: int = 0

    @property
    def pose(self) -> tuple[float, float, float]:
        """The three controlled coordinates (z, roll, pitch)."""
        return (self.z, self.roll, self.pitch)


def rotation_zyx(yaw: float, pitch: float, roll: float) -> tuple[float, ...]:
    """R = Rz(yaw) Ry(pitch) Rx(roll), row-major 9-tuple."""
    ca, sa = math.cos(yaw), math.sin(yaw)
    cb, sb = math.cos(pitch), math.sin(pitch)
    cg, sg = math.cos(roll), math.sin(roll)
    return (
        ca * cb, ca * sb * sg - sa * cg, ca * sb * cg + sa * sg,
        sa * cb, sa * sb * sg + ca * cg, sa * sb * cg - ca * sg,
        -sb, cb * sg, cb * cg,
    )


def parasitic_yaw(roll: float, pitch: float) -> float:
    """Yaw α (rad) forced by the 3-PRS constraints for a given roll γ and pitch β (thesis eq. 9)."""
    return math.atan2(math.sin(pitch) * math.sin(roll), math.cos(pitch) + math.cos(roll))


class Kinematics:
    """Closed-form IK, Newton-Raphson FK, velocity maps and the workspace check."""

    def __init__(self, description: RobotDescription):
        g = description.geometry
        lim = description.limits
        self.description = description
        self.base_radius = g.base_radius_m
        self.platform_radius = g.platform_radius_m
        self.rod_length = g.rod_length_m
        th = [math.radians(a) for a in g.leg_angles_deg]
        self.cos_theta = tuple(math.cos(t) for t in th)
        self.sin_theta = tuple(math.sin(t) for t in th)
        # cos(θ_i - θ_j) for the pairs (0,1), (1,2), (2,0): -1/2 for 120° spacing.
        self._pairs = ((0, 1), (1, 2), (2, 0))
        self._cos_pair = tuple(math.cos(th[i] - th[j]) for i, j in self._pairs)
        self._side_sq = 3.0 * self.platform_radius ** 2
        self.stroke = (lim.stroke_m[0], lim.stroke_m[1])
        self.rod_angle_max = math.radians(lim.rod_angle_max_deg)
        self.cone_half_angle = math.radians(lim.spherical_cone_half_angle_deg)
        self.roll_max = math.radians(lim.roll_max_deg)
        self.pitch_max = math.radians(lim.pitch_max_deg)
        # Rod angle with the platform level and centred: sin φ0 = (R_p - R_b) / L.
        self.phi_nominal = math.asin((self.platform_radius - self.base_radius) / self.rod_length)
        # The FK warm start, shared by ``fk`` and the compiled model block
        # (``rt.model.kernels.model_state``), so both continue from the same solution.
        self._phi_guess = np.full(3, self.phi_nominal)
        #: The workspace limits as ``model_state`` reads them (``kernels.LIMIT_*``).
        self.limits_array = np.array([self.stroke[0], self.stroke[1], self.rod_angle_max,
                                      self.cone_half_angle, self.roll_max, self.pitch_max])
        self.geom = pack_geometry(self.base_radius, self.platform_radius, self.rod_length,
                                  self.cos_theta, self.sin_theta, self._cos_pair)
        self._q_buf = np.zeros(3)
        self._phi_work = np.zeros(3)
        self._rot = np.zeros((3, 3))
        self._pos = np.zeros(3)
        self._spheres = np.zeros((3, 3))

    def reset_warm_start(self) -> None:
        """Start the next forward kinematics from the level, centred platform's rod angles, as
        a freshly loaded model does. A loop built on a model that ran before calls this so that
        what it computes does not depend on that history: Newton's last bits follow its start."""
        # In place: the compiled blocks hold this array.
        self._phi_guess[:] = self.phi_nominal

    # ------------------------------------------------------------------ inverse kinematics
    def ik(self, z: float, roll: float, pitch: float, check: bool = True) -> Configuration:
        """Slider positions for a platform pose (z m, roll γ rad, pitch β rad).

        Raises ``WorkspaceError`` naming the violated limit when the pose is unreachable or (with
        ``check``) outside the workspace limits.
        """
        for name, value in (("z", z), ("roll", roll), ("pitch", pitch)):
            if not math.isfinite(value):
                raise WorkspaceError(f"{name} must be a finite number, got {value}")
        if check:
            if abs(roll) > self.roll_max:
                raise WorkspaceError(f"roll {math.degrees(roll):.2f} deg exceeds the limit "
                                     f"±{math.degrees(self.roll_max):.1f} deg")
            if abs(pitch) > self.pitch_max:
                raise WorkspaceError(f"pitch {math.degrees(pitch):.2f} deg exceeds the limit "
                                     f"±{math.degrees(self.pitch_max):.1f} deg")
        yaw = parasitic_yaw(roll, pitch)
        rot = rotation_zyx(yaw, pitch, roll)
        rp, rb, length = self.platform_radius, self.base_radius, self.rod_length
        r = []
        rt_sum_x = rt_sum_y = 0.0
        for i in range(3):
            c, s = self.cos_theta[i], self.sin_theta[i]
            rx = rp * (rot[0] * c + rot[1] * s)
            ry = rp * (rot[3] * c + rot[4] * s)
            rz = rp * (rot[6] * c + rot[7] * s)
            r.append((rx, ry, rz))
            along_t = -s * rx + c * ry          # r_i · t_i, with t_i = (-sin θ_i, cos θ_i, 0)
            rt_sum_x += -s * along_t
            rt_sum_y += c * along_t
        x = -2.0 / 3.0 * rt_sum_x
        y = -2.0 / 3.0 * rt_sum_y
        q = [0.0, 0.0, 0.0]
        phi = [0.0, 0.0, 0.0]
        spheres = []
        for i in range(3):
            c, s = self.cos_theta[i], self.sin_theta[i]
            bx, by, bz = x + r[i][0], y + r[i][1], z + r[i][2]
            spheres.append((bx, by, bz))
            radial = bx * c + by * s
            sin_phi = (radial - rb) / length
            if abs(sin_phi) >= 1.0:
                raise WorkspaceError(f"pose unreachable: sphere {i + 1} is {abs(radial - rb):.3f} m "
                                     f"from its guide, more than the rod length {length} m")
            phi[i] = math.asin(sin_phi)
            q[i] = bz - length * math.cos(phi[i])
        cfg = Configuration((q[0], q[1], q[2]), (phi[0], phi[1], phi[2]), z, roll, pitch, x, y,
                            yaw, rot, tuple(spheres))
        if check:
            self.check_workspace(cfg)
        return cfg

    # ------------------------------------------------------------------ forward kinematics
    def fk(self, q, guess=None, check: bool = True) -> Configuration:
        """Platform pose from slider positions ``q`` (m) by Newton-Raphson on the rod angles.

        Warm-started from ``guess`` (rod angles, rad) or from this object's previous solution.
        Raises ``ConvergenceError`` when Newton does not converge and ``WorkspaceError`` when the
        result lies outside the workspace (with ``check``).
        """
        q0, q1, q2 = float(q[0]), float(q[1]), float(q[2])
        if not (math.isfinite(q0) and math.isfinite(q1) and math.isfinite(q2)):
            raise WorkspaceError(f"slider positions must be finite numbers, got {tuple(q)}")
        if check:
            lo, hi = self.stroke
            for i, qi in enumerate((q0, q1, q2)):
                if not lo <= qi <= hi:
                    raise WorkspaceError(f"slider {i + 1} at {qi:.4f} m is outside the stroke "
                                         f"[{lo}, {hi}] m")
        self._q_buf[0], self._q_buf[1], self._q_buf[2] = q0, q1, q2
        phi = self._phi_work
        g = self._phi_guess if guess is None else guess
        phi[0], phi[1], phi[2] = g[0], g[1], g[2]
        iterations = fk_solve(self.geom, self._q_buf, phi, FK_STEP_TOL_RAD, FK_MAX_ITERATIONS)
        if iterations == FK_SINGULAR:
            raise ConvergenceError(f"forward kinematics hit a singular configuration at "
                                   f"q = {(q0, q1, q2)} m")
        if iterations < 0:
            raise ConvergenceError(
                f"forward kinematics did not converge for q = {(q0, q1, q2)} m within "
                f"{FK_MAX_ITERATIONS} Newton iterations; the sliders may be outside the "
                "assembly range")
        p0, p1, p2 = float(phi[0]), float(phi[1]), float(phi[2])
        cfg = self._assemble((q0, q1, q2), (p0, p1, p2), iterations)
        if check:
            self.check_workspace(cfg)
        self._phi_guess[0], self._phi_guess[1], self._phi_guess[2] = p0, p1, p2
        return cfg

    def fk_roll_pitch(self, qs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Roll and pitch (rad) of ``fk(q, check=False)`` for each row of ``qs`` (n × 3 slider
        positions, m, finite), in order, as n such calls give them: the same warm starts
        (this object's, left at the last solution) and the same floats, compiled
        (``rt.model.kernels.fk_rows``). Also which rows solved (a row FK cannot solve gets
        NaN angles and leaves the warm start, as ``fk`` raising does)."""
        qs = np.ascontiguousarray(qs, dtype=np.float64).reshape(-1, 3)
        if not np.isfinite(qs).all():
            raise WorkspaceError("slider positions must be finite numbers")
        n = len(qs)
        rot_z = np.empty((n, 3))
        status = np.empty(n, dtype=np.int64)
        fk_rows(self.geom, qs, self._phi_guess, FK_STEP_TOL_RAD, FK_MAX_ITERATIONS, rot_z,
                status)
        ok = status >= 0
        roll = np.full(n, np.nan)
        pitch = np.full(n, np.nan)
        for k in np.flatnonzero(ok).tolist():
            r20, r21, r22 = rot_z[k].tolist()
            # ``_assemble``'s arithmetic on the same floats (Python's atan2 and hypot).
            roll[k] = math.atan2(r21, r22)
            pitch[k] = math.atan2(-r20, math.hypot(r21, r22))
        return roll, pitch, ok

    def _assemble(self, q, phi, iterations: int) -> Configuration:
        """Platform frame from the three sphere centres (thesis eq. 7), angles read off R."""
        phi_arr = self._phi_work
        phi_arr[0], phi_arr[1], phi_arr[2] = phi
        self._q_buf[0], self._q_buf[1], self._q_buf[2] = q
        assemble(self.geom, self._q_buf, phi_arr, self._rot, self._pos, self._spheres)
        rot = tuple(self._rot.ravel().tolist())
        px, py, pz = self._pos.tolist()
        pts = tuple((float(x), float(y), float(z)) for x, y, z in self._spheres.tolist())
        roll = math.atan2(rot[7], rot[8])
        pitch = math.atan2(-rot[6], math.hypot(rot[7], rot[8]))
        yaw = math.atan2(rot[3], rot[0])
        return Configuration((q[0], q[1], q[2]), (phi[0], phi[1], phi[2]), pz, roll, pitch, px,
                             py, yaw, rot, pts, iterations)

    # ------------------------------------------------------------------ workspace
    def workspace_violations(self, cfg: Configuration) -> list[str]:
        """Every limit the configuration breaks, as readable sentences (empty when inside)."""
        out = []
        lo, hi = self.stroke
        rot = cfg.rotation
        nx, ny, nz = rot[2], rot[5], rot[8]
        for i in range(3):
            qi = cfg.q[i]
            if not lo <= qi <= hi:
                out.append(f"slider {i + 1} at {qi:.4f} m is outside the stroke [{lo}, {hi}] m")
            phi = cfg.phi[i]
            if abs(phi) > self.rod_angle_max:
                out.append(f"rod {i + 1} inclined {math.degrees(phi):.1f} deg beyond "
                           f"±{math.degrees(self.rod_angle_max):.1f} deg")
            # Rod direction in the base frame: sin φ r̂_i + cos φ ẑ.
            s, c = math.sin(phi), math.cos(phi)
            dot = s * (self.cos_theta[i] * nx + self.sin_theta[i] * ny) + c * nz
            cone = math.acos(max(-1.0, min(1.0, dot)))
            if cone > self.cone_half_angle:
                out.append(f"spherical joint {i + 1} at {math.degrees(cone):.1f} deg beyond its "
                           f"cone ±{math.degrees(self.cone_half_angle):.1f} deg")
        if abs(cfg.roll) > self.roll_max:
            out.append(f"roll {math.degrees(cfg.roll):.2f} deg exceeds "
                       f"±{math.degrees(self.roll_max):.1f} deg")
        if abs(cfg.pitch) > self.pitch_max:
            out.append(f"pitch {math.degrees(cfg.pitch):.2f} deg exceeds "
                       f"±{math.degrees(self.pitch_max):.1f} deg")
        return out

    def check_workspace(self, cfg: Configuration) -> None:
        """Raise ``WorkspaceError`` listing every violated limit."""
        violations = self.workspace_violations(cfg)
        if violations:
            raise WorkspaceError("outside the workspace: " + "; ".join(violations))

    def in_workspace(self, cfg: Configuration) -> bool:
        return not self.workspace_violations(cfg)
