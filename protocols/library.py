"""Protocol files: loading (YAML → validated model) and the shipped library.

YAML is read with talus's bounded safe loader (``rt.safe_yaml``): regular files of at most
``MAX_FILE_BYTES``, bounded aliases and nesting, duplicate keys refused (PyYAML would silently
keep the last one, and a clinician's second ``amplitude_deg`` would win unseen). Syntax errors
and schema problems are :class:`~rt.errors.ProtocolValidationError` with the file and the
line, e.g.::

    library/sine_fz.yaml, line 9: amplitude_n: 400.0 N exceeds mean_n 300.0 N: ...
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path, PurePath

import yaml

from protocols.schema import ProtocolModel, validate_protocol_data
from rt.errors import ProtocolValidationError
from rt.safe_yaml import parse_yaml, read_text_file

#: The shipped protocols (next to this module).
LIBRARY_DIR = Path(__file__).resolve().parent / "library"
#: Larger files are refused unread: a protocol is a page of YAML.
MAX_FILE_BYTES = 1_000_000


def _locator(root: yaml.Node | None):
    """A function mapping a field path to the 1-based line of its key (or deepest parent)."""

    def locate(path: Sequence[str | int]) -> int | None:
        node = root
        line = None if node is None else node.start_mark.line + 1
        for p in path:
            if isinstance(node, yaml.MappingNode):
                for key_node, value_node in node.value:
                    if isinstance(key_node, yaml.ScalarNode) and key_node.value == str(p):
                        line = key_node.start_mark.line + 1
                        node = value_node
                        break
                else:
                    return line
            elif isinstance(node, yaml.SequenceNode) and isinstance(p, int) \
                    and 0 <= p < len(node.value):
                node = node.value[p]
                line = node.start_mark.line + 1
            else:
                return line
        return line

    return locate


def parse_protocol_text(text: str, source: str = "<memory>") -> ProtocolModel:
    """Validate protocol YAML text; raises ProtocolValidationError naming ``source``.

    A ``source`` that is a file path (not ``"<...>"``) is remembered as ``loaded_from``.
    """
    data, root = parse_yaml(text, source, ProtocolValidationError)
    if data is None:
        raise ProtocolValidationError(f"{source}: the file is empty")
    protocol = validate_protocol_data(data, source, _locator(root))
    if not source.startswith("<"):
        protocol._source = PurePath(source)  # relative file names resolve next to it
    return protocol


def load_protocol(path: str | Path) -> ProtocolModel:
    """Read and validate a protocol file; the model remembers it (``protocol.loaded_from``).

    Raises:
        ProtocolValidationError: the file is unreadable, not YAML, or fails the schema; the
            message names the file, the line, the field path and the reason.
    """
    p = Path(path)
    text = read_text_file(p, "protocol", ProtocolValidationError, MAX_FILE_BYTES)
    protocol = parse_protocol_text(text, str(p))
    protocol._source = p.resolve()
    return protocol


def protocol_files(protocol: ProtocolModel) -> list[Path]:
    """The files a protocol is read from: itself and the data files it names (a gait source,
    a playback CSV; relative names resolve next to the protocol). Outputs must not be these."""
    if protocol.loaded_from is None:
        return []
    here = Path(protocol.loaded_from)
    named = [getattr(protocol, key, None) for key in ("source", "file")]
    return [here] + [here.parent / n for n in named if isinstance(n, str)]


def list_library() -> list[Path]:
    """The shipped protocol files, sorted by name."""
    return sorted(LIBRARY_DIR.glob("*.yaml"))
