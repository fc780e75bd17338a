"""Report settings: the clinic's name, address and logo, the paper size (CONVENTIONS 9).

A small typed model loaded from YAML (``schema_version: 1``); the GUI's Settings page edits
the same file. Where it lives: ``--settings FILE`` on the command line, else the file named by
``TALUS_REPORT_SETTINGS``, else ``$XDG_CONFIG_HOME/talus/reports.yaml`` (``~/.config/...``);
no file means the defaults below.
"""
from __future__ import annotations

import os
from enum import Enum
from pathlib import Path
from typing import Annotated, Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from reports.inputs import first_problem
from rt.errors import ConfigurationError

SCHEMA_VERSION = 1
ENV_VAR = "TALUS_REPORT_SETTINGS"


class PageSize(str, Enum):
    """Paper: ISO A4 (Europe) or US Letter."""

    A4 = "A4"
    LETTER = "Letter"


class ReportSettings(BaseModel):
    """What every report's header and layout take from the clinic's settings."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    schema_version: int = SCHEMA_VERSION
    clinic_name: Annotated[str, Field(min_length=1, max_length=120)] = "talus"
    #: Lines under the name (address, department), printed small.
    clinic_address: Annotated[str, Field(max_length=300)] = ""
    #: PNG or JPEG file drawn at the top left (relative paths: to the settings file).
    logo_path: Path | None = None
    page_size: PageSize = PageSize.A4

    @field_validator("schema_version")
    @classmethod
    def _version(cls, v: int) -> int:
        if v != SCHEMA_VERSION:
            raise ValueError(f"this talus reads report settings version {SCHEMA_VERSION}, "
                             f"not {v}")
        return v

    def check_logo(self) -> None:
        """Raise ConfigurationError when the logo is set but not a readable PNG/JPEG file."""
        if self.logo_path is None:
            return
        p = self.logo_path
        if not p.is_file():
            raise ConfigurationError(f"report settings: logo_path {p}: no such file")
        with open(p, "rb") as f:
            head = f.read(8)
        if not (head.startswith((b"\x89PNG\r\n\x1a\n", b"\xff\xd8"))):
            raise ConfigurationError(f"report settings: logo_path {p}: not a PNG or JPEG image")


def default_settings_path() -> Path:
    env = os.environ.get(ENV_VAR)
    if env:
        return Path(env)
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "talus" / "reports.yaml"


def load_settings(path: str | os.PathLike[str] | None = None) -> ReportSettings:
    """Load the settings (defaults when ``path`` is None and no default file exists).

    Raises ConfigurationError naming the file and the field for a malformed file, and for a
    ``path`` given explicitly that does not exist.
    """
    explicit = path is not None
    p = Path(path) if path is not None else default_settings_path()
    if not p.is_file():
        if explicit or os.environ.get(ENV_VAR):
            raise ConfigurationError(f"report settings {p}: no such file")
        return ReportSettings()
    try:
        data: Any = yaml.safe_load(p.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ConfigurationError(f"report settings {p}: not valid YAML: {exc}") from exc
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigurationError(f"report settings {p}: expected a mapping at the top")
    logo = data.get("logo_path")
    if isinstance(logo, str) and logo and not Path(logo).is_absolute():
        data = {**data, "logo_path": str(p.parent / logo)}
    try:
        settings = ReportSettings.model_validate(data)
    except ValidationError as exc:
        raise ConfigurationError(f"report settings {p}: {first_problem(exc)}") from exc
    settings.check_logo()
    return settings


def save_settings(settings: ReportSettings, path: str | os.PathLike[str]) -> None:
    """Write the settings as YAML (to a temporary file, then renamed over ``path``)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    data = settings.model_dump(mode="json")
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text(yaml.safe_dump(data, sort_keys=False, allow_unicode=True), encoding="utf-8")
    os.replace(tmp, p)
