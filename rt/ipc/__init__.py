"""The RT process boundary: versioned command/reply and telemetry messages over ZeroMQ.

* :mod:`rt.ipc.messages` — the wire format (pydantic v2 models, strict validation); no zmq.
* :mod:`rt.ipc.server` — :class:`~rt.ipc.server.RtServer`, run inside the RT process.
* :mod:`rt.ipc.client` — :class:`~rt.ipc.client.RtClient` and
  :class:`~rt.ipc.client.Subscriber` for the GUI and the CLI (Qt-free).
* :mod:`rt.ipc.cli` — ``talus rt status|stop|estop|reset``.

Nothing is imported here so that ``rt.ipc.messages`` can be used without importing zmq.
"""
