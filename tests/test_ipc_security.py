"""Wire safety of the RT server: loopback by default, CurveZMQ off loopback, bounded frames.

Real ZeroMQ sockets on loopback; the oversized-frame test runs the server in a child process
so its peak resident memory (``VmHWM``) is its own.
"""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import zmq

from rt.errors import ConfigurationError
from rt.ipc.client import RtClient, RtUnavailableError
from rt.ipc.security import ClientCurveConfig, ServerCurveConfig, is_loopback, make_keys
from rt.ipc.server import RtServer
from talus.cli import main as talus_main

ANY_PORT = "tcp://127.0.0.1:*"


class AnswerAll:
    """A handler answering every command with its name and arguments (the caller's id,
    which every handler method receives as ``client``, left out)."""

    def __getattr__(self, cmd: str) -> Any:
        if cmd.startswith("_"):
            raise AttributeError(cmd)
        return lambda client, **kwargs: {"did": cmd, **kwargs}


@pytest.fixture()
def keys(tmp_path: Path) -> dict[str, Path]:
    """A server pair, an allowed client pair and a stranger's pair."""
    allowed = tmp_path / "allowed"
    server_pub, server_secret = make_keys(tmp_path / "server", "server")
    client_pub, client_secret = make_keys(tmp_path / "client", "ws-1")
    _, stranger_secret = make_keys(tmp_path / "stranger", "ws-2")
    allowed.mkdir()
    (allowed / client_pub.name).write_bytes(client_pub.read_bytes())
    return {"server_pub": server_pub, "server_secret": server_secret,
            "client_secret": client_secret, "stranger_secret": stranger_secret,
            "allowed": allowed}


@pytest.fixture()
def curve_server(keys: dict[str, Path]) -> Iterator[RtServer]:
    cfg = ServerCurveConfig(secret_key_file=keys["server_secret"],
                            allowed_clients_dir=keys["allowed"])
    with RtServer(AnswerAll(), ANY_PORT, ANY_PORT, curve=cfg) as server:
        yield server


@pytest.mark.parametrize("endpoint, loopback", [
    ("tcp://127.0.0.1:5560", True), ("tcp://127.1.2.3:5560", True), ("tcp://[::1]:5560", True),
    ("tcp://localhost:5560", True), ("tcp://lo:5560", True), ("ipc:///tmp/talus", True),
    ("inproc://rt", True), ("tcp://*:5560", False), ("tcp://0.0.0.0:5560", False),
    ("tcp://192.168.1.20:5560", False), ("tcp://eth0:5560", False), ("tcp://[::]:5560", False),
    ("tcp://10.0.0.1;127.0.0.1:5560", True), ("tcp://127.0.0.1;10.0.0.2:5560", False),
    ("udp://127.0.0.1:5560", False), ("garbage", False),
])
def test_loopback_classification(endpoint: str, loopback: bool) -> None:
    assert is_loopback(endpoint) is loopback


@pytest.mark.parametrize("endpoint, pub", [("tcp://0.0.0.0:*", ANY_PORT),
                                           (ANY_PORT, "tcp://*:*")])
def test_non_loopback_bind_without_keys_is_refused(endpoint: str, pub: str) -> None:
    with pytest.raises(ConfigurationError, match="not loopback and no CurveZMQ keys"):
        RtServer(AnswerAll(), endpoint, pub)


def test_non_loopback_client_without_keys_is_refused() -> None:
    with pytest.raises(ConfigurationError, match="without CurveZMQ"):
        RtClient("tcp://192.168.1.20:5560")


def test_curve_client_with_an_allowed_key_is_served(curve_server: RtServer,
                                                    keys: dict[str, Path]) -> None:
    cfg = ClientCurveConfig(secret_key_file=keys["client_secret"],
                            server_public_key_file=keys["server_pub"])
    with RtClient(curve_server.endpoint, timeout_s=5.0, curve=cfg) as client:
        assert client.status() == {"did": "status"}
        with client.subscribe(["event"]) as sub:
            deadline = time.monotonic() + 5.0
            msg = None
            while msg is None and time.monotonic() < deadline:   # slow joiner: republish
                curve_server.publish("event", {"t": 1.0, "kind": "k", "cause": "c"})
                msg = sub.recv(0.1)
            assert msg is not None and msg["cause"] == "c"


@pytest.mark.parametrize("who", ["stranger", "plain"])
def test_a_key_not_allowed_or_no_key_is_refused(curve_server: RtServer, keys: dict[str, Path],
                                                who: str) -> None:
    cfg = None if who == "plain" else ClientCurveConfig(
        secret_key_file=keys["stranger_secret"], server_public_key_file=keys["server_pub"])
    with (
        RtClient(curve_server.endpoint, timeout_s=0.5, curve=cfg) as client,
        pytest.raises(RtUnavailableError),
    ):
        client.status()
    assert curve_server.stats()["requests"] == 0


def test_a_client_with_the_wrong_server_key_gets_nothing(curve_server: RtServer,
                                                         keys: dict[str, Path]) -> None:
    cfg = ClientCurveConfig(secret_key_file=keys["client_secret"],
                            server_public_key_file=keys["stranger_secret"])
    with (
        RtClient(curve_server.endpoint, timeout_s=0.5, curve=cfg) as client,
        pytest.raises(RtUnavailableError),
    ):
        client.status()


def test_server_config_errors_are_clear(keys: dict[str, Path], tmp_path: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    cases = [
        (ServerCurveConfig(secret_key_file=keys["server_pub"], allowed_clients_dir=keys["allowed"]),
         "holds no secret key"),
        (ServerCurveConfig(secret_key_file=tmp_path / "missing", allowed_clients_dir=empty),
         "cannot read the CurveZMQ key file"),
        (ServerCurveConfig(secret_key_file=keys["server_secret"], allowed_clients_dir=empty),
         "no client public keys"),
    ]
    for cfg, message in cases:
        with pytest.raises(ConfigurationError, match=message):
            RtServer(AnswerAll(), ANY_PORT, ANY_PORT, curve=cfg)


def test_keys_command_never_overwrites(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert talus_main(["rt", "keys", "--dir", str(tmp_path / "k"), "--name", "robot-1"]) == 0
    paths = json.loads(capsys.readouterr().out)
    secret = Path(paths["secret"])
    assert Path(paths["public"]).name == "robot-1.key" and secret.name == "robot-1.key_secret"
    assert secret.stat().st_mode & 0o777 == 0o600
    before = secret.read_bytes()
    assert talus_main(["rt", "keys", "--dir", str(tmp_path / "k"), "--name", "robot-1"]) == 2
    assert "refusing to overwrite" in json.loads(capsys.readouterr().out)["error"]
    assert secret.read_bytes() == before
    assert sorted(p.name for p in (tmp_path / "k").iterdir()) == ["robot-1.key",
                                                                  "robot-1.key_secret"]
    assert talus_main(["rt", "keys", "--dir", str(tmp_path), "--name", "../evil"]) == 2


def test_cli_client_uses_keys(curve_server: RtServer, keys: dict[str, Path],
                              capsys: pytest.CaptureFixture) -> None:
    assert talus_main(["rt", "status", "--endpoint", curve_server.endpoint, "--timeout", "5",
                       "--curve-secret", str(keys["client_secret"]),
                       "--server-key", str(keys["server_pub"])]) == 0
    assert json.loads(capsys.readouterr().out) == {"did": "status"}


_SERVER_CHILD = textwrap.dedent("""
    import sys
    from rt.ipc.server import RtServer

    class AnswerAll:
        def __getattr__(self, cmd):
            if cmd.startswith("_"):
                raise AttributeError(cmd)
            return lambda **kwargs: {"did": cmd}

    with RtServer(AnswerAll(), "tcp://127.0.0.1:*", "tcp://127.0.0.1:*") as server:
        print(server.endpoint, flush=True)
        sys.stdin.read()          # until the test closes our stdin
""")


def _peak_rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    raise AssertionError("no VmHWM in /proc status")


def test_a_200_mb_frame_is_dropped_without_being_read() -> None:
    child = subprocess.Popen([sys.executable, "-c", _SERVER_CHILD], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None
        endpoint = child.stdout.readline().strip()
        with RtClient(endpoint, timeout_s=10.0) as client:
            assert client.status() == {"did": "status"}
            peak_before = _peak_rss_kib(child.pid)
            ctx = zmq.Context()
            rogue = ctx.socket(zmq.DEALER)
            rogue.setsockopt(zmq.LINGER, 0)
            rogue.setsockopt(zmq.RECONNECT_IVL, 10_000)   # one attempt during the test
            rogue.connect(endpoint)
            frame = bytearray(200 * 1024 * 1024)
            rogue.send_multipart([b"", frame], copy=False)
            del frame
            # The server keeps answering while (and after) the rogue peer streams its frame.
            for _ in range(5):
                assert client.status() == {"did": "status"}
                time.sleep(0.2)
            rogue.close()
            ctx.term()
            assert client.status() == {"did": "status"}
            grown_mib = (_peak_rss_kib(child.pid) - peak_before) / 1024
        # Reading the frame would have taken ≥ 200 MiB; 16 MiB is the configured frame bound.
        assert grown_mib < 32, f"server peak memory grew by {grown_mib:.0f} MiB"
        assert child.poll() is None
    finally:
        if child.stdin is not None:
            child.stdin.close()
        child.wait(timeout=30)


def test_rt_serve_refuses_a_network_endpoint_without_keys_before_starting(
        capsys: pytest.CaptureFixture) -> None:
    assert talus_main(["rt", "serve", "--endpoint", "tcp://0.0.0.0:5560", "--seconds", "1"]) == 2
    assert "not loopback and no CurveZMQ keys" in capsys.readouterr().out


def test_rt_serve_with_curve_keys_from_its_config(keys: dict[str, Path], tmp_path: Path) -> None:
    """The RT process itself, configured with curve: in its YAML, serves the allowed client
    and nobody else."""
    config = tmp_path / "rt.yaml"
    config.write_text(json.dumps({                 # JSON is YAML
        "endpoint": ANY_PORT, "pub_endpoint": ANY_PORT,
        "curve": {"secret_key_file": str(keys["server_secret"]),
                  "allowed_clients_dir": str(keys["allowed"])}}))
    proc = subprocess.Popen([sys.executable, "-m", "talus", "rt", "serve", "--config",
                             str(config)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        serving = json.loads(proc.stdout.readline())["serving"]
        allowed = ClientCurveConfig(secret_key_file=keys["client_secret"],
                                    server_public_key_file=keys["server_pub"])
        with RtClient(serving["endpoint"], timeout_s=5.0, curve=allowed) as client:
            assert client.status()["state"] == "run"
        with (
            RtClient(serving["endpoint"], timeout_s=0.5) as plain,
            pytest.raises(RtUnavailableError),
        ):
            plain.status()
    finally:
        proc.terminate()
        proc.wait(timeout=60)
