"""The calibration wizard driven by its buttons: plan (sites drawn), registration (the
camera's frame with the detected markers and the registered outline drawn), run (progress and
the live force plot, checked against the trial files), fit (PASS/FAIL and the COP error map,
checked against the record), verify, certificate (a PDF read back, never over a file, stored
in the clinical record for the engineer); steps refuse to run out of order; the page is the
calibration engineer's."""
from __future__ import annotations

import itertools
import json
import math
import shutil
import subprocess

import gui_support  # noqa: F401  (offscreen platform before Qt)
import numpy as np
import pytest
from patients_helpers import PASSWORD, open_record, staff
from PySide6.QtCore import Qt
from PySide6.QtGui import QColor

from app.calibration_flow import MARKER_BGR, OUTLINE_BGR, CalibrationFlow, cop_error_points
from app.main_window import MainWindow
from app.pages.calibrate import TABS, CalibratePage
from app.settings import GuiSettings
from calibration.trial import TRIALS_DIR, TrialData
from rt.errors import InputError

WAIT_MS = 300_000
#: A short plan (as the calibration tests use): 2 × 2 grid, three loads.
SHORT_PLAN = """schema_version: 1
name: short test plan
loads_n: [200.0, 800.0, 1500.0]
grid: {nx: 2, ny: 2, margin_m: 0.08}
sine_sites: none
gait_sites: centre
registration: nominal
"""


def test_steps_refuse_to_run_out_of_order(tmp_path):
    from calibration.plate import TWIN_PLATE_FILE

    flow = CalibrationFlow(tmp_path / "cal", TWIN_PLATE_FILE, "direct")
    for step in (flow.register, flow.run, flow.fit, flow.verify):
        with pytest.raises(InputError, match="first"):
            step()
    with pytest.raises(InputError, match="plan"):
        flow.make_plan("schema_version: 1\nloads_n: [-5]\n")
    with pytest.raises(InputError, match="backend"):
        CalibrationFlow(tmp_path / "x", TWIN_PLATE_FILE, "rt").make_plan()
    assert not (tmp_path / "cal").exists()                 # nothing written by a refusal


@pytest.mark.skipif(shutil.which("pdftotext") is None, reason="poppler-utils missing")
def test_engineer_calibrates_a_plate_through_the_wizard(qtbot, tmp_path):
    record = open_record(str(tmp_path / "talus.db"))
    staff(record)
    try:
        window = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path)), record=record)
        qtbot.addWidget(window)
        window.show()
        window.login.user.setText("engineer")
        window.login.password.setText(PASSWORD)
        qtbot.mouseClick(window.login.button, Qt.MouseButton.LeftButton)
        qtbot.waitUntil(lambda: window.actor is not None, timeout=30_000)
        assert window.rail_buttons["calibrate"].isVisible()
        qtbot.mouseClick(window.rail_buttons["calibrate"], Qt.MouseButton.LeftButton)
        page = window.calibrate
        assert [k for k, b in page.buttons.items() if b.isEnabled()] == ["plan"]

        plan = tmp_path / "plan.yaml"
        plan.write_text(SHORT_PLAN)
        page.plan_file.setText(str(plan))
        page.work_folder.setText(str(tmp_path / "work"))
        page.backend.setCurrentIndex(page.backend.findData("direct"))

        def click(step: str) -> None:
            assert page.buttons[step].isEnabled(), step
            qtbot.mouseClick(page.buttons[step], Qt.MouseButton.LeftButton)
            qtbot.waitUntil(lambda: not page.busy, timeout=WAIT_MS)
            assert step in page.done, page.last_error

        click("plan")
        assert "trials at" in page.status.text()
        assert not page.buttons["run"].isEnabled()         # register first
        click("register")                                  # this plan: nominal, no camera
        assert page.camera_view is None and "no camera" in page.camera_caption.text()
        assert not page.buttons["fit"].isEnabled()         # run first
        # What the running trial's curves were given, and which trials had finished then.
        arrivals: list[tuple[object, int]] = []
        page.progress_signal.samples.connect(
            lambda block: arrivals.append((block, len(page.live_series))))
        drawn: list[int] = []
        page.progress_signal.samples.connect(
            lambda _b: drawn.append(len(page.running_curves["ati"].xData)))
        click("run")
        assert page.progress.value() == page.progress.maximum() > 0
        assert not page.plate_file.isEnabled()             # the campaign is fixed now
        flow = page.flow
        assert flow is not None
        _check_live_plot(page, flow)
        _check_live_samples(flow, arrivals, drawn)
        x_running = page.running_curves["ati"].xData
        assert x_running is None or len(x_running) == 0   # the last trial's file took over
        click("fit")
        assert flow.record is not None
        _check_cop_map(page, flow.record)
        verdict = flow.record["verdict"]["pass"]
        assert page.verdict.text() == ("PASS" if verdict else "FAIL")
        m = flow.record["metrics"]
        assert m["nonlinear"]["cop_rms_mm"] < m["before"]["cop_rms_mm"]   # it calibrated
        assert f"{m['nonlinear']['cop_rms_mm']:.1f} mm after" in page.status.text()
        click("verify")
        assert "Verification" in page.status.text()

        out = tmp_path / "certificate.pdf"
        page.ask_path = lambda title, suggested: out
        click("certificate")
        assert page.last_certificate == out
        text = subprocess.run(["pdftotext", "-layout", str(out), "-"], check=True,
                              capture_output=True, text=True).stdout
        assert flow.record["id"] in text
        stored = record.list_calibrations(window.actor)
        assert [c["record_id"] for c in stored] == [flow.record["id"]]
        # again to the same file: refused, the certificate untouched
        before = out.read_bytes()
        page.done.discard("certificate")
        qtbot.mouseClick(page.buttons["certificate"], Qt.MouseButton.LeftButton)
        assert "already exists" in page.status.text()
        assert out.read_bytes() == before
    finally:
        record.close()


def test_only_the_engineer_sees_calibrate(qtbot, tmp_path):
    record = open_record(str(tmp_path / "talus.db"))
    staff(record)
    try:
        window = MainWindow(None, GuiSettings(recordings_dir=str(tmp_path)), record=record)
        qtbot.addWidget(window)
        window.show()
        window.login.user.setText("clinician")
        window.login.password.setText(PASSWORD)
        qtbot.mouseClick(window.login.button, Qt.MouseButton.LeftButton)
        qtbot.waitUntil(lambda: window.actor is not None, timeout=30_000)
        assert not window.rail_buttons["calibrate"].isVisible()
    finally:
        record.close()


def _check_live_plot(page: CalibratePage, flow: CalibrationFlow) -> None:
    """The Trials tab shows every trial of the campaign, in order, each segment on its own
    trial's robot-clock span, and the forces the trial files hold: the ATI's peak is the
    trial's peak load within 1 % (the direct runner presses exactly the commanded load, plus
    the ATI's 0.25 N noise; the plot keeps every 20th sample, which may miss a gait curve's
    sharp peak by a few newtons), the plate's peak through its nominal matrix within 5 % of it
    (the twin plate's drawn sensitivity errors are ±3 %, crosstalk ±2 %)."""
    assert page.tabs.currentIndex() == TABS.index("trials")
    index = json.loads((flow.campaign / "campaign.json").read_text())
    ids = [e["id"] for e in index["trials"]]
    assert [s.trial_id for s in page.live_series] == ids
    assert [s.index for s in page.live_series] == list(range(len(ids)))
    # The data given (getData() is what is drawn: clipped to the view, downsampled).
    x, y = page.live_curves["ati"].xData, page.live_curves["ati"].yData
    xp = page.live_curves["plate"].xData
    assert x is not None and xp is not None and len(x) > 20 * len(ids)
    assert np.isnan(x).sum() == len(ids) == np.isnan(xp).sum()     # one gap after each trial
    for s in page.live_series:
        d = TrialData.load(flow.campaign / TRIALS_DIR / f"{s.trial_id}.npz")
        assert s.t_ati_s[0] == d.t_robot[0] and s.t_ati_s[-1] == d.t_robot[-1]
        peak_ref = float(d.force_ref.max())
        assert float(s.ati_fz_n.max()) == pytest.approx(peak_ref, rel=0.01)
        assert float(s.plate_fz_n.max()) == pytest.approx(peak_ref, rel=0.05)
        assert s.aligned                     # on the robot's clock: the peaks line up
        # Lined up: the plate's curve at the ATI's times differs by its calibration error only.
        inside = (s.t_ati_s >= s.t_plate_s[0]) & (s.t_ati_s <= s.t_plate_s[-1])
        diff = np.interp(s.t_ati_s[inside], s.t_plate_s, s.plate_fz_n) - s.ati_fz_n[inside]
        assert float(np.sqrt(np.mean(diff ** 2))) < 0.05 * peak_ref, s.trial_id
    finite = np.isfinite(y)
    assert float(y[finite].max()) == pytest.approx(
        max(float(s.ati_fz_n.max()) for s in page.live_series))


def _check_live_samples(flow: CalibrationFlow, arrivals: list[tuple[object, int]],
                        drawn: list[int]) -> None:
    """While each trial ran, its samples reached the page before its file's forces did
    (per sample, not per trial), and they are the trial file's own samples: every
    ``k``-th one (50 Hz of the 1 kHz recording), on the file's clock, the commanded force and
    the ATI's load along the tool (``-ati[:, 2]``) exactly; the running curve grew block by
    block."""
    from app.calibration_flow import PLOT_RATE_HZ

    index = json.loads((flow.campaign / "campaign.json").read_text())
    ids = [e["id"] for e in index["trials"]]
    k = round(1.0 / (PLOT_RATE_HZ * 1e-3))
    assert next(b.trial_id for b, _ in arrivals) == ids[0]
    for n, trial_id in enumerate(ids):
        mine = [(b, done) for b, done in arrivals if b.trial_id == trial_id]
        assert mine, trial_id
        assert all(done == n for _, done in mine)    # before the trial's own file's forces
        d = TrialData.load(flow.campaign / TRIALS_DIR / f"{trial_id}.npz")
        t = np.concatenate([b.t_robot for b, _ in mine])
        np.testing.assert_array_equal(t, d.t_robot[::k])
        np.testing.assert_array_equal(np.concatenate([b.force_ref for b, _ in mine]),
                                      d.force_ref[::k])
        np.testing.assert_array_equal(np.concatenate([b.ati_load for b, _ in mine]),
                                      -d.ati[::k, 2])
        assert len(mine) > 1                         # several blocks: it grew while running
    assert max(drawn) > 0 and any(b > a for a, b in itertools.pairwise(drawn))


def test_twin_runner_publishes_its_samples_while_the_trial_runs():
    """The robot twin's trial hands its samples over every 0.5 s of the loop, from the ATI's
    first reading, on the trial file's clock: together they are the trial's recording
    (time, commanded force, the ATI's load along the tool), sample for sample."""
    from calibration.plan import ProfileKind, Trial, default_plan, force_profile
    from calibration.plate import TWIN_PLATE_FILE, load_plate
    from calibration.twin_plate import TruthSettings, TwinPlate, draw_truth
    from calibration.twin_runner import TwinTrialRunner

    plate = load_plate(TWIN_PLATE_FILE)
    truth = draw_truth(plate, TruthSettings.ideal(clock_offset_s=0.1, clock_drift_ppm=0.0))
    runner = TwinTrialRunner(plate, TwinPlate(plate, truth), registration="nominal", seed=3)
    blocks: list = []
    runner.samples = blocks.append
    plan = default_plan()
    trial = Trial(id="push", site="S", site_xy_m=(0.0, 0.0), profile=ProfileKind.STEPS,
                  held_out=False, load_n=300.0)
    profile = force_profile(plan, trial, 1e-3)
    d = runner.run("push", trial.site_xy_m, (plan.pose_z_m, 0.0, 0.0), profile, 1e-3)
    assert len(blocks) > 2 and all(b.trial_id == "push" for b in blocks)
    assert max(len(b.t_robot) for b in blocks) <= 500 + 1          # 0.5 s at 1 kHz
    t = np.concatenate([b.t_robot for b in blocks])
    n = len(d.t_robot)
    np.testing.assert_array_equal(t[:n], d.t_robot)
    np.testing.assert_array_equal(np.concatenate([b.force_ref for b in blocks])[:n],
                                  d.force_ref)
    np.testing.assert_array_equal(np.concatenate([b.ati_load for b in blocks])[:n],
                                  -d.ati[:, 2])
    assert len(t) - n <= 1          # at most the one row the contact tap had not written


def _check_cop_map(page: CalibratePage, record: dict) -> None:
    """The Plate tab after the fit: one hollow marker per site with a COP error before, one
    filled per site after, at the record's positions, each after-marker labelled in mm."""
    import pyqtgraph as pg

    assert page.tabs.currentIndex() == TABS.index("plate")
    items = page.plot.getPlotItem().items
    scatters = [i for i in items if isinstance(i, pg.ScatterPlotItem)]
    drawn = {}
    for sc in scatters:
        xs, ys = sc.getData()
        drawn[sc.name()] = sorted(zip(np.round(xs, 6), np.round(ys, 6), strict=True))
    for stage, name in (("before", "COP error before (mm)"), ("after", "COP error after (mm)")):
        want = sorted((round(x, 6), round(y, 6)) for x, y, _ in cop_error_points(record, stage))
        assert want and drawn[name] == want, stage
    labels = sorted(i.textItem.toPlainText() for i in items if isinstance(i, pg.TextItem))
    assert labels == sorted(f"{e:.1f}" for _x, _y, e in cop_error_points(record, "after"))


CAMERA_PLAN = SHORT_PLAN.replace("registration: nominal", "registration: camera")


def test_registration_shows_the_camera_with_the_markers_drawn(qtbot, tmp_path):
    """The twin camera's frame: both boards' 24 markers detected and outlined, the plate
    outline drawn where the registration put it — within a millimetre of the twin's true
    placement — and shown on the Camera tab at the frame's own size."""
    from calibration.plate import TWIN_PLATE_FILE

    page = CalibratePage()
    qtbot.addWidget(page)
    page.resize(1366 - 150 - 160, 620)
    page.show()
    plan = tmp_path / "plan.yaml"
    plan.write_text(CAMERA_PLAN)
    page.plan_file.setText(str(plan))
    page.work_folder.setText(str(tmp_path / "work"))
    page.plate_file.setText(str(TWIN_PLATE_FILE))
    for step in ("plan", "register"):
        qtbot.mouseClick(page.buttons[step], Qt.MouseButton.LeftButton)
        qtbot.waitUntil(lambda: not page.busy, timeout=WAIT_MS)
        assert step in page.done, page.last_error
    view = page.camera_view
    assert view is not None
    assert page.tabs.currentIndex() == TABS.index("camera")
    assert sorted(view.marker_ids) == sorted(view.expected_ids) and view.markers == 24
    # The registration found the plate: within 3 σ (of a 3-D distance) of the twin's truth,
    # σ of the order the trials' registrations have (the campaign's uncertainty budget).
    assert view.sigma_translation_mm < 1.5
    assert view.error_mm < 3.0 * math.sqrt(3.0) * view.sigma_translation_mm
    frame = page.camera.frame
    assert frame is not None and (frame.width(), frame.height()) == (1600, 1600)
    assert view.image_bgr.shape == (1600, 1600, 3)
    # What is drawn: the marker outlines and the plate outline, in their colours.
    green = QColor(MARKER_BGR[2], MARKER_BGR[1], MARKER_BGR[0])
    red = QColor(OUTLINE_BGR[2], OUTLINE_BGR[1], OUTLINE_BGR[0])
    bgr = view.image_bgr
    n_green = int(np.all(bgr == MARKER_BGR, axis=2).sum())
    assert n_green > 24 * 4 * 20                       # 24 squares' borders
    u, v = np.rint(view.outline_px[0]).astype(int)
    assert frame.pixelColor(int(u), int(v)) == red
    corners = [tuple(int(c) for c in np.argwhere(np.all(bgr == MARKER_BGR, axis=2))[0])]
    r, c = corners[0]
    assert frame.pixelColor(c, r) == green
    # The outline is the plate's size as the camera sees it (0.6 m at 1.2 m, f = 1300 px).
    from calibration.plate import load_plate
    width_m = load_plate(TWIN_PLATE_FILE).size_m[0]
    side_px = float(np.linalg.norm(view.outline_px[0] - view.outline_px[1]))
    assert side_px == pytest.approx(width_m * 1300.0 / 1.2, rel=0.02)
    # Shown scaled into the tab, keeping the frame's aspect.
    pix = page.camera.pixmap()
    assert not pix.isNull() and pix.width() == pix.height() <= page.camera.height()
    assert "24 of 24 markers" in page.camera_caption.text()
