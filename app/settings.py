"""The GUI's settings: a validated model saved as JSON (atomically: temp file and rename).

Qt-free, so it is tested without a display. Times in seconds; the idle lock never fires while
a session runs (the main window checks).
"""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from rt.errors import ConfigurationError
from rt.ipc.messages import DEFAULT_ENDPOINT

SCHEMA_VERSION = 1


def default_path() -> Path:
    """``$XDG_CONFIG_HOME/talus/gui.json`` (``~/.config`` when unset)."""
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "talus" / "gui.json"


class GuiSettings(BaseModel):
    """Everything Settings edits (SI units)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    schema_version: Literal[1] = 1
    rt_endpoint: Annotated[str, Field(min_length=6, pattern=r"^(tcp|ipc)://\S+$")] = \
        DEFAULT_ENDPOINT
    database_url: str = ""
    recordings_dir: str = ""
    clinic_name: Annotated[str, Field(max_length=120)] = ""
    clinic_logo: str = ""
    language: Literal["en", "es"] = "en"
    idle_lock_s: Annotated[float, Field(ge=30.0, le=24 * 3600.0)] = 600.0
    rt_timeout_s: Annotated[float, Field(gt=0.0, le=60.0)] = 2.0


def load(path: Path) -> GuiSettings:
    """The settings at ``path`` (defaults when the file does not exist).

    Raises:
        ConfigurationError: the file is unreadable or invalid (named, with the field).
    """
    if not path.exists():
        return GuiSettings()
    try:
        return GuiSettings.model_validate(json.loads(path.read_text(encoding="utf-8")))
    except (OSError, ValueError) as exc:
        detail = exc.errors()[0] if isinstance(exc, ValidationError) else None
        where = ".".join(str(p) for p in detail["loc"]) + ": " + detail["msg"] if detail \
            else str(exc)
        raise ConfigurationError(f"{path}: {where}") from None


def save(settings: GuiSettings, path: Path) -> None:
    """Write ``settings`` to ``path`` atomically (the old file stays whole on a crash)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".gui-", suffix=".json", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(settings.model_dump(), f, indent=2)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
