"""Wire safety of the RT process boundary: loopback by default, CurveZMQ on the network.

The RT process commands a robot with a patient's foot on it and publishes that patient's
data; DESIGN §3 keeps it on loopback unless it is configured for the network. Rules:

* An endpoint that is not loopback (``tcp://127.x.x.x``, ``tcp://[::1]``, ``tcp://localhost``,
  ``ipc://``, ``inproc://``) is refused unless CurveZMQ keys are configured: the server's key
  pair and a directory of the client public keys it accepts. A ZAP authenticator (pyzmq's
  ``zmq.auth.thread.ThreadAuthenticator``) then refuses every client whose key is not there,
  and every frame is encrypted. On loopback the keys are optional (if given they are used).
* A client refuses a non-loopback server without its own key pair and the server's public
  key, so commands and telemetry never cross a network in plain text.
* Key files are ZeroMQ's certificate format (``NAME.key`` public, ``NAME.key_secret`` both
  keys), as ``zmq.auth.create_certificates`` writes them; :func:`make_keys` (``talus rt keys``)
  creates a pair and never overwrites a file.

A clinic's setup: on the robot PC ``talus rt keys --dir /etc/talus/curve --name server``; on
each workstation ``talus rt keys --dir ~/.config/talus/curve --name ws-3``; copy ``ws-3.key``
into the server's ``allowed_clients_dir`` and ``server.key`` to the workstations.

This module never logs or returns a secret key.
"""
from __future__ import annotations

import ipaddress
import os
import re
import tempfile
from pathlib import Path
from typing import Any

import zmq
import zmq.auth
from pydantic import BaseModel, ConfigDict

from rt.errors import ConfigurationError

_TCP = re.compile(r"^tcp://(?:(?P<source>[^;]*);)?(?P<host>\[[^\]]*\]|[^:\[\]]*):(?P<port>[^:]+)$")
_LOCAL_TRANSPORTS = ("ipc://", "inproc://")


def is_loopback(endpoint: str) -> bool:
    """True when ``endpoint`` can only be reached from this machine.

    ``tcp://`` with a loopback address (127.0.0.0/8, ::1), ``localhost`` or the ``lo``
    interface; ``ipc://`` and ``inproc://``. Wildcards (``*``, ``0.0.0.0``), other addresses,
    other interface names and anything unparsable count as not loopback.
    """
    if endpoint.startswith(_LOCAL_TRANSPORTS):
        return True
    m = _TCP.match(endpoint)
    if m is None:
        return False
    host = m.group("host").strip("[]")
    if host in ("localhost", "lo"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class ServerCurveConfig(BaseModel):
    """CurveZMQ for ``talus rt serve`` (the ``curve:`` section of the RT config).

    ``secret_key_file``: the server's ``NAME.key_secret`` (made by ``talus rt keys``);
    ``allowed_clients_dir``: a directory of client public keys (``*.key``); a client whose key
    is not there is refused during the handshake. Re-read at every start.
    """

    model_config = ConfigDict(extra="forbid")
    secret_key_file: Path
    allowed_clients_dir: Path


class ClientCurveConfig(BaseModel):
    """CurveZMQ for a client: its own ``NAME.key_secret`` and the server's ``NAME.key``."""

    model_config = ConfigDict(extra="forbid")
    secret_key_file: Path
    server_public_key_file: Path


def _load(path: Path, need_secret: bool) -> tuple[bytes, bytes | None]:
    """(public, secret) keys of a certificate file, with a clear error."""
    try:
        public, secret = zmq.auth.load_certificate(path)
    except (OSError, ValueError) as exc:
        raise ConfigurationError(f"cannot read the CurveZMQ key file {path}: {exc}") from None
    if need_secret and not secret:
        raise ConfigurationError(
            f"{path} holds no secret key: give the NAME.key_secret file made by "
            f"`talus rt keys`, not the public NAME.key")
    return public, secret


class ServerSecurity:
    """A running ZAP authenticator plus the server key pair, applied to every bound socket.

    Construct before binding; :meth:`apply` each socket before its ``bind``; :meth:`close`
    stops the authenticator (safe twice). ``allowed`` is the number of client keys accepted.
    """

    def __init__(self, context: zmq.Context[Any], config: ServerCurveConfig) -> None:
        if not zmq.has("curve"):
            raise ConfigurationError("this libzmq was built without CURVE support")
        self.public_key, secret = _load(config.secret_key_file, need_secret=True)
        assert secret is not None
        self._secret = secret
        directory = config.allowed_clients_dir
        if not directory.is_dir():
            raise ConfigurationError(f"allowed_clients_dir {directory} is not a directory")
        try:
            keys = zmq.auth.load_certificates(directory)
        except (OSError, ValueError) as exc:
            raise ConfigurationError(f"cannot read client keys in {directory}: {exc}") from None
        if not keys:
            raise ConfigurationError(
                f"no client public keys (*.key) in {directory}: no client could connect")
        self.allowed = len(keys)
        from zmq.auth.thread import ThreadAuthenticator

        self._auth: ThreadAuthenticator | None = ThreadAuthenticator(context)
        self._auth.start()
        self._auth.configure_curve(domain="*", location=str(directory))

    def apply(self, sock: zmq.Socket[Any]) -> None:
        """Make ``sock`` a CURVE server (call before ``bind``)."""
        sock.curve_secretkey = self._secret
        sock.curve_publickey = self.public_key
        sock.curve_server = True

    def close(self) -> None:
        if self._auth is not None:
            self._auth.stop()
            self._auth = None


def check_server_endpoint(endpoint: str, security: ServerSecurity | None) -> None:
    """Refuse to bind ``endpoint`` off loopback without CurveZMQ."""
    if security is None and not is_loopback(endpoint):
        raise ConfigurationError(
            f"refusing to serve on {endpoint}: it is not loopback and no CurveZMQ keys are "
            f"configured (the RT config's curve: secret_key_file, allowed_clients_dir; make "
            f"keys with `talus rt keys`)")


class ClientSecurity:
    """A client's key pair and the server's public key, applied to each socket it opens."""

    def __init__(self, config: ClientCurveConfig) -> None:
        self.public_key, secret = _load(config.secret_key_file, need_secret=True)
        assert secret is not None
        self._secret = secret
        self.server_key, _ = _load(config.server_public_key_file, need_secret=False)

    def apply(self, sock: zmq.Socket[Any]) -> None:
        """Make ``sock`` a CURVE client of the configured server (call before ``connect``)."""
        sock.curve_secretkey = self._secret
        sock.curve_publickey = self.public_key
        sock.curve_serverkey = self.server_key


def check_client_endpoint(endpoint: str, security: ClientSecurity | None) -> None:
    """Refuse to talk to ``endpoint`` off loopback without CurveZMQ."""
    if security is None and not is_loopback(endpoint):
        raise ConfigurationError(
            f"refusing to connect to {endpoint} without CurveZMQ: it is not loopback; give "
            f"this client's key_secret file and the server's public key")


def make_keys(directory: str | Path, name: str) -> tuple[Path, Path]:
    """Create ``NAME.key`` and ``NAME.key_secret`` in ``directory`` (made if missing).

    Never overwrites: refused with ``ConfigurationError`` when either file exists (nothing is
    written then). The secret file is readable by its owner only (0600). Returns (public,
    secret) paths.
    """
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}", name):
        raise ConfigurationError(
            f"key name {name!r}: use letters, digits, '.', '_' or '-' (at most 64)")
    directory = Path(directory)
    public, secret = directory / f"{name}.key", directory / f"{name}.key_secret"
    existing = [str(p) for p in (public, secret) if p.exists()]
    if existing:
        raise ConfigurationError(f"refusing to overwrite {', '.join(existing)}")
    try:
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=directory, prefix=".talus-keys-") as tmp:
            os.chmod(tmp, 0o700)
            tmp_public, tmp_secret = zmq.auth.create_certificates(tmp, name)
            os.chmod(tmp_secret, 0o600)
            os.chmod(tmp_public, 0o644)
            # link() fails if the name exists: no overwrite even against a concurrent writer.
            os.link(tmp_secret, secret)
            try:
                os.link(tmp_public, public)
            except BaseException:
                secret.unlink()
                raise
    except FileExistsError as exc:
        raise ConfigurationError(f"refusing to overwrite {exc.filename}") from None
    except OSError as exc:
        raise ConfigurationError(f"cannot write keys in {directory}: {exc}") from None
    return public, secret
