"""Review's list of recordings: titled at once from the file names, then retitled with the
protocols' own names read from the files' metadata on a worker (the file name's
filesystem-safe form loses characters such as "±"); unreadable files keep their file-name
title, and nothing is written to the folder."""
from __future__ import annotations

import shutil
from pathlib import Path

import gui_support  # noqa: F401  (offscreen platform before Qt)
import pytest

from app.pages.review import ReviewPage, recording_title
from app.review_data import recording_protocol_name
from app.settings import GuiSettings
from rt.errors import TalusError

DATA = Path(__file__).parent / "data"
SAMPLE = DATA / "recording_protobuf_v2_2026-11-25.mcap"     # its protocol_name: "sine_fz"
NAME = "20261123T181621Z_P-0007_Sine-Fz-300---100-N-at-1-Hz.mcap"


def test_the_title_takes_the_metadata_name_over_the_file_name() -> None:
    path = Path(NAME)
    assert recording_title(path).endswith("\nSine Fz 300   100 N at 1 Hz")
    title = recording_title(path, "Sine Fz 300 ± 100 N at 1 Hz")
    assert title.endswith("\nSine Fz 300 ± 100 N at 1 Hz") and "P-0007" in title
    assert recording_title(Path("notes.mcap"), "x") == "notes"      # not an RT file name


def test_the_protocol_name_is_read_from_a_complete_and_a_cut_recording(tmp_path: Path) -> None:
    assert recording_protocol_name(SAMPLE) == "sine_fz"
    cut = tmp_path / "cut.mcap"
    blob = SAMPLE.read_bytes()
    cut.write_bytes(blob[: len(blob) * 2 // 3])       # a crash: no summary, no footer
    assert recording_protocol_name(cut) == "sine_fz"
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    with pytest.raises(TalusError, match="junk.mcap"):
        recording_protocol_name(junk)


def test_the_review_list_is_retitled_from_the_files(qtbot, tmp_path: Path) -> None:
    shutil.copyfile(SAMPLE, tmp_path / NAME)
    (tmp_path / "20261122T090000Z_P-0001_Broken.mcap").write_bytes(b"\x89MCAP0\r\n broken")
    before = sorted(p.name for p in tmp_path.iterdir())
    page = ReviewPage(tmp_path, settings=GuiSettings(recordings_dir=str(tmp_path)))
    qtbot.addWidget(page)
    titles = lambda: [page.sessions.item(i).text() for i in range(page.sessions.count())]
    assert page.sessions.count() == 2
    qtbot.waitUntil(lambda: any(t.endswith("\nsine_fz") for t in titles()), timeout=20_000)
    assert any(t.endswith("\nBroken") for t in titles())      # unreadable: file-name title
    assert sorted(p.name for p in tmp_path.iterdir()) == before
