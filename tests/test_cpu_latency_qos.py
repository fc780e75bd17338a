"""The loop's PM QoS request (rt_hygiene.try_cpu_latency_bound): the kernel's request file
gets one 32-bit bound, the request is held while the file is open, shared by every loop of
the process, released by the last one, and refused with a reason when it cannot be made.
A regular file stands in for /dev/cpu_dma_latency (the kernel reads the same 4 bytes)."""
from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from rt.engine import rt_hygiene as h


@pytest.fixture(autouse=True)
def _no_request_left() -> Iterator[None]:
    yield
    while h._qos_users:
        h.release_cpu_latency_bound()


def test_the_request_writes_one_int32_and_is_held_until_the_last_user_releases(tmp_path: Path):
    dev = tmp_path / "cpu_dma_latency"
    dev.write_bytes(b"")
    ok, detail = h.try_cpu_latency_bound(0, path=str(dev))
    assert ok, detail
    assert dev.read_bytes() == (0).to_bytes(4, sys.byteorder, signed=True)
    fd = h._qos_fd
    assert fd is not None
    ok2, detail2 = h.try_cpu_latency_bound(0, path=str(dev))
    assert ok2 and "already held" in detail2
    h.release_cpu_latency_bound()
    assert h._qos_fd == fd                       # the first user still holds it
    h.release_cpu_latency_bound()
    assert h._qos_fd is None and h._qos_users == 0
    h.release_cpu_latency_bound()                # one too many: harmless


def test_a_bound_is_written_in_microseconds(tmp_path: Path):
    dev = tmp_path / "cpu_dma_latency"
    dev.write_bytes(b"")
    assert h.try_cpu_latency_bound(25, path=str(dev))[0]
    assert int.from_bytes(dev.read_bytes(), sys.byteorder, signed=True) == 25


@pytest.mark.parametrize("us", [-1, 2_000_000])
def test_an_impossible_bound_is_refused_and_nothing_is_held(tmp_path: Path, us: int):
    dev = tmp_path / "cpu_dma_latency"
    dev.write_bytes(b"")
    ok, detail = h.try_cpu_latency_bound(us, path=str(dev))
    assert not ok and "[0, 1e6] µs" in detail
    assert h._qos_users == 0 and dev.read_bytes() == b""


def test_a_missing_request_file_is_reported_not_raised(tmp_path: Path):
    ok, detail = h.try_cpu_latency_bound(0, path=str(tmp_path / "absent"))
    assert not ok and "not present" in detail
    assert h._qos_users == 0


def test_realtime_thread_reports_and_undoes_the_request(tmp_path: Path, monkeypatch):
    dev = tmp_path / "cpu_dma_latency"
    dev.write_bytes(b"")
    monkeypatch.setattr(h, "CPU_DMA_LATENCY", str(dev))
    monkeypatch.setattr(h.try_cpu_latency_bound, "__defaults__", (str(dev),))
    with h.realtime_thread(priority=None, lock_memory=False, timer_slack_ns=None,
                           switch_interval_s=None, cpu_latency_us=0) as report:
        assert report.cpu_latency_us == 0 and report.cpu_latency_detail.startswith("ok")
        assert h._qos_users == 1
        assert "CPU wake:   0 µs" in report.summary()
    assert h._qos_users == 0 and h._qos_fd is None
    with h.realtime_thread(priority=None, lock_memory=False, timer_slack_ns=None,
                           switch_interval_s=None) as report:
        assert report.cpu_latency_us is None and report.cpu_latency_detail == "not requested"
