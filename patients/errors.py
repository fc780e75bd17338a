"""Errors of the clinical record; all are ``TalusError`` so the CLI prints one line, exit 2."""
from __future__ import annotations

from rt.errors import InputError, TalusError


class RecordError(TalusError):
    """The clinical record refused or could not do what was asked; nothing was changed."""


class NotFound(RecordError):
    """No such patient, user, session or calibration."""


class AlreadyExists(RecordError):
    """A code, user name or record id is already taken."""


class AuthenticationFailed(RecordError):
    """Unknown user or wrong password (the message never says which)."""


class AccountLocked(AuthenticationFailed):
    """Too many failed logins: the account is locked for a while (an admin can unlock it)."""


class PermissionDenied(RecordError):
    """The user's role may not do this (docs/roles.md)."""


class ConcurrentUpdate(RecordError):
    """Someone else changed the record since it was read; reload and apply the change again."""


class AuditChainBroken(RecordError):
    """``talus audit verify`` found an edited, inserted or deleted audit row."""


class DatabaseUnavailable(RecordError):
    """The database cannot be opened, or its schema is not at the version this talus needs."""


__all__ = ["RecordError", "NotFound", "AlreadyExists", "AuthenticationFailed", "AccountLocked",
           "PermissionDenied", "ConcurrentUpdate", "AuditChainBroken", "DatabaseUnavailable",
           "InputError"]
