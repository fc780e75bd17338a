"""Shared pieces of the clinical-record tests: a settable clock, a fast Argon2id hasher and a
record populated with one user per role."""
from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

from argon2 import PasswordHasher

from patients.service import Actor, ClinicalRecord

T0 = dt.datetime(2026, 3, 2, 9, 0, tzinfo=dt.timezone.utc)
PASSWORD = "a long test password"
PROTOCOL = "protocols/library/ankle_rom.yaml"


class Clock:
    """Injected time (aware UTC); ``advance`` moves it."""

    def __init__(self, start: dt.datetime = T0) -> None:
        self.now = start

    def __call__(self) -> dt.datetime:
        return self.now

    def advance(self, seconds: float) -> dt.datetime:
        self.now += dt.timedelta(seconds=seconds)
        return self.now


def fast_hasher() -> PasswordHasher:
    """Argon2id still, with parameters small enough for hundreds of logins in a test run."""
    return PasswordHasher(time_cost=1, memory_cost=1024, parallelism=1)


def open_record(url: str, clock: Clock | None = None) -> ClinicalRecord:
    return ClinicalRecord.open(url, create=True, clock=clock or Clock(), hasher=fast_hasher())


@dataclass
class Staff:
    admin: Actor
    clinician: Actor
    engineer: Actor
    viewer: Actor

    def by_role(self, role: str) -> Actor:
        return getattr(self, role)


def staff(record: ClinicalRecord) -> Staff:
    admin = record.init_admin("admin", PASSWORD)
    for name in ("clinician", "engineer", "viewer"):
        record.add_user(admin, name, name, PASSWORD)
    return Staff(admin, *(record.authenticate(n, PASSWORD)
                          for n in ("clinician", "engineer", "viewer")))
