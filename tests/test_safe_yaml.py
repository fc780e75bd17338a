"""Hostile YAML files: every loader (protocol, robot description, RT config) goes through
``rt.safe_yaml`` and refuses them quickly, without echoing their contents."""
from __future__ import annotations

import os
import re
import time

import pytest

from protocols.library import load_protocol
from rt.errors import ConfigurationError, ProtocolValidationError, TalusError
from rt.model.description import load_description
from rt.safe_yaml import MAX_FILE_BYTES, expanded_size, load_yaml_file
from rt.service import load_config

LOADERS = [(load_protocol, ProtocolValidationError), (load_description, ConfigurationError),
           (load_config, ConfigurationError)]

#: About 350 bytes of "billion laughs": 10^9 strings when expanded.
LAUGHS = "a: &a [" + ",".join(["lol"] * 10) + "]\n" + "".join(
    f"{b}: &{b} [{','.join([f'*{a}'] * 10)}]\n" for a, b in zip("abcdefgh", "bcdefghi"))


def _fifo(tmp_path):
    path = tmp_path / "fifo.yaml"
    os.mkfifo(path)
    return path


@pytest.mark.parametrize("loader, error", LOADERS)
@pytest.mark.parametrize("make, message", [
    (lambda tmp: "/dev/zero", "is a device, not a regular file"),
    (_fifo, "is a FIFO, not a regular file"),
    (lambda tmp: tmp, "is a directory, not a regular file"),
    (lambda tmp: tmp / "missing.yaml", "No such file or directory"),
])
def test_only_regular_files_are_read(loader, error, make, message, tmp_path):
    start = time.monotonic()
    with pytest.raises(error, match=message):
        loader(make(tmp_path))
    # Not a timing assertion on speed: a FIFO with no writer would block forever otherwise.
    assert time.monotonic() - start < 60.0


@pytest.mark.parametrize("loader, error", LOADERS)
def test_a_file_over_the_limit_is_refused_unread(loader, error, tmp_path):
    path = tmp_path / "big.yaml"
    path.write_bytes(b"#" * (MAX_FILE_BYTES + 1))
    with pytest.raises(error, match=f"larger than {MAX_FILE_BYTES} bytes"):
        loader(path)


@pytest.mark.parametrize("loader, error", LOADERS)
@pytest.mark.parametrize("text, message", [
    (LAUGHS + "? *i\n: 1\n", "expands to more than"),                  # bomb as a key
    ("? [1, 2]\n: x\n", "mapping key must be a plain value"),
    (LAUGHS + "bomb: *i\n", "expands to more than"),                  # bomb as a value
    ("a: &a [1, *a]\n", "alias refers to a list or mapping that contains it"),
    ("x: " + "[" * 100 + "]" * 100 + "\n", "nested more than 64 levels"),
    ("x: " + "[" * 100_000 + "]" * 100_000 + "\n", "nested more than 64 levels"),
    ("a: &a 1\n" + "".join(f"b{k}: *a\n" for k in range(300)), "more than 256 aliases"),
    ("a: 1\na: 2\n", "duplicate key 'a' (first at line 1)"),
])
def test_hostile_documents_are_refused(loader, error, text, message, tmp_path):
    path = tmp_path / "hostile.yaml"
    path.write_text(text)
    with pytest.raises(error, match=re.escape(message)):
        loader(path)


def test_the_laughs_are_small_and_measured_without_expanding_them():
    import yaml

    assert len(LAUGHS) <= 360
    root = yaml.compose(LAUGHS, Loader=yaml.SafeLoader)  # anchors are shared, not copied
    assert expanded_size(root) > 10**9


SHADOW_LIKE = [
    "root:$6$Secret.Hash$abcdefgh:19000:0:99999:7:::\ndaemon:*:19000:0:99999:7:::\n",  # a map
    "root:$6$Secret.Hash$abcdefgh:19000:0:99999:7:::\n  daemon: [x:\n",            # bad YAML
]


@pytest.mark.parametrize("loader, error", LOADERS)
@pytest.mark.parametrize("secret", SHADOW_LIKE)
def test_messages_never_echo_the_file(loader, error, secret, tmp_path):
    path = tmp_path / "shadow"
    path.write_text(secret)
    with pytest.raises(TalusError) as exc:
        loader(path)
    assert "Secret" not in str(exc.value) and "daemon" not in str(exc.value)
    assert str(path) in str(exc.value)


def test_a_valid_file_still_loads(tmp_path):
    path = tmp_path / "ok.yaml"
    path.write_text("base: &b {k: 1}\nuse: *b\n")
    assert load_yaml_file(path, "test file") == {"base": {"k": 1}, "use": {"k": 1}}
    assert load_yaml_file(tmp_path / "ok.yaml", "test file", max_bytes=100) is not None
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    assert load_yaml_file(empty, "test file") is None
