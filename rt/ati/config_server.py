"""The twin's Net F/T configuration interfaces: ``netftapi2.xml`` over HTTP and the TCP
calibration command (codecs and facts in ``rt.ati.netft_config``).

``NetFtConfigServer`` runs beside an ``RdtServer`` (``talus twin serve-ati --http-port P
--tcp-port Q``) so that clients which read their scaling from the sensor work against the twin.
Each interface is a standard-library server in its own daemon thread; anything but
``GET /netftapi2.xml`` gets 404, any TCP command but READCALINFO is ignored (the connection is
closed), as a device does with what it does not know.
"""
from __future__ import annotations

import socket
import socketserver
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Self

from rt.ati.netft_config import (
    CAL_INFO_REQUEST,
    CMD_READ_CAL_INFO,
    NETFT_XML_PATH,
    NetFtConfiguration,
    decode_cal_info_request,
)
from rt.errors import ProtocolError

#: A TCP client gets this long to send its 20-byte command (s).
TCP_COMMAND_TIMEOUT_S = 2.0


class _XmlHandler(BaseHTTPRequestHandler):
    server: _HttpServer
    protocol_version = "HTTP/1.1"

    def do_GET(self) -> None:
        path = self.path.split("?", 1)[0]
        body = self.server.config.to_xml() if path == NETFT_XML_PATH else b""
        self.server.requests += 1     # counted before answering: a client then sees it
        self.send_response(200 if body else 404)
        self.send_header("Content-Type", "text/xml")
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Connection", "close")
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args: Any) -> None:
        pass   # no per-request lines on stderr: the CLI's stdout is JSON lines


class _HttpServer(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, address: tuple[str, int], config: NetFtConfiguration) -> None:
        self.config = config
        self.requests = 0
        super().__init__(address, _XmlHandler)


class _TcpHandler(socketserver.BaseRequestHandler):
    server: _TcpServer

    def handle(self) -> None:
        sock: socket.socket = self.request
        sock.settimeout(TCP_COMMAND_TIMEOUT_S)
        data = b""
        try:
            while len(data) < CAL_INFO_REQUEST.size:
                chunk = sock.recv(CAL_INFO_REQUEST.size - len(data))
                if not chunk:
                    return
                data += chunk
            if decode_cal_info_request(data) == CMD_READ_CAL_INFO:
                self.server.requests += 1
                sock.sendall(self.server.config.cal_info_response())
        except (OSError, ProtocolError):
            return


class _TcpServer(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, address: tuple[str, int], config: NetFtConfiguration) -> None:
        self.config = config
        self.requests = 0
        super().__init__(address, _TcpHandler)


class NetFtConfigServer:
    """HTTP (``http_port``) and/or TCP (``tcp_port``) configuration interfaces on ``host``.

    ``None`` leaves an interface off; 0 picks an ephemeral port (read ``http_port`` /
    ``tcp_port`` back). Context manager; ``close()`` is safe to call twice. Raises OSError when
    a port cannot be bound.
    """

    def __init__(self, config: NetFtConfiguration, *, host: str = "127.0.0.1",
                 http_port: int | None = None, tcp_port: int | None = None) -> None:
        self.config = config
        self._servers: list[socketserver.BaseServer] = []
        self._threads: list[threading.Thread] = []
        self.http_port: int | None = None
        self.tcp_port: int | None = None
        try:
            if http_port is not None:
                self._http = _HttpServer((host, http_port), config)
                self.http_port = int(self._http.server_address[1])
                self._start(self._http, "netft-http")
            if tcp_port is not None:
                self._tcp = _TcpServer((host, tcp_port), config)
                self.tcp_port = int(self._tcp.server_address[1])
                self._start(self._tcp, "netft-tcp")
        except OSError:
            self.close()
            raise

    def _start(self, server: socketserver.BaseServer, name: str) -> None:
        thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.1},
                                  name=name, daemon=True)
        self._servers.append(server)
        self._threads.append(thread)
        thread.start()

    @property
    def requests(self) -> dict[str, int]:
        """Requests answered per interface."""
        out = {}
        if self.http_port is not None:
            out["http"] = self._http.requests
        if self.tcp_port is not None:
            out["tcp"] = self._tcp.requests
        return out

    def close(self) -> None:
        """Stop both interfaces and release their sockets; safe to call twice."""
        servers, self._servers = self._servers, []
        for server in servers:
            server.shutdown()
            server.server_close()
        for thread in self._threads:
            thread.join(timeout=5.0)
        self._threads = []

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
