"""YAML description files with line numbers in their errors (plate descriptions, plans).

Read with PyYAML's safe loader, refusing duplicate keys; a pydantic validation error becomes one
line per problem, ``"<file>, line <n>: <field.path>: <reason>"``, raised as
:class:`~rt.errors.ConfigurationError`. Nothing is changed when a file is refused.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ValidationError

from rt.errors import ConfigurationError

#: Larger files are refused unread: a description is a page or two of YAML.
MAX_FILE_BYTES = 2_000_000

Model = TypeVar("Model", bound=BaseModel)
LineOf = Callable[[Sequence[str | int]], int | None]


class _NoDuplicateKeys(yaml.SafeLoader):
    def construct_mapping(self, node: yaml.MappingNode,
                          deep: bool = False) -> dict:
        first_line: dict[object, int] = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if isinstance(key, (list, dict)):
                raise yaml.constructor.ConstructorError(None, None, f"unhashable key {key!r}",
                                                        key_node.start_mark)
            if key in first_line:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r} (first at line {first_line[key]})",
                    key_node.start_mark)
            first_line[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep=deep)


def _line_finder(root: yaml.Node) -> LineOf:
    """Field path → 1-based line of its key (or of the deepest parent found)."""

    def line_of(path: Sequence[str | int]) -> int | None:
        node: yaml.Node = root
        line: int | None = root.start_mark.line + 1
        for part in path:
            if isinstance(node, yaml.MappingNode):
                hit = [(k, v) for k, v in node.value if getattr(k, "value", None) == str(part)]
                if not hit:
                    return line
                line, node = hit[0][0].start_mark.line + 1, hit[0][1]
            elif isinstance(node, yaml.SequenceNode) and isinstance(part, int) \
                    and 0 <= part < len(node.value):
                node = node.value[part]
                line = node.start_mark.line + 1
            else:
                return line
        return line

    return line_of


def _dotted(path: Sequence[str | int]) -> str:
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text or "(top level)"


def parse_yaml(text: str, source: str) -> tuple[Any, LineOf]:
    """Parse YAML text; returns the data and a path → line function."""
    loader = _NoDuplicateKeys(text)
    try:
        root = loader.get_single_node()
        data = loader.construct_document(root) if root is not None else None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{source}, line {mark.line + 1}" if mark else source
        raise ConfigurationError(f"{where}: YAML syntax error: {exc.problem}") from None
    except yaml.YAMLError as exc:
        raise ConfigurationError(f"{source}: YAML error: {exc}") from None
    finally:
        loader.dispose()
    if root is None or data is None:
        raise ConfigurationError(f"{source}: the file is empty")
    return data, _line_finder(root)


def validate(cls: type[Model], data: Any, source: str, line_of: LineOf | None = None) -> Model:
    """Build ``cls`` from ``data``; every problem is named with its line and field path."""
    if not isinstance(data, dict):
        raise ConfigurationError(f"{source}: the file must hold a mapping of fields "
                                 f"(got {type(data).__name__})")
    try:
        return cls.model_validate(data)
    except ValidationError as exc:
        lines = []
        for err in exc.errors():
            loc = list(err["loc"])
            line = line_of(loc) if line_of is not None else None
            where = f"{source}, line {line}" if line is not None else source
            reason = str(err["msg"]).removeprefix("Value error, ")
            if err["type"] == "extra_forbidden":
                reason = "unknown key"
            elif err["type"] == "missing":
                reason = "required field is missing"
            elif "input" in err and not isinstance(err["input"], (dict, list)):
                reason += f" (got {err['input']!r})"
            lines.append(f"{where}: {_dotted(loc)}: {reason}")
        raise ConfigurationError("\n".join(lines)) from None


def load(cls: type[Model], path: str | Path) -> Model:
    """Read and validate a YAML file into ``cls`` (ConfigurationError naming file and line)."""
    p = Path(path)
    try:
        if p.stat().st_size > MAX_FILE_BYTES:
            raise ConfigurationError(f"{p}: larger than {MAX_FILE_BYTES} bytes; not a "
                                     "description file")
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigurationError(f"{p}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ConfigurationError(f"{p}: not UTF-8 text") from None
    data, line_of = parse_yaml(text, str(p))
    return validate(cls, data, str(p), line_of)
