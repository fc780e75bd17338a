"""Run's live ankle view: while the telemetry carries the ankle's state (an exercise about the
patient's ankle centre), the angle plot shows the foot's angles from neutral with references
derived from the platform's, the readout names them, the torques and the centre's displacement
in clinical words, and the platform's own angles sit behind an engineer toggle; without those
fields the view is hidden and the platform's angles are plotted as before. Repetitions count on
the ankle's angles from neutral when they arrive."""
from __future__ import annotations

import math

import gui_support  # noqa: F401  (offscreen platform before Qt)
import numpy as np
import pytest
from PySide6.QtCore import Qt

from app.pages.run import ANKLE_CURVES, PLATFORM_CURVES, RunPage
from app.patient_context import PatientContext
from app.rt_link import RtLink
from app.telemetry import RepetitionCounter, TelemetryRing
from protocols.library import LIBRARY_DIR
from protocols.rt_session import protocol_document

#: The neutral pose the foot was strapped at (platform roll, pitch, degrees).
ROLL0, PITCH0 = -2.0, 5.0
LEFT = {"side": "left", "height_above_sole_m": 0.08, "offset_x_m": 0.0, "offset_y_m": 0.0,
        "sole_above_sensor_m": 0.0, "source": "entered"}


def _ankle_sample(t: float, plantar_deg: float, inversion_deg: float, *, ref_lead_deg: float = 1.0,
                  session: str = "S1", flat: bool = False) -> dict:
    """A left foot (inversion is −roll from neutral, rt.model.ankle.ankle_angles): the platform
    at the neutral pose plus the ankle's rotation; the reference leads by ``ref_lead_deg``.
    The ankle's state as the RT process publishes it (its last ``/ankle/state`` message under
    ``ankle``), or as flat ``ankle_*`` fields (``flat``)."""
    roll = ROLL0 - inversion_deg
    pitch = PITCH0 + plantar_deg
    msg = {"t": t, "pose": [0.63, math.radians(roll), math.radians(pitch)],
           "pose_ref": [0.63, math.radians(roll - ref_lead_deg),
                        math.radians(pitch + ref_lead_deg)],
           "force_ref_n": 0.0, "force_n": 20.0, "progress": t / 60.0, "phase": "play",
           "session": session}
    if flat:
        msg.update({"ankle_dfpf_deg": plantar_deg, "ankle_inev_deg": inversion_deg,
                    "ankle_torque_dfpf_nm": -4.25, "ankle_torque_inev_nm": 1.5,
                    "ankle_centre_displacement_mm": 13.0})
    else:
        msg["ankle"] = {"t": t, "plantarflexion_deg": plantar_deg,
                        "inversion_deg": inversion_deg, "abduction_deg": 0.1,
                        "plantarflexion_torque_nm": -4.25, "inversion_torque_nm": 1.5,
                        "abduction_torque_nm": 0.0, "centre_displacement_mm": [3.0, 4.0, 12.0],  # 5 mm horizontally,
                        "platform_roll_deg": roll, "platform_pitch_deg": pitch}
    return msg


def _legend(page: RunPage) -> list[str]:
    legend = page.angle_plot.getPlotItem().legend
    return [label.text for _sample, label in legend.items]


@pytest.fixture()
def page(qtbot):
    link = RtLink("tcp://127.0.0.1:9")      # not started: nothing is contacted
    p = RunPage(link)
    qtbot.addWidget(p)
    p.resize(1100, 640)
    p.show()
    p.set_patient(PatientContext("P-1", 70.0, {
        "roll_min_deg": -8.0, "roll_max_deg": 8.0, "pitch_min_deg": -12.0,
        "pitch_max_deg": 12.0}, side="left", ankle=LEFT))
    yield p
    link.close()


def test_ankle_view_shows_the_foot_from_neutral_and_hides_without_the_fields(page, qtbot):
    ring = page.link.telemetry
    # Without the ankle fields: the platform's angles, no ankle view.
    ring.push({"t": 0.0, "pose": [0.63, 0.0, math.radians(3.0)],
               "pose_ref": [0.63, 0.0, math.radians(3.0)], "phase": "play", "session": "S1",
               "wrench": [None] * 6})
    page.redraw()
    assert not page.ankle_mode
    assert page.ankle_angles_label.isHidden() and page.engineer_button.isHidden()
    assert all(page.curves[k].isVisible() for k in PLATFORM_CURVES)
    assert not any(page.curves[k].isVisible() for k in ANKLE_CURVES)
    assert page.angle_plot.getPlotItem().titleLabel.text == "Ankle angles (°)"

    # With them: the ankle from neutral; the platform's curves go to the engineer view.
    ring.clear()
    motion = [(i / 30, 8.0 * math.sin(i / 20), -3.0 * math.sin(i / 20)) for i in range(300)]
    for i, (t, pf, ie) in enumerate(motion):
        ring.push(_ankle_sample(t, pf, ie, flat=i % 2 == 1))        # either shape reads alike
    page.redraw()
    assert page.ankle_mode
    assert all(page.curves[k].isVisible() for k in ANKLE_CURVES)
    assert not any(page.curves[k].isVisible() for k in PLATFORM_CURVES)
    assert page.angle_plot.getPlotItem().titleLabel.text == "Ankle angles from neutral (°)"
    assert _legend(page) == ["ankle: plantar(+)/dorsi(−) flexion from neutral",
                             "ankle: inversion(+)/eversion(−) from neutral"]
    _t, dfpf = page.curves["ankle_dfpf"].getData()
    _t, inev = page.curves["ankle_inev"].getData()
    assert dfpf == pytest.approx([m[1] for m in motion]) and inev == pytest.approx(
        [m[2] for m in motion])
    # The references from neutral: the platform's less the neutral pose (the lead survives).
    _t, dfpf_ref = page.curves["ankle_dfpf_ref"].getData()
    _t, inev_ref = page.curves["ankle_inev_ref"].getData()
    assert dfpf_ref == pytest.approx(np.array([m[1] for m in motion]) + 1.0, abs=1e-9)
    assert inev_ref == pytest.approx(np.array([m[2] for m in motion]) + 1.0, abs=1e-9)
    # The ROM band is about neutral (left foot: the roll band mirrored), and in view.
    lo, hi = page.angle_plot.getViewBox().viewRange()[1]
    assert lo <= -12.0 and hi >= 12.0
    last_pf, last_ie = motion[-1][1], motion[-1][2]
    words = page.ankle_angles_label.text()
    pf_word = "plantarflexion" if last_pf >= 0 else "dorsiflexion"
    ie_word = "inversion" if last_ie >= 0 else "eversion"
    assert words == (f"Ankle from neutral: {pf_word} {abs(last_pf):.1f}°, {ie_word} "
                     f"{abs(last_ie):.1f}° — the ankle centre moved 13 mm (comfort limit 30 mm)")
    assert page.ankle_label.text() == "Ankle torque: dorsiflexion 4.2 N·m, inversion 1.5 N·m"
    assert page.platform_label.isHidden()

    # The engineer view: the platform's measured angles dotted, their values in words.
    qtbot.mouseClick(page.engineer_button, Qt.MouseButton.LeftButton)
    ring.push(_ankle_sample(10.0, 4.0, -1.0))
    page.redraw()
    assert page.curves["pitch"].isVisible() and page.curves["roll"].isVisible()
    assert page.curves["pitch"].opts["pen"].style() == Qt.PenStyle.DotLine
    assert not page.curves["pitch_ref"].isVisible()
    assert "platform pitch (engineers)" in _legend(page)
    _t, pitch = page.curves["pitch"].getData()
    assert pitch[-1] == pytest.approx(PITCH0 + 4.0)
    assert page.platform_label.text() == (f"Platform (engineers): roll {ROLL0 + 1.0:+.1f}°, "
                                          f"pitch {PITCH0 + 4.0:+.1f}°")
    qtbot.mouseClick(page.engineer_button, Qt.MouseButton.LeftButton)
    assert not page.curves["pitch"].isVisible() and page.platform_label.isHidden()

    # A torque hold regulated on the ankle: its target now, in words.
    ring.push({**_ankle_sample(10.05, 0.0, 0.0), "ankle_target": {
        "hold": 2, "direction": "dorsiflexion", "target_nm": 6.0, "now_nm": -3.25}})
    page.redraw()
    assert page.ankle_angles_label.text().endswith(
        "\nHold 2: dorsiflexion 6.0 N·m (target now 3.2 N·m)")
    assert "the ankle centre moved 5 mm" in page.ankle_angles_label.text()   # horizontal

    # A sample whose ankle fields are missing reads as a dash, not an invented angle.
    ring.push({**_ankle_sample(10.1, 0.0, 0.0, flat=True), "ankle_dfpf_deg": None,
               "ankle_torque_inev_nm": None})
    page.redraw()
    assert page.ankle_angles_label.text().startswith("Ankle from neutral: —")
    assert page.ankle_label.text() == "Ankle torque: —"

    # The next session without the fields: the ankle view goes away.
    ring.clear()
    ring.push({"t": 20.0, "pose": [0.63, 0.0, 0.0], "pose_ref": [0.63, 0.0, 0.0],
               "phase": "play", "session": "S2", "wrench": [0.0, 0.0, -50.0, 0.0, 0.0, 0.0]})
    page.redraw()
    assert not page.ankle_mode and page.ankle_angles_label.isHidden()
    assert page.engineer_button.isHidden()
    assert page.ankle_label.text().startswith("Ankle torque: ")   # from the wrench (setup)
    assert all(page.curves[k].isVisible() for k in PLATFORM_CURVES)
    assert page.curves["pitch"].opts["pen"].style() == Qt.PenStyle.SolidLine


def test_repetitions_count_on_the_ankle_from_neutral():
    """A foot strapped 8° plantarflexed: ±10° about that neutral never takes the platform's
    pitch below −5° (half the dorsiflexion amplitude), so counting on the platform would find
    no repetition; the ankle's angles from neutral count all of them."""
    doc = protocol_document(LIBRARY_DIR / "ankle_rom.yaml")
    amp = doc["amplitude_deg"]
    ext = min(amp["dorsiflexion"], amp["plantarflexion"])
    motion: list[float] = []
    for _ in range(3):
        for a, b in ((0.0, -ext), (-ext, ext), (ext, 0.0)):
            motion += list(np.linspace(a, b, 40))
    for with_ankle, expected in ((True, 3), (False, None)):
        ring = TelemetryRing(100)
        counter = RepetitionCounter.for_protocol({**doc, "sequence": ["dorsi_plantar"],
                                                  "repetitions": 3})
        assert counter is not None
        ring.count_repetitions("S1", counter)
        for i, a in enumerate(motion):
            msg = _ankle_sample(i / 30, a, 0.0)
            msg["pose"][2] = math.radians(8.0 + a)
            if not with_ankle:
                del msg["ankle"]
            ring.push(msg)
        reps = ring.repetitions()
        assert reps is not None
        if expected is not None:
            assert reps == (3, 3)
        else:
            assert reps[0] < 3
