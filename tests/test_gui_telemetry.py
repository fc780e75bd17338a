"""Live telemetry off the GUI thread: the ring keeps the last samples in order and in SI units,
decodes missing values as gaps; repetitions of ROM and active-assist exercises are counted from
the measured angles while the reference plays, for the running session only; the Run page draws
the ring and shows the count."""
from __future__ import annotations

import math
import threading

import gui_support  # noqa: F401  (offscreen platform before Qt)
import numpy as np
import pytest

from app.telemetry import RepetitionCounter, TelemetryRing
from protocols.library import LIBRARY_DIR
from protocols.rt_session import protocol_document


def _sample(t: float, pitch_deg: float = 0.0, roll_deg: float = 0.0, *, session: str = "S1",
            phase: str = "play", force: float | None = 100.0) -> dict:
    return {"t": t, "pose": [0.63, math.radians(roll_deg), math.radians(pitch_deg)],
            "pose_ref": [0.63, math.radians(roll_deg), math.radians(pitch_deg)],
            "force_ref_n": 100.0, "force_n": force, "progress": t / 100.0, "phase": phase,
            "session": session}


def _rom_motion(amplitude_deg: float, reps: int, dt: float = 1 / 60) -> list[float]:
    """neutral → one end → the other → neutral, ``reps`` times (what ankle_rom plays)."""
    out: list[float] = []
    for _ in range(reps):
        for a, b in ((0.0, -amplitude_deg), (-amplitude_deg, amplitude_deg),
                     (amplitude_deg, 0.0)):
            n = max(2, int(abs(b - a) / 10.0 / dt))      # 10 deg/s
            out += list(np.linspace(a, b, n))
    return out


def test_ring_keeps_the_last_samples_oldest_first_in_si():
    ring = TelemetryRing(5)
    for i in range(8):
        ring.push(_sample(float(i), pitch_deg=float(i)))
    n, col = ring.snapshot()
    assert n == 8
    assert col["t"].tolist() == [3.0, 4.0, 5.0, 6.0, 7.0]          # wrapped, in order
    assert np.allclose(np.degrees(col["pitch"]), [3, 4, 5, 6, 7])
    col["t"][:] = -1.0                                               # a copy: the ring is safe
    assert ring.snapshot()[1]["t"][0] == 3.0
    ring.push({"t": 8.0, "pose": None, "force_n": None})             # missing → gaps, not 0
    last = {k: v[-1] for k, v in ring.snapshot()[1].items()}
    assert last["t"] == 8.0 and math.isnan(last["force"]) and math.isnan(last["pitch"])
    ring.clear()
    assert ring.snapshot()[0] == 0 and ring.snapshot()[1]["t"].size == 0
    with pytest.raises(ValueError, match="capacity"):
        TelemetryRing(1)


def test_ring_is_written_and_read_from_two_threads_without_tearing():
    ring = TelemetryRing(200)
    stop = threading.Event()

    def write() -> None:
        i = 0
        while not stop.is_set():
            ring.push(_sample(float(i), pitch_deg=float(i % 20)))
            i += 1
    writer = threading.Thread(target=write)
    writer.start()
    try:
        for _ in range(300):
            _n, col = ring.snapshot()
            t = col["t"]
            if t.size > 1:     # consecutive samples: never a half-written or reordered row
                assert np.all(np.diff(t) == 1.0)
                assert np.allclose(np.degrees(col["pitch"]), t % 20)
    finally:
        stop.set()
        writer.join()


def test_ankle_rom_repetitions_are_counted_per_axis_from_the_library_protocol():
    doc = protocol_document(LIBRARY_DIR / "ankle_rom.yaml")   # ±10° pitch, ±8° roll, 3 reps
    counter = RepetitionCounter.for_protocol(doc)
    assert counter is not None and counter.expected == 6
    assert counter.axes == {"pitch": (-5.0, 5.0), "roll": (-4.0, 4.0)}
    for a in _rom_motion(10.0, 3):
        counter.feed(a, 0.0)
    assert counter.count == 3
    for a in _rom_motion(8.0, 3):
        counter.feed(0.0, a)
    assert counter.count == 6
    # noise around neutral and a half-hearted swing below half the range count nothing
    for a in np.sin(np.linspace(0, 40 * np.pi, 2000)) * 4.0:
        counter.feed(float(a), float(a) * 0.9)
    assert counter.count == 6
    assert RepetitionCounter.for_protocol(
        protocol_document(LIBRARY_DIR / "sine_fz.yaml")) is None   # force protocols: none


def test_active_assist_counts_guide_cycles_on_its_axis():
    doc = protocol_document(LIBRARY_DIR / "active_assist.yaml")  # -10..+15°, 60 s, 8 s period
    counter = RepetitionCounter.for_protocol(doc)
    assert counter is not None and counter.expected == 7
    assert counter.axes == {"pitch": (-5.0, 7.5)}
    t = np.arange(0.0, 60.0, 1 / 60)
    for a in 12.5 * np.sin(2 * np.pi * t / 8.0) + 2.5:                # -10..+15 every 8 s
        counter.feed(float(a), 0.0)
    assert counter.count == 7                                         # 60 s / 8 s = 7.5


def test_ring_counts_only_the_running_session_while_it_plays():
    ring = TelemetryRing(100)
    doc = protocol_document(LIBRARY_DIR / "ankle_rom.yaml")
    ring.count_repetitions("S1", RepetitionCounter.for_protocol(doc))
    motion = _rom_motion(10.0, 2)
    for i, a in enumerate(motion):
        ring.push(_sample(i / 60, pitch_deg=a, phase="approach"))      # not yet playing
        ring.push(_sample(i / 60, pitch_deg=a, session="OTHER"))       # someone else's
    assert ring.repetitions() == (0, 6)
    for i, a in enumerate(motion):
        ring.push(_sample(i / 60, pitch_deg=a))
    assert ring.repetitions() == (2, 6)
    ring.count_repetitions(None, None)
    assert ring.repetitions() is None


def test_run_page_draws_the_ring_and_shows_the_repetitions(qtbot):
    from app.pages.run import WINDOW_S, RunPage
    from app.patient_context import PatientContext
    from app.rt_link import RtLink

    link = RtLink("tcp://127.0.0.1:9")      # not started: nothing is contacted
    try:
        page = RunPage(link)
        qtbot.addWidget(page)
        page.resize(1000, 600)
        page.show()
        page.set_patient(PatientContext("P-1", 70.0, {
            "roll_min_deg": -8.0, "roll_max_deg": 8.0, "pitch_min_deg": -12.0,
            "pitch_max_deg": 12.0, "max_force_n": 600.0, "max_angular_speed_deg_s": 30.0},
            side="left"))
        page.prescribe(protocol_document(LIBRARY_DIR / "ankle_rom.yaml"))
        page._replied("session_start", {"session_id": "S1", "duration_s": 60.0}, "")
        motion = _rom_motion(10.0, 3)
        for i, a in enumerate(motion):
            link.telemetry.push(_sample(i / 60, pitch_deg=a, roll_deg=3.0))
        frames = page.frames
        page.redraw()
        page.redraw()                        # nothing new: no second frame
        assert page.frames == frames + 1
        t, y = page.curves["pitch"].getData()
        duration = (len(motion) - 1) / 60
        assert t[-1] == 0.0                                  # "now" at 0 on a fixed axis
        assert t[0] == pytest.approx(-min(WINDOW_S, duration), abs=1 / 60)  # the last 20 s
        assert y[-1] == pytest.approx(motion[-1])
        _t, roll = page.curves["roll"].getData()
        assert roll[-1] == pytest.approx(-3.0)          # left foot: +roll is eversion
        assert page.reps_label.text() == "Repetitions: 3 of 6"
        assert page.force_plot.getViewBox().viewRange()[0] == pytest.approx([-WINDOW_S, 0.0])
    finally:
        link.close()
