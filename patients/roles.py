"""Who may do what: the one permission table the service layer enforces (docs/roles.md).

The CLI and the GUI never check roles themselves; they call ``patients.service`` which calls
``require`` before touching anything. ``docs/roles.md`` is generated from ``PERMISSIONS``
(``roles_markdown``) and a test keeps the two equal.
"""
from __future__ import annotations

import enum

from patients.errors import PermissionDenied


class Role(str, enum.Enum):
    """A user's one role."""

    ADMIN = "admin"          #: accounts, GDPR erasure, audit, backups; no clinical decisions
    CLINICIAN = "clinician"  #: patients, limits, plans, sessions
    ENGINEER = "engineer"    #: calibrations; reads pseudonymous sessions for technical review
    VIEWER = "viewer"        #: reads the pseudonymous record (research, supervision)


class Action(str, enum.Enum):
    """Everything the service layer does on behalf of a user."""

    USERS_MANAGE = "users.manage"
    PATIENT_CREATE = "patient.create"
    PATIENT_READ = "patient.read"
    PATIENT_UPDATE = "patient.update"
    IDENTITY_READ = "identity.read"
    IDENTITY_WRITE = "identity.write"
    PATIENT_FORGET = "patient.forget"
    LIMITS_SET = "limits.set"
    PLAN_ASSIGN = "plan.assign"
    SESSION_RUN = "session.run"
    SESSION_READ = "session.read"
    RECORD_EXPORT = "record.export"
    RECORD_IMPORT = "record.import"
    CALIBRATION_WRITE = "calibration.write"
    CALIBRATION_READ = "calibration.read"
    AUDIT_READ = "audit.read"
    DATABASE_ADMIN = "database.admin"


A, C, E, V = Role.ADMIN, Role.CLINICIAN, Role.ENGINEER, Role.VIEWER

#: action -> (roles allowed, what it covers)
PERMISSIONS: dict[Action, tuple[frozenset[Role], str]] = {
    Action.USERS_MANAGE: (frozenset({A}), "add users, change any password, unlock, disable"),
    Action.PATIENT_CREATE: (frozenset({A, C}), "register a patient (code, clinical data)"),
    Action.PATIENT_READ: (frozenset({A, C, E, V}),
                          "pseudonymous record: code, clinical data, limits, plans"),
    Action.PATIENT_UPDATE: (frozenset({C}), "change clinical data (mass, height, side, ...)"),
    Action.IDENTITY_READ: (frozenset({A, C}), "read name, birth date, national id, contact "
                                              "(every read is audited)"),
    Action.IDENTITY_WRITE: (frozenset({A, C}), "enter or correct identifying data"),
    Action.PATIENT_FORGET: (frozenset({A}), "erase identifying data (GDPR art. 17)"),
    Action.LIMITS_SET: (frozenset({C}), "prescribe ROM, force and speed limits"),
    Action.PLAN_ASSIGN: (frozenset({C}), "assign a protocol to a patient, end a plan"),
    Action.SESSION_RUN: (frozenset({C}), "start and finish a therapy session"),
    Action.SESSION_READ: (frozenset({A, C, E, V}), "list and show sessions (pseudonymous)"),
    Action.RECORD_EXPORT: (frozenset({A, C}), "export a patient's pseudonymous record"),
    Action.RECORD_IMPORT: (frozenset({A, C}), "import a pseudonymous record"),
    Action.CALIBRATION_WRITE: (frozenset({E}), "store a force-plate calibration record"),
    Action.CALIBRATION_READ: (frozenset({A, C, E, V}), "list and read calibration records"),
    Action.AUDIT_READ: (frozenset({A}), "verify and export the audit log"),
    Action.DATABASE_ADMIN: (frozenset({A}), "back up and restore the database"),
}


def allowed(role: Role, action: Action) -> bool:
    """Whether ``role`` may do ``action``."""
    return role in PERMISSIONS[action][0]


def require(role: Role, action: Action, username: str) -> None:
    """Raise ``PermissionDenied`` unless ``role`` may do ``action``."""
    if not allowed(role, action):
        raise PermissionDenied(f"user {username!r} ({role.value}) may not {action.value}: "
                               f"{PERMISSIONS[action][1]} (see docs/roles.md)")


def roles_markdown() -> str:
    """The roles table of docs/roles.md (generated; a test keeps the file in step)."""
    head = "| action | what | " + " | ".join(r.value for r in Role) + " |"
    rule = "|---|---|" + "---|" * len(Role)
    rows = [f"| `{a.value}` | {what} | "
            + " | ".join("yes" if r in roles else "—" for r in Role) + " |"
            for a, (roles, what) in PERMISSIONS.items()]
    return "\n".join([head, rule, *rows]) + "\n"
