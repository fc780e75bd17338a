"""Protocol files: loading (YAML → validated model) and the shipped library.

YAML is read with PyYAML's safe loader, refusing duplicate keys (PyYAML would silently keep the
last one, and a clinician's second ``amplitude_deg`` would win unseen). Syntax errors and schema
problems are :class:`~rt.errors.ProtocolValidationError` with the file and the line, e.g.::

    library/sine_fz.yaml, line 9: amplitude_n: 400.0 N exceeds mean_n 300.0 N: ...
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path, PurePath

import yaml

from protocols.schema import ProtocolModel, validate_protocol_data
from rt.errors import ProtocolValidationError

#: The shipped protocols (next to this module).
LIBRARY_DIR = Path(__file__).resolve().parent / "library"
#: Larger files are refused unread: a protocol is a page of YAML.
MAX_FILE_BYTES = 1_000_000


class _StrictLoader(yaml.SafeLoader):
    """Safe loader that refuses duplicate mapping keys."""

    def construct_mapping(self, node: yaml.MappingNode,  # type: ignore[override]
                          deep: bool = False) -> dict:
        seen: dict[object, int] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)  # type: ignore[no-untyped-call]
            try:
                hash(key)
            except TypeError:
                raise yaml.constructor.ConstructorError(
                    None, None, f"unhashable key {key!r}", key_node.start_mark) from None
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    f"while reading the mapping from line {node.start_mark.line + 1}", None,
                    f"duplicate key {key!r} (first at line {seen[key]})", key_node.start_mark)
            seen[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep=deep)  # type: ignore[no-untyped-call]


def _locator(root: yaml.Node | None):  # type: ignore[no-untyped-def]
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
    loader = _StrictLoader(text)
    try:
        root = loader.get_single_node()
        data = loader.construct_document(root) if root is not None else None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{source}, line {mark.line + 1}, column {mark.column + 1}" if mark else source
        problem = exc.problem or "malformed YAML"
        context = f" ({exc.context})" if exc.context else ""
        raise ProtocolValidationError(f"{where}: YAML syntax error: {problem}{context}") from None
    except yaml.YAMLError as exc:
        raise ProtocolValidationError(f"{source}: YAML error: {exc}") from None
    finally:
        loader.dispose()  # type: ignore[no-untyped-call]
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
    try:
        size = p.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ProtocolValidationError(f"{p}: the file is {size} bytes, more than the "
                                          f"{MAX_FILE_BYTES} a protocol can be")
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ProtocolValidationError(f"{p}: not UTF-8 text ({exc.reason} at byte "
                                      f"{exc.start})") from None
    except OSError as exc:
        raise ProtocolValidationError(f"{p}: cannot read the file ({exc.strerror})") from None
    protocol = parse_protocol_text(text, str(p))
    protocol._source = p.resolve()
    return protocol


def list_library() -> list[Path]:
    """The shipped protocol files, sorted by name."""
    return sorted(LIBRARY_DIR.glob("*.yaml"))
