"""Nothing lost: the output-file rules every writing command follows (rt.output_files)."""
from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from rt.output_files import (
    OutputFileError,
    atomic_output,
    check_output,
    commit_output,
    partial_path,
)


def _names(d: Path) -> list[str]:
    return sorted(p.name for p in d.iterdir())


def test_an_input_is_refused_by_any_name(tmp_path: Path) -> None:
    src = tmp_path / "in.mcap"
    src.write_bytes(b"data")
    (tmp_path / "hard.mcap").hardlink_to(src)
    (tmp_path / "soft.mcap").symlink_to(src)
    for out in (src, tmp_path / "hard.mcap", tmp_path / "soft.mcap", tmp_path / "." / "in.mcap"):
        with pytest.raises(OutputFileError, match="is also an input"):
            check_output(out, [src], force=True)
    assert src.read_bytes() == b"data"


def test_existing_outputs_directories_and_missing_directories(tmp_path: Path) -> None:
    old = tmp_path / "old.csv"
    old.write_text("keep")
    with pytest.raises(OutputFileError, match="exists; refused"):
        check_output(old)
    assert check_output(old, force=True) == old
    with pytest.raises(OutputFileError, match="is a directory"):
        check_output(tmp_path, force=True)
    with pytest.raises(OutputFileError, match="does not exist"):
        check_output(tmp_path / "nope" / "x.csv")


def test_a_failed_write_leaves_the_old_file_and_no_partial(tmp_path: Path) -> None:
    out = tmp_path / "out.csv"
    out.write_text("previous")
    with pytest.raises(RuntimeError), atomic_output(out, force=True) as f:
        f.write("half")
        raise RuntimeError("the channel does not exist")
    assert out.read_text() == "previous" and _names(tmp_path) == ["out.csv"]
    with atomic_output(out, force=True) as f:
        f.write("new")
    assert out.read_text() == "new" and _names(tmp_path) == ["out.csv"]


def test_a_new_output_gets_the_usual_permissions(tmp_path: Path) -> None:
    umask = os.umask(0o022)
    try:
        with atomic_output(tmp_path / "a.csv") as f:
            f.write("x")
    finally:
        os.umask(umask)
    assert stat.S_IMODE((tmp_path / "a.csv").stat().st_mode) == 0o644   # not mkstemp's 0600


def test_a_file_appearing_meanwhile_is_not_overwritten(tmp_path: Path) -> None:
    out = tmp_path / "race.csv"
    partial = partial_path(out)
    partial.write_text("ours")
    out.write_text("someone else's")               # created between check and commit
    with pytest.raises(OutputFileError, match="kept in"):
        commit_output(partial, out, force=False)
    assert out.read_text() == "someone else's" and partial.read_text() == "ours"
