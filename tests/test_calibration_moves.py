"""The operator's move of the plate between sites, confirmed by the camera (calibration.operator,
calibration.site_moves): a move within tolerance passes, a bad one is refused with the measured
offset (scripts) or asked again (a terminal); a run without a terminal and without --yes is
refused before anything moves."""
from __future__ import annotations

import io
import math
import re

import numpy as np
import pytest

from calibration import registration as reg
from calibration.operator import (
    MoveTolerance,
    ScriptOperator,
    SimulatedOperator,
    TerminalOperator,
    pose_offset,
    terminal_or_refuse,
)
from calibration.site_moves import CameraSiteMoves
from calibration.twin_runner import _SiteMoves, site_name
from rt.devices.interfaces import Camera
from rt.errors import InputError

TIP_B = np.array([0.1, 0.0, 0.7])
SITE = (0.1, -0.05)


def test_pose_offset_is_measured_in_the_planned_plate_axes() -> None:
    planned = reg.transform(reg.rot_z(math.radians(90.0)), np.array([0.3, 0.2, 0.7]))
    moved = planned @ reg.transform(reg.rot_z(math.radians(1.5)), np.array([0.004, -0.003, 0.0]))
    off = pose_offset(planned, moved)
    assert (off.dx_m, off.dy_m) == pytest.approx((0.004, -0.003), abs=1e-12)
    assert off.translation_m == pytest.approx(0.005)
    assert math.degrees(off.yaw_rad) == pytest.approx(1.5)
    assert math.degrees(off.rotation_rad) == pytest.approx(1.5)
    assert off.within(MoveTolerance(0.006, math.radians(2.0)))
    assert not off.within(MoveTolerance(0.004, math.radians(2.0)))
    with pytest.raises(InputError, match="positive"):
        MoveTolerance(0.0)


def test_twin_move_within_tolerance_passes_on_the_first_attempt() -> None:
    op = SimulatedOperator()
    moves = _SiteMoves("camera", 5, math.radians(0.1), op)
    true, registered = moves.place(TIP_B, SITE, "G00")
    assert len(op.instructions) == 1 and "site G00 (x +100 mm, y -50 mm" in op.instructions[0]
    # The camera's registration is within a millimetre of the simulated true pose.
    off = pose_offset(true, registered.T_BF)
    assert off.translation_m < 1e-3
    # The same site again: no new move.
    assert moves.place(TIP_B, SITE, "G00")[1] is registered and len(op.instructions) == 1


def test_a_script_is_refused_with_the_offset_the_camera_measured() -> None:
    # A clumsy placement (30 mm σ) against a 10 mm tolerance, no operator to ask again.
    moves = _SiteMoves("camera", 1, math.radians(0.1), SimulatedOperator(interactive=False),
                       placement_sigma_m=0.03)
    with pytest.raises(InputError) as exc:
        moves.place(TIP_B, SITE, "K2")
    msg = str(exc.value)
    assert msg.startswith("site K2: the camera sees the plate ")
    assert "from its planned pose (tolerance 10.0 mm, 2.00°)" in msg
    measured = float(msg.split("the plate ")[1].split(" mm")[0])
    assert measured > 10.0
    assert moves.current is None            # nothing registered for the site


def test_an_operator_is_asked_again_with_the_offset_until_the_move_is_right() -> None:
    op = SimulatedOperator(interactive=True)
    moves = _SiteMoves("camera", 1, math.radians(0.1), op, placement_sigma_m=0.012)
    _true, registered = moves.place(TIP_B, SITE, "K2")
    assert len(op.instructions) >= 2
    assert "the camera sees the plate" in op.instructions[1]
    assert "Adjust it so that site K2 is under the tool tip" in op.instructions[1]
    assert pose_offset(reg.nominal_T_BF(TIP_B, SITE), registered.T_BF).translation_m <= 0.010


class RigCamera(Camera):
    """A real camera's interface showing the twin rig's boards with the plate at ``pose``."""

    def __init__(self, rig: reg.MarkerRig, T_BF_centre: np.ndarray) -> None:
        self.rig, self.centre = rig, T_BF_centre
        self.pose = T_BF_centre
        self.rng = np.random.default_rng(0)
        self.frames = 0

    def read(self) -> tuple[np.ndarray, float]:
        self.frames += 1
        return reg.render_rig(self.rig, self.pose, self.centre, self.rng), 0.0

    def _close(self) -> None:
        pass


def test_real_plate_moves_wait_for_the_operator_and_the_camera_confirms() -> None:
    rig = reg.MarkerRig()
    centre = reg.nominal_T_BF(TIP_B, (0.0, 0.0))
    camera = RigCamera(rig, centre)
    planned = reg.nominal_T_BF(TIP_B, SITE)
    # The operator first leaves the plate 15 mm off, then gets it right; Enter each time.
    placements = iter([planned @ reg.transform(np.eye(3), np.array([0.015, 0.0, 0.0])),
                       planned @ reg.transform(np.eye(3), np.array([0.001, 0.0, 0.0]))])

    class Terminal(io.StringIO):
        def readline(self, *a: object) -> str:
            camera.pose = next(placements)
            return "\n"

    out = io.StringIO()
    moves = CameraSiteMoves(TerminalOperator(Terminal(), out), camera, frames=2)
    _T, registered = moves.place(TIP_B, SITE, "G20")
    text = out.getvalue()
    assert text.count("Enter when done") == 2
    measured = re.search(r"site G20: the camera sees the plate ([\d.]+) mm \(x ([+-][\d.]+)",
                         text)
    assert measured is not None
    # 15 mm off along x, as measured by the camera (its registration is good to ≈ 0.5 mm).
    assert float(measured[1]) == pytest.approx(15.0, abs=0.5)
    assert float(measured[2]) == pytest.approx(15.0, abs=0.5)
    assert pose_offset(planned, registered.T_BF).translation_m < 2.5e-3
    assert camera.frames == 4
    # The operator stops the campaign.
    moves2 = CameraSiteMoves(TerminalOperator(io.StringIO("q\n"), io.StringIO()), camera)
    with pytest.raises(InputError, match="the operator stopped the campaign"):
        moves2.place(TIP_B, (0.0, 0.1), "G12")
    # --yes: not waiting; outside the tolerance refused with the offset.
    camera.pose = planned @ reg.transform(reg.rot_z(math.radians(4.0)), np.zeros(3))
    moves3 = CameraSiteMoves(ScriptOperator(), camera, frames=1)
    with pytest.raises(InputError, match=r"site G20: .* and 4\.\d\d° \(yaw \+4\.\d\d°\)"):
        moves3.place(TIP_B, SITE, "G20")


def test_no_terminal_and_no_yes_is_refused_before_anything_moves() -> None:
    with pytest.raises(InputError, match="no terminal to ask on: run it in a terminal, or "
                                         "pass --yes"):
        terminal_or_refuse(False, io.StringIO())
    assert isinstance(terminal_or_refuse(True, io.StringIO()), ScriptOperator)


def test_site_names_of_trial_ids() -> None:
    assert site_name("G11-steps-2") == "G11"
    assert site_name("K3-sine") == "K3"
    assert site_name("V-c0-hold") == "V-c0"
    assert site_name("H0-gait") == "H0"
