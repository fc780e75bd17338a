"""Argon2id password hashing and the lockout policy. No default password exists anywhere:
every account's password is typed by a person or given in $TALUS_PASSWORD."""
from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError

from patients.errors import InputError

#: Shortest password accepted (characters).
MIN_PASSWORD_LENGTH = 10


def default_hasher() -> PasswordHasher:
    """Argon2id with argon2-cffi's defaults (RFC 9106 "low memory": t=3, 64 MiB, p=4)."""
    return PasswordHasher()


def check_new_password(username: str, password: str) -> None:
    """Refuse passwords that are too short or are the user name."""
    if len(password) < MIN_PASSWORD_LENGTH:
        raise InputError(f"the password must have at least {MIN_PASSWORD_LENGTH} characters")
    if password.strip().lower() == username.strip().lower():
        raise InputError("the password must not be the user name")


def verify(hasher: PasswordHasher, stored_hash: str, password: str) -> bool:
    try:
        return bool(hasher.verify(stored_hash, password))
    except (VerificationError, InvalidHashError):
        return False


@dataclass(frozen=True)
class LockoutPolicy:
    """After ``max_failures`` wrong passwords in a row the account is locked for ``lock_s``."""

    max_failures: int = 5
    lock_s: float = 15 * 60.0

    def locked_until(self, now: dt.datetime, failures: int) -> dt.datetime | None:
        return now + dt.timedelta(seconds=self.lock_s) if failures >= self.max_failures \
            else None
