"""The one way talus reads YAML files (protocols, robot descriptions, RT configs).

A YAML file may come from anywhere (a USB stick, a mistyped path), so reading one is bounded
in every dimension before any of it is used:

* only regular files: ``/dev/zero``, a FIFO or a directory is refused without blocking
  (the file is opened non-blocking and checked with ``fstat``);
* size: at most ``max_bytes + 1`` bytes are ever read, so a huge or endless file costs nothing;
* UTF-8 text only;
* nesting depth (the composer recurses once per level: 100 000 ``[`` would overflow the stack);
* aliases: at most ``MAX_ALIASES``, and the document fully expanded (every alias replaced by
  what it names) may hold at most ``MAX_EXPANDED_NODES`` nodes. A 351-byte "billion laughs"
  is 10^9 nodes expanded: it is refused after composing a few dozen;
* duplicate mapping keys (PyYAML silently keeps the last one) and non-scalar keys.

Errors never echo the file's contents (PyYAML's own messages quote the offending line, which
for ``--robot /etc/shadow`` would print a password hash): they name the file, the line and
column, and the problem.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

import yaml

from rt.errors import ConfigurationError, TalusError

#: Largest YAML file read (bytes): configuration and protocols are pages, not megabytes.
MAX_FILE_BYTES = 1_000_000
#: Deepest nesting of sequences and mappings.
MAX_DEPTH = 64
#: Most alias uses (``*name``) in one document.
MAX_ALIASES = 256
#: Most nodes of the document with every alias expanded.
MAX_EXPANDED_NODES = 200_000


def read_regular_file(path: str | Path, what: str, error: type[TalusError] = ConfigurationError,
                      max_bytes: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a regular file of at most ``max_bytes``; ``error`` names what is wrong.

    ``what`` says what the file is for the message ("robot description").
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0))
    except OSError as exc:
        raise error(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            kind = ("a directory" if stat.S_ISDIR(mode) else "a FIFO" if stat.S_ISFIFO(mode)
                    else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
                    else "not a regular file")
            raise error(f"{what} {path} is {kind}, not a regular file")
        chunks: list[bytes] = []
        size = 0
        while size <= max_bytes:
            chunk = os.read(fd, max_bytes + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        if size > max_bytes:
            raise error(f"{what} {path} is larger than {max_bytes} bytes; refused unread")
        return b"".join(chunks)
    except OSError as exc:
        raise error(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    finally:
        os.close(fd)


def read_text_file(path: str | Path, what: str, error: type[TalusError] = ConfigurationError,
                   max_bytes: int = MAX_FILE_BYTES) -> str:
    """``read_regular_file`` decoded as UTF-8 (a BOM is accepted)."""
    data = read_regular_file(path, what, error, max_bytes)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise error(f"{what} {path} is not UTF-8 text ({exc.reason} at byte "
                    f"{exc.start})") from None


class BoundedSafeLoader(yaml.SafeLoader):
    """PyYAML's safe loader with the bounds above and duplicate/non-scalar keys refused."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self._aliases = 0

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node | None:
        if self.check_event(yaml.AliasEvent):
            self._aliases += 1
            if self._aliases > MAX_ALIASES:
                event = self.peek_event()
                raise yaml.composer.ComposerError(
                    None, None, f"more than {MAX_ALIASES} aliases", event.start_mark)
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                event = self.peek_event()
                raise yaml.composer.ComposerError(
                    None, None, f"nested more than {MAX_DEPTH} levels deep", event.start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node: yaml.MappingNode,
                          deep: bool = False) -> dict[Any, Any]:
        seen: dict[object, int] = {}
        for key_node, _ in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                # Never build (or print) a collection key: it may be a billion-laughs bomb.
                raise yaml.constructor.ConstructorError(
                    None, None, "a mapping key must be a plain value, not a list or mapping",
                    key_node.start_mark)
            key = self.construct_object(key_node, deep=True)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    f"while reading the mapping from line {node.start_mark.line + 1}", None,
                    f"duplicate key {_brief(key)} (first at line {seen[key]})",
                    key_node.start_mark)
            seen[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep=deep)


def _brief(value: object, limit: int = 40) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "…"


class _RecursiveAlias(Exception):
    """An alias inside the collection it names (``&a [*a]``): infinite when expanded."""


def expanded_size(root: yaml.Node) -> int | None:
    """Nodes in the document with every alias replaced by its target (memoised: linear);
    None when an alias refers to a collection that contains it (infinitely large)."""
    sizes: dict[int, int] = {}
    in_progress = -1

    def size(node: yaml.Node) -> int:
        known = sizes.get(id(node))
        if known == in_progress:
            raise _RecursiveAlias()
        if known is not None:
            return known
        sizes[id(node)] = in_progress
        if isinstance(node, yaml.SequenceNode):
            n = 1 + sum(size(child) for child in node.value)
        elif isinstance(node, yaml.MappingNode):
            n = 1 + sum(size(k) + size(v) for k, v in node.value)
        else:
            n = 1
        sizes[id(node)] = n
        return n

    try:
        return size(root)
    except _RecursiveAlias:
        return None


def parse_yaml(text: str, source: str, error: type[TalusError] = ConfigurationError
               ) -> tuple[Any, yaml.Node | None]:
    """(data, root node) of one YAML document; ``error`` says where and what is wrong.

    The root node lets callers map a field path back to its line (see ``protocols.library``).
    An empty document gives ``(None, None)``.
    """
    loader = BoundedSafeLoader(text)
    try:
        root = loader.get_single_node()
        if root is None:
            return None, None
        expanded = expanded_size(root)
        if expanded is None:
            raise error(f"{source}: an alias refers to a list or mapping that contains it")
        if expanded > MAX_EXPANDED_NODES:
            raise error(f"{source}: the document expands to more than {MAX_EXPANDED_NODES} "
                        "values through its aliases; refused")
        return loader.construct_document(root), root
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{source}, line {mark.line + 1}, column {mark.column + 1}" if mark else source
        problem = exc.problem or "malformed YAML"
        context = f" ({exc.context})" if exc.context else ""
        raise error(f"{where}: YAML syntax error: {problem}{context}") from None
    except yaml.YAMLError:
        raise error(f"{source}: not valid YAML") from None
    finally:
        loader.dispose()


def load_yaml_file(path: str | Path, what: str, error: type[TalusError] = ConfigurationError,
                   max_bytes: int = MAX_FILE_BYTES) -> Any:
    """Read and parse a YAML file within the bounds above (``None`` when it is empty)."""
    return parse_yaml(read_text_file(path, what, error, max_bytes), str(path), error)[0]
