"""Reading a report's input files: one error type, JSON with clear errors, validation messages.

Every bad input becomes a :class:`ReportInputError` whose message names the file (or the
source) and, for a validation failure, the path of the offending key.
"""
from __future__ import annotations

import json
import os
from typing import Any

from pydantic import ValidationError

from rt.errors import InputError


class ReportInputError(InputError):
    """The input of a report is unusable (the message names the file and what is wrong)."""


def read_json(path: str | os.PathLike[str]) -> Any:
    """The parsed JSON of ``path``; ReportInputError for a missing file or invalid JSON."""
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except FileNotFoundError as exc:
        raise ReportInputError(f"{path}: no such file") from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ReportInputError(f"{path}: not valid JSON: {exc}") from exc


def first_problem(exc: ValidationError) -> str:
    """``key.path: message`` of a pydantic validation error's first problem."""
    err = exc.errors()[0]
    where = ".".join(str(x) for x in err["loc"]) or "(top)"
    return f"{where}: {err['msg']}"
