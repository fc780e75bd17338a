"""The ankle centre measured with the camera (issue 17): ArUco markers on both malleoli and the
platform's board in one frame of the twin camera, rendered where a known truth puts them; the
measurement recovers the truth, states its uncertainty, refuses a frame without both markers,
and ``talus patients ankle --measure`` stores it as a camera setup."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from patients_helpers import fast_hasher

from patients.ankle_camera import (
    MalleoliRig,
    measure_malleoli,
    render_malleoli,
    twin_malleoli,
)
from rt.errors import InputError
from rt.model.ankle import AnkleSetup
from rt.model.description import load_description
from talus.cli import main

OFFSET = list(load_description().sensor.offset_m)
RIG = MalleoliRig()
#: Tolerance on the centre (m, per axis). Single 40 mm markers ~0.57 m from a 1000 px camera:
#: a corner error of ~0.1 px moves a marker's centre ≈ z²·σ/(f·L/2) ≈ 1.6 mm along the
#: optical axis (much less across it); measured on the twin: the markers' centres 1.3-2.1 mm
#: too far (the sub-pixel corners' inward bias), the board ≤ 0.15 mm, the ankle centre
#: ≤ 1.7 mm off. 3 mm leaves room and stays below palpation's few mm.
CENTRE_TOL_M = 3.0e-3


@pytest.mark.parametrize("truth", [
    AnkleSetup(side="right", height_above_sole_m=0.07, offset_x_m=0.0),
    AnkleSetup(side="left", height_above_sole_m=0.085, offset_x_m=0.02, offset_y_m=-0.015),
    AnkleSetup(side="right", height_above_sole_m=0.06, offset_x_m=-0.01, offset_y_m=0.01,
               sole_above_sensor_m=0.012),
])
def test_the_camera_recovers_the_twin_ankle_centre(truth) -> None:
    frame = render_malleoli(RIG, *twin_malleoli(truth, OFFSET))
    m = measure_malleoli(frame, RIG, truth.side, OFFSET, truth.sole_above_sensor_m)
    got = m.setup
    assert got.source == "camera" and got.side == truth.side
    for name in ("height_above_sole_m", "offset_x_m", "offset_y_m"):
        assert getattr(got, name) == pytest.approx(getattr(truth, name), abs=CENTRE_TOL_M), name
    # The stated uncertainty is small and consistent with the error actually made.
    assert all(0.0 < s < 2.0e-3 for s in m.centre_sigma_m)
    err = np.array([got.offset_x_m - truth.offset_x_m, got.offset_y_m - truth.offset_y_m,
                    got.height_above_sole_m - truth.height_above_sole_m])
    assert np.all(np.abs(err) <= 4.0 * np.array(m.centre_sigma_m) + 2e-4)
    assert m.reprojection_rms_px < 0.5


@pytest.mark.parametrize("hide, words", [
    ("medial", r"the medial malleolus marker \(id 41\)"),
    ("lateral", r"the lateral malleolus marker \(id 40\)"),
    ("board", r"the platform's board \(ids 0-5: 0 of its markers seen"),
])
def test_a_frame_without_both_markers_and_the_board_is_refused(hide, words) -> None:
    lat, med = twin_malleoli(AnkleSetup(side="right", height_above_sole_m=0.07), OFFSET)
    frame = render_malleoli(RIG, None if hide == "lateral" else lat,
                            None if hide == "medial" else med, show_board=hide != "board")
    with pytest.raises(InputError, match=r"camera frame refused: not seen: .*" + words):
        measure_malleoli(frame, RIG, "right", OFFSET)


def test_markers_on_the_wrong_foot_are_refused() -> None:
    lat, med = twin_malleoli(AnkleSetup(side="right", height_above_sole_m=0.07), OFFSET)
    frame = render_malleoli(RIG, lat, med)
    with pytest.raises(InputError, match="medial marker is on the lateral side of a left foot"):
        measure_malleoli(frame, RIG, "left", OFFSET)


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_patients_ankle_measure_stores_a_camera_setup(tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.setattr("patients.passwords.default_hasher", fast_hasher)
    db = ["--db", f"sqlite:///{tmp_path / 'clinic.db'}"]
    monkeypatch.setenv("TALUS_PASSWORD", "admin password 1")
    monkeypatch.setenv("TALUS_NEW_PASSWORD", "clinician password 1")
    assert _run(capsys, "users", "init", *db, "--user", "root")[0] == 0
    assert _run(capsys, "users", "add", "ana", "--role", "clinician", *db, "--user",
                "root")[0] == 0
    monkeypatch.setenv("TALUS_PASSWORD", "clinician password 1")
    code, out, _ = _run(capsys, "patients", "add", "--mass-kg", "70", "--side", "left", *db,
                        "--user", "ana", "--json")
    assert code == 0, out
    patient = json.loads(out)["code"]
    code, out, _ = _run(capsys, "patients", "ankle", patient, "--measure", "--twin-truth",
                        "0.08,0.015,-0.01", *db, "--user", "ana", "--json")
    assert code == 0, out
    got = json.loads(out)
    assert got["source"] == "camera" and got["side"] == "left"
    assert got["height_above_sole_m"] == pytest.approx(0.08, abs=CENTRE_TOL_M)
    assert got["offset_x_m"] == pytest.approx(0.015, abs=CENTRE_TOL_M)
    assert got["offset_y_m"] == pytest.approx(-0.01, abs=CENTRE_TOL_M)
    assert "centre σ (x, y, z)" in got["reason"]
    # A frame without the medial marker: refused in one line, nothing stored.
    lat, _ = twin_malleoli(AnkleSetup(side="left", height_above_sole_m=0.07), OFFSET)
    frame = tmp_path / "frame.png"
    cv2.imwrite(str(frame), render_malleoli(RIG, lat, None))
    code, out, _ = _run(capsys, "patients", "ankle", patient, "--measure", "--frame",
                        str(frame), *db, "--user", "ana", "--json")
    assert code == 2 and "medial malleolus marker (id 41)" in json.loads(out)["error"]
    code, out, _ = _run(capsys, "patients", "ankle", patient, *db, "--user", "ana", "--json")
    assert json.loads(out)["offset_x_m"] == pytest.approx(0.015, abs=CENTRE_TOL_M)
