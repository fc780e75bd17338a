"""Session recording to MCAP (DESIGN 9): Foxglove-readable JSON channels written from a
non-real-time thread, crash-tolerant (chunked, recoverable), CSV export.

* :mod:`rt.recording.channels` — channel definitions (topic → JSON Schema, protobuf).
* :mod:`rt.recording.cycle` — ``talus.v4``: one message per loop cycle (state, wrench,
  reference), the default.
* :mod:`rt.recording.writer` — :class:`SessionRecorder`.
* :mod:`rt.recording.reader` — :func:`read_recording`, :func:`recover`, :func:`export_csv`.
* :mod:`rt.recording.cli` — ``talus record info|export``.

Import the submodules directly; this package imports nothing heavy on its own.
"""
