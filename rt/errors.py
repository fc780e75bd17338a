"""One error hierarchy for the product (CONVENTIONS item 12).

Messages say what was wrong and, where it helps, what to do about it.
"""
from __future__ import annotations


class TalusError(Exception):
    """Root of every error raised on purpose by talus."""


class ConfigurationError(TalusError):
    """A configuration or description file is malformed or inconsistent."""


class InputError(TalusError):
    """A request (CLI line, IPC message, datagram) is malformed; nothing was changed."""


class KinematicsError(TalusError):
    """A pose or joint vector cannot be handled by the kinematic model."""


class WorkspaceError(KinematicsError):
    """The pose or joint vector lies outside the robot's workspace."""


class ConvergenceError(KinematicsError):
    """An iterative solver (forward kinematics) did not converge."""


class HardwareError(TalusError):
    """A device failed to read or write."""


class BackendUnavailableError(HardwareError):
    """A hardware backend was chosen but cannot run on this machine."""


class ProtocolError(HardwareError):
    """A device spoke something that is not its protocol (malformed frame or datagram)."""


class SafetyTrip(TalusError):
    """The safety supervisor stopped the robot."""


class ProtocolValidationError(TalusError):
    """A therapy/calibration protocol file failed validation."""


#: Most problems one validation message lists (a wrong file would otherwise list them all).
MAX_LISTED_PROBLEMS = 6


def _field_name(part: object) -> str:
    """A location part as printed: field names and indices, never arbitrary file text."""
    text = str(part)
    if isinstance(part, int) or (text.isidentifier() and text.isascii() and len(text) <= 40):
        return text
    return f"<a key of {len(text)} characters that is no field name>"


def validation_summary(exc: object) -> str:
    """A pydantic ``ValidationError`` as ``field.path: message; ...``.

    ``str(exc)`` of a pydantic error carries help URLs and echoes the input (a file's
    contents, a 5000-digit number); this keeps field names and messages only, at most
    ``MAX_LISTED_PROBLEMS`` of them. Keys that are not identifiers are not printed: loading
    ``/etc/shadow`` as YAML gives keys holding password hashes.
    """
    errors = exc.errors(include_url=False, include_input=False)  # type: ignore[attr-defined]
    parts = [f"{'.'.join(_field_name(p) for p in e['loc']) or '(top level)'}: {e['msg']}"
             for e in errors[:MAX_LISTED_PROBLEMS]]
    if len(errors) > MAX_LISTED_PROBLEMS:
        parts.append(f"and {len(errors) - MAX_LISTED_PROBLEMS} more problems")
    return "; ".join(parts)
