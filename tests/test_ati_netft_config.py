"""The twin's ATI server as third-party clients use it: netftapi2.xml over HTTP, the TCP
calibration command, the real ``pynetft`` client reading its scaling from the twin, the first
record after a long idle, and a software bias averaged over several samples."""
from __future__ import annotations

import json
import socket
import statistics
import subprocess
import sys
import urllib.error
import urllib.request
import xml.etree.ElementTree as ET

import pytest

from rt.ati.config_server import NetFtConfigServer
from rt.ati.netft_config import (
    CAL_INFO_REQUEST,
    CMD_READ_CAL_INFO,
    ForceUnit,
    NetFtConfiguration,
    TorqueUnit,
    decode_cal_info_response,
)
from rt.ati.rdt import CountsPerUnit
from rt.ati.rdt_server import RdtServer
from rt.ati.twin_sensor import BIAS_SAMPLES, AtiSensorParams, SourceReader, TwinAtiSensorModel
from rt.errors import InputError

#: Not the usual 1e6: a client that assumed 1e6 would read forces 1000× too small.
CONFIG = NetFtConfiguration(counts_per_force=1000, counts_per_torque=2000)
LOAD = (1.0, -2.0, -50.0, 0.1, 0.2, -0.3)


def _get(port: int, path: str) -> tuple[int, bytes]:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=5.0) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, b""


def test_the_xml_page_carries_counts_and_units():
    with NetFtConfigServer(CONFIG, http_port=0) as server:
        status, body = _get(server.http_port, "/netftapi2.xml")
        assert status == 200
        root = ET.fromstring(body)
        assert root.tag == "netft"
        fields = {child.tag: child.text for child in root}
        assert fields == {"prodname": "talus twin Net F/T", "cfgcpf": "1000", "cfgcpt": "2000",
                          "scfgfu": "N", "scfgtu": "N-m"}
        assert _get(server.http_port, "/index.html")[0] == 404
        assert server.requests == {"http": 2}


def test_the_tcp_calibration_command_round_trips():
    with NetFtConfigServer(CONFIG, tcp_port=0) as server:
        with socket.create_connection(("127.0.0.1", server.tcp_port), timeout=5.0) as s:
            s.sendall(CAL_INFO_REQUEST.pack(CMD_READ_CAL_INFO))
            answer = b""
            while len(answer) < 24:
                chunk = s.recv(24 - len(answer))
                assert chunk
                answer += chunk
        decoded = decode_cal_info_response(answer)
        assert (decoded.counts_per_force, decoded.counts_per_torque) == (1000, 2000)
        assert decoded.force_unit is ForceUnit.N and decoded.torque_unit is TorqueUnit.N_M
        # An unknown command gets no answer: the connection is closed.
        with socket.create_connection(("127.0.0.1", server.tcp_port), timeout=5.0) as s:
            s.sendall(CAL_INFO_REQUEST.pack(0x7F))
            assert s.recv(24) == b""
        assert server.requests == {"tcp": 1}


@pytest.mark.parametrize("counts", [0, 1.5, 2**32, float("nan")])
def test_a_configuration_the_wire_cannot_carry_is_refused(counts):
    with pytest.raises(InputError, match="counts_per_force"):
        NetFtConfiguration(counts_per_force=counts)


def test_pynetft_reads_its_scaling_from_the_twin():
    pynetft = pytest.importorskip("pynetft")
    model = TwinAtiSensorModel(seed=3)
    counts = CountsPerUnit(CONFIG.counts_per_force, CONFIG.counts_per_torque)
    with RdtServer(model.make_source(LOAD), port=0, counts=counts) as rdt, \
            NetFtConfigServer(CONFIG, http_port=0) as http:
        config = pynetft.Config(sensor_host="127.0.0.1", rdt_port=rdt.port,
                                http_port=http.http_port)
        with pynetft.Client(config) as client:
            assert client.wait_for_first_sample(10.0)
            samples = client.samples(timeout=5.0)
            wrenches = [next(samples).wrench for _ in range(50)]
            calibration = client.health().sensor_configuration.calibration
            assert calibration.counts_per_force_unit == 1000.0
            assert calibration.counts_per_torque_unit == 2000.0
            # Mean of 50 samples: within 4 σ/√50 of the true load (σ: the twin's noise);
            # plus the counts' resolution (1 mN, 0.5 mN m).
            sigma = AtiSensorParams().noise_sigma
            for axis in range(6):
                mean = statistics.fmean(w[axis] for w in wrenches)
                assert mean == pytest.approx(LOAD[axis], abs=4 * sigma[axis] / 50**0.5 + 1e-3)
            client.bias()
            for _ in range(200):          # records still in flight were measured unbiased
                after = next(samples).wrench
            assert abs(after[2]) < 5 * sigma[2]           # was -50 N


def test_serve_ati_cli_serves_the_page_and_reports_its_ports():
    proc = subprocess.Popen([sys.executable, "-m", "talus", "twin", "serve-ati", "--port", "0",
                             "--http-port", "0", "--tcp-port", "0", "--counts-per-force",
                             "1000", "--seconds", "30"], stdout=subprocess.PIPE, text=True)
    try:
        serving = json.loads(proc.stdout.readline())["serving"]
        status, body = _get(serving["http_port"], "/netftapi2.xml")
        assert status == 200 and b"<cfgcpf>1000</cfgcpf>" in body
        assert serving["tcp_port"] > 0 and serving["port"] > 0
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def test_the_first_record_after_a_long_idle_is_not_a_replay_of_it():
    """30 s without a request must not be simulated when streaming resumes: the next record
    comes from at most MAX_CATCH_UP_S of twin time (≤ 0.5 ms of work), not from 30 s (2.6 s
    of work, the bug). An injected clock: no test sleeps 30 s."""
    from rt.twin.serve import MAX_CATCH_UP_S, twin_wrench_source

    now = [100.0]
    source = twin_wrench_source("plate:0.74", None, seed=0, clock=lambda: now[0])
    twin = source.twin
    for _ in range(200):                   # 0.2 s streamed at 1 kHz: the twin keeps time
        now[0] += 0.001
        sample = source()
    assert twin.t == pytest.approx(0.2, abs=2e-3)
    before_t, before_seq = twin.t, sample.ft_sequence
    now[0] += 30.0                         # nobody streams for 30 s
    sample = source()
    assert 0.0 < twin.t - before_t <= MAX_CATCH_UP_S + 1e-9
    assert sample.ft_sequence > before_seq          # a fresh sample, not the old one
    now[0] += 0.001
    source()
    assert twin.t - before_t <= MAX_CATCH_UP_S + 0.001 + 1e-9


def test_bias_averages_several_samples():
    """The bias's own noise is σ/√n: with the default 16 samples about 4× smaller than with
    one (400 biases each, no drift; the spread estimate is good to ≈ 4 %)."""
    params = AtiSensorParams(drift_rate=(0.0,) * 6)
    spread = {}
    for n in (1, BIAS_SAMPLES):
        model = TwinAtiSensorModel(params, seed=11)
        reader = SourceReader(model.make_source(LOAD, clock=lambda: 0.0))
        biases = []
        for _ in range(400):
            assert reader.set_bias(samples=n)
            biases.append(reader.bias[2] - LOAD[2])
        spread[n] = statistics.pstdev(biases)
    sigma = params.noise_sigma[2]
    assert spread[1] == pytest.approx(sigma, rel=0.15)
    assert spread[BIAS_SAMPLES] == pytest.approx(sigma / BIAS_SAMPLES**0.5, rel=0.15)


def test_bias_waits_for_fresh_samples_and_survives_a_dropout():
    ticks = []
    values = iter([((1.0,) * 6, 0, 1), ((1.0,) * 6, 0, 1), ((3.0,) * 6, 0, 2)] + [None] * 50)
    reader = SourceReader(lambda: next(values))
    assert reader.set_bias(samples=4, wait=lambda: ticks.append(1))
    assert reader.bias == [2.0] * 6           # two distinct samples, then a dropout
    assert len(ticks) >= 1                    # the repeated sample was waited for
