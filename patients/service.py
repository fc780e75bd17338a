"""The clinical record's one service layer: every read and write the CLI, the GUI and the RT
session runner make goes through ``ClinicalRecord``, which authenticates, checks the role
(patients.roles), writes the audit log in the same transaction, and never lets a half-done
change reach the database.

Typical use::

    record = ClinicalRecord.open("postgresql://talus@db/clinic")      # or None: the default
    me = record.authenticate("alice", password)                     # Actor, or raises
    limits = record.limits_in_force(me, "P7K3M9QX")                  # PatientLimits fields + mass
    uid = record.start_session(me, "P7K3M9QX", protocol_yaml)
    record.finish_session(me, uid, Outcome.COMPLETED, summary=summary, recording=(path, sha))

Times come from the injected ``clock`` (aware UTC). Results are plain dicts (JSON-ready).
"""
from __future__ import annotations

import datetime as dt
import hashlib
import re
import secrets
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Self, TypeVar

import sqlalchemy as sa
from argon2 import PasswordHasher
from pydantic import ValidationError
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session
from sqlalchemy.orm.exc import StaleDataError

from patients import audit, passwords, transfer
from patients import db as dbmod
from patients.anatomy import ClinicalRom, to_clinical
from patients.errors import (
    AccountLocked,
    AlreadyExists,
    AuthenticationFailed,
    ConcurrentUpdate,
    InputError,
    NotFound,
    RecordError,
)
from patients.models import (
    Calibration,
    Outcome,
    Patient,
    PatientAnkleRow,
    PatientIdentity,
    PatientLimitsRow,
    Plan,
    Side,
    TherapySession,
    User,
)
from patients.roles import Action, Role, require
from rt.safety.limits import PatientLimits

Clock = Callable[[], dt.datetime]
_Row = TypeVar("_Row")
_Prescription = TypeVar("_Prescription", PatientLimitsRow, PatientAnkleRow)

#: Fields of ``rt.safety.limits.PatientLimits``, in its order.
LIMIT_FIELDS = tuple(PatientLimits.model_fields)
CLINICAL_FIELDS = ("body_mass_kg", "height_m", "affected_side", "diagnosis", "notes")
IDENTITY_FIELDS = ("full_name", "birth_date", "national_id", "contact")
#: The lockout used unless a deployment sets its own (the policy is immutable).
DEFAULT_LOCKOUT = passwords.LockoutPolicy()
_CODE = re.compile(r"^[A-Z0-9][A-Z0-9-]{2,31}$")
_USERNAME = re.compile(r"^[a-z][a-z0-9._-]{1,63}$")
#: Crockford base32 without I, L, O, U: codes read aloud or copied by hand without mistakes.
_CODE_ALPHABET = "0123456789ABCDEFGHJKMNPQRSTVWXYZ"


def utc_now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def sha256_text(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class Actor:
    """A logged-in user, as handed out by ``authenticate``; the service checks its token."""

    username: str
    role: Role
    token: str = field(repr=False)


@dataclass(frozen=True)
class Identity:
    """Identifying data (never leaves the service except to roles allowed to read it)."""

    full_name: str
    birth_date: dt.date | None = None
    national_id: str | None = None
    contact: str | None = None


class _Act:
    """One request of a logged-in actor inside its transaction (``ClinicalRecord._acting``):
    the session ``db``, the actor's re-read ``user`` row, and the queries and audit rows
    bound to them; ``audited`` counts the rows written."""

    def __init__(self, record: ClinicalRecord, db: Session, actor: Actor, user: User) -> None:
        self.db = db
        self.user = user
        self.username = actor.username
        self.audited = 0
        self._record = record
        self._actor = actor

    def require(self, action: Action) -> None:
        """A further permission the request needs (e.g. identifying data on top of a read)."""
        self._record._require(self.db, self._actor, action)

    def patient(self, code: str, lock: bool = False) -> Patient:
        """The patient with ``code`` (``NotFound`` otherwise), locked for update with ``lock``."""
        return self._record._patient(self.db, code, lock)

    def audit(self, action: str, entity: str, key: str | None = None, before: Any = None,
              after: Any = None) -> None:
        """One audit row by this actor, in this transaction (kept only if it commits)."""
        self._record._audit(self.db, self._actor, action, entity, key, before, after)
        self.audited += 1


class ClinicalRecord:
    """The clinical record on one database. Thread-safe like an SQLAlchemy engine."""

    def __init__(self, engine: Engine, clock: Clock = utc_now,
                 hasher: PasswordHasher | None = None,
                 lockout: passwords.LockoutPolicy = DEFAULT_LOCKOUT) -> None:
        self.engine = engine
        self.clock = clock
        self.hasher = hasher or passwords.default_hasher()
        self.lockout = lockout
        self._logins: dict[str, str] = {}  # token -> username
        self._dummy: str | None = None

    @classmethod
    def open(cls, db: str | None = None, *, create: bool = False, **kwargs: Any) -> ClinicalRecord:
        """Open the record at ``db`` (see patients.db.resolve_url).

        ``create`` makes a missing SQLite file and migrates an empty database to the current
        schema; otherwise the schema must already be current.
        """
        engine = dbmod.create_engine(dbmod.resolve_url(db), create=create)
        try:
            if create:
                dbmod.upgrade(engine)
            else:
                dbmod.require_current(engine)
        except sa.exc.OperationalError as exc:
            engine.dispose()
            raise RecordError(f"cannot open {dbmod.describe(engine.url)}: "
                              f"{exc.orig or exc}") from None
        except BaseException:
            engine.dispose()
            raise
        return cls(engine, **kwargs)

    def close(self) -> None:
        self.engine.dispose()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------ plumbing
    @contextmanager
    def _tx(self) -> Iterator[Session]:
        """One transaction: committed if the block ends normally, rolled back otherwise."""
        try:
            with Session(self.engine, expire_on_commit=False) as db, db.begin():
                yield db
        except StaleDataError:
            raise ConcurrentUpdate("someone else changed this record at the same time; "
                                   "reload it and apply your change again") from None
        except sa.exc.IntegrityError as exc:
            # A unique key taken by another workstation between our check and our insert.
            raise ConcurrentUpdate(f"conflicting change saved at the same time elsewhere; "
                                   f"nothing was changed ({exc.orig or exc})") from None
        except sa.exc.OperationalError as exc:
            raise RecordError(f"database error: {exc.orig or exc}") from None

    def _audit(self, db: Session, actor: Actor | str | None, action: str, entity: str,
               key: str | None = None, before: Any = None, after: Any = None) -> None:
        name = actor.username if isinstance(actor, Actor) else actor
        audit.append(db, self.clock(), name, action, entity, key, before, after)

    @contextmanager
    def _acting(self, actor: Actor, action: Action | None, *, writes: bool = False
                ) -> Iterator[_Act]:
        """One request of a logged-in ``actor``: a transaction (``_tx``) in which the actor is
        re-read and checked for ``action`` before anything else, handing out the queries and
        the audit trail bound to it (:class:`_Act`).

        ``writes``: the request changes the record, so it must leave at least one audit row;
        a block that ends normally without one is a bug, refused and rolled back rather than
        committed unaudited."""
        with self._tx() as db:
            act = _Act(self, db, actor, self._require(db, actor, action))
            yield act
            if writes and act.audited == 0:
                raise RecordError(f"internal error: a change by {actor.username!r} wrote no "
                                  "audit row; nothing was saved")

    def _require(self, db: Session, actor: Actor, action: Action | None) -> User:
        """The acting user, re-read: a disabled account or changed role takes effect at once.
        ``action`` None: any role (e.g. changing one's own password)."""
        if self._logins.get(actor.token) != actor.username:
            raise AuthenticationFailed("not logged in: authenticate first")
        user = db.execute(sa.select(User).where(User.username == actor.username)) \
            .scalar_one_or_none()
        if user is None or user.disabled:
            raise AuthenticationFailed(f"user {actor.username!r} is disabled")
        if action is not None:
            require(Role(user.role), action, user.username)
        return user

    @staticmethod
    def _patient(db: Session, code: str, lock: bool = False) -> Patient:
        return _one(db, sa.select(Patient).where(Patient.code == code),
                    f"no patient with code {code!r}", lock)

    # ------------------------------------------------------------ users
    def has_users(self) -> bool:
        with self._tx() as db:
            return db.execute(sa.select(sa.func.count()).select_from(User)).scalar_one() > 0

    def init_admin(self, username: str, password: str) -> Actor:
        """Create the first admin (only on a database with no users) and log them in."""
        _check_username(username)
        passwords.check_new_password(username, password)
        with self._tx() as db:
            if db.execute(sa.select(sa.func.count()).select_from(User)).scalar_one():
                raise AlreadyExists("this database already has users: the first admin was "
                                    "created before; ask an admin to add you (`users add`)")
            db.add(User(username=username, role=Role.ADMIN.value,
                        password_hash=self.hasher.hash(password), created_at=self.clock(),
                        created_by=None))
            self._audit(db, username, "users.init", "user", username,
                        after={"role": Role.ADMIN.value})
        return self._login(username, Role.ADMIN)

    def _login(self, username: str, role: Role) -> Actor:
        token = secrets.token_hex(16)
        self._logins[token] = username
        return Actor(username, role, token)

    def authenticate(self, username: str, password: str) -> Actor:
        """Check the password (Argon2id); lock the account after repeated failures."""
        now = self.clock()
        failure: RecordError | None = None
        with self._tx() as db:
            user = db.execute(sa.select(User).where(User.username == username)
                              .with_for_update()).scalar_one_or_none()
            if user is None or user.disabled:
                # Spend the time a real check takes: the answer's delay must not tell
                # whether the account exists.
                passwords.verify(self.hasher, self._dummy_hash(), password)
                self._audit(db, username, "login.failed", "user", username,
                            after={"reason": "unknown or disabled user"})
                failure = AuthenticationFailed("wrong user name or password")
            elif user.locked_until is not None and user.locked_until > now:
                self._audit(db, username, "login.refused", "user", username,
                            after={"reason": "locked", "until": user.locked_until})
                failure = AccountLocked(
                    f"account {username!r} is locked until {user.locked_until.isoformat()} "
                    "after repeated wrong passwords (an admin can unlock it with "
                    "`talus users passwd`)")
            elif not passwords.verify(self.hasher, user.password_hash, password):
                user.failed_logins += 1
                user.locked_until = self.lockout.locked_until(now, user.failed_logins)
                self._audit(db, username, "login.failed", "user", username,
                            after={"failures": user.failed_logins,
                                   "locked_until": user.locked_until})
                failure = AuthenticationFailed("wrong user name or password")
            else:
                if self.hasher.check_needs_rehash(user.password_hash):
                    user.password_hash = self.hasher.hash(password)
                user.failed_logins, user.locked_until = 0, None
                self._audit(db, username, "login", "user", username)
                role = Role(user.role)
        if failure is not None:  # raised after the commit: the failure stays counted
            raise failure
        return self._login(username, role)

    def _dummy_hash(self) -> str:
        if self._dummy is None:
            self._dummy = self.hasher.hash(secrets.token_hex(16))
        return self._dummy

    def logout(self, actor: Actor) -> None:
        self._logins.pop(actor.token, None)

    def add_user(self, actor: Actor, username: str, role: Role | str, password: str) -> dict[str, Any]:
        _check_username(username)
        role_: Role = _enum(Role, role, "role")
        passwords.check_new_password(username, password)
        with self._acting(actor, Action.USERS_MANAGE, writes=True) as act:
            if act.db.execute(sa.select(User.id).where(User.username == username)).first():
                raise AlreadyExists(f"user {username!r} exists")
            user = User(username=username, role=role_.value,
                        password_hash=self.hasher.hash(password), created_at=self.clock(),
                        created_by=actor.username)
            act.db.add(user)
            act.audit("user.create", "user", username, after={"role": role_.value})
            act.db.flush()
            return _user_dict(user)

    def set_password(self, actor: Actor, username: str, new_password: str,
                     old_password: str | None = None) -> None:
        """An admin sets anyone's password (and unlocks); others change their own with the old."""
        passwords.check_new_password(username, new_password)
        # One's own password with the current one: any role; anything else: an admin's act.
        own_old = old_password if username == actor.username else None
        with self._acting(actor, None if own_old is not None else Action.USERS_MANAGE,
                          writes=True) as act:
            if own_old is not None:
                if not passwords.verify(self.hasher, act.user.password_hash, own_old):
                    raise AuthenticationFailed("the current password is wrong")
                user = act.user
            else:
                user = _user(act.db, username)
            user.password_hash = self.hasher.hash(new_password)
            user.failed_logins, user.locked_until = 0, None
            act.audit("user.passwd", "user", username)

    def set_user_disabled(self, actor: Actor, username: str, disabled: bool) -> None:
        with self._acting(actor, Action.USERS_MANAGE, writes=True) as act:
            if username == actor.username:
                raise InputError("an admin cannot disable their own account")
            user = _user(act.db, username)
            before = user.disabled
            user.disabled = disabled
            act.audit("user.disable" if disabled else "user.enable", "user",
                      username, before={"disabled": before}, after={"disabled": disabled})

    def list_users(self, actor: Actor) -> list[dict[str, Any]]:
        with self._acting(actor, Action.USERS_MANAGE) as act:
            return [_user_dict(u) for u in act.db.execute(sa.select(User).order_by(User.username))
                    .scalars()]

    # ------------------------------------------------------------ patients
    def add_patient(self, actor: Actor, code: str | None = None, *,
                    identity: Identity | None = None, **clinical: Any) -> dict[str, Any]:
        """Register a patient; ``code`` is generated when not given. Returns ``show``'s dict."""
        values = _clinical(clinical)
        with self._acting(actor, Action.PATIENT_CREATE, writes=True) as act:
            if identity is not None:
                act.require(Action.IDENTITY_WRITE)
            code = _check_code(code) if code else self._new_code(act.db)
            if act.db.execute(sa.select(Patient.id).where(Patient.code == code)).first():
                raise AlreadyExists(f"patient code {code!r} is taken")
            patient = Patient(code=code, created_at=self.clock(), created_by=actor.username,
                              **values)
            act.db.add(patient)
            act.audit("patient.create", "patient", code, after=values)
            if identity is not None:
                patient.identity = _identity_row(identity)
                act.audit("identity.create", "patient", code,
                          after={"fields": _present(identity)})
            act.db.flush()
            return _patient_dict(patient, self._limits_row(act.db, patient))

    @staticmethod
    def _new_code(db: Session) -> str:
        while True:
            code = "P" + "".join(secrets.choice(_CODE_ALPHABET) for _ in range(7))
            if not db.execute(sa.select(Patient.id).where(Patient.code == code)).first():
                return code

    def list_patients(self, actor: Actor, include_identity: bool = False) -> list[dict[str, Any]]:
        with self._acting(actor, Action.PATIENT_READ) as act:
            if include_identity:
                act.require(Action.IDENTITY_READ)
            out = []
            for p in act.db.execute(sa.select(Patient).order_by(Patient.code)).scalars():
                d = _patient_dict(p, None)
                if include_identity:
                    d["identity"] = _identity_dict(p.identity)
                out.append(d)
            if include_identity:
                act.audit("identity.read", "patient", None,
                          after={"codes": [d["code"] for d in out],
                                 "fields": list(IDENTITY_FIELDS)})
            return out

    def get_patient(self, actor: Actor, code: str, include_identity: bool = False) -> dict[str, Any]:
        with self._acting(actor, Action.PATIENT_READ) as act:
            patient = act.patient(code)
            d = _patient_dict(patient, self._limits_row(act.db, patient))
            if include_identity:
                act.require(Action.IDENTITY_READ)
                d["identity"] = _identity_dict(patient.identity)
                act.audit("identity.read", "patient", code,
                          after={"fields": list(IDENTITY_FIELDS)})
            return d

    def update_patient(self, actor: Actor, code: str, expected_version: int | None = None,
                       **changes: Any) -> dict[str, Any]:
        """Change clinical data. ``expected_version`` (the ``version`` the caller showed the
        user) refuses the change if someone else saved in between: no lost update."""
        values = _clinical(changes)
        with self._acting(actor, Action.PATIENT_UPDATE, writes=True) as act:
            patient = act.patient(code)
            if expected_version is not None and patient.version != expected_version:
                raise ConcurrentUpdate(
                    f"patient {code} was changed by someone else (version {patient.version}, "
                    f"you edited version {expected_version}); reload it and apply your change "
                    "again")
            before = {k: getattr(patient, k) for k in values}
            for k, v in values.items():
                setattr(patient, k, v)
            act.db.flush()  # UPDATE ... WHERE version = read version (StaleDataError otherwise)
            act.audit("patient.update", "patient", code, before=before, after=values)
            return _patient_dict(patient, self._limits_row(act.db, patient))

    def set_identity(self, actor: Actor, code: str, identity: Identity) -> None:
        with self._acting(actor, Action.IDENTITY_WRITE, writes=True) as act:
            patient = act.patient(code)
            if patient.forgotten_at is not None:
                raise InputError(f"patient {code} was forgotten (GDPR erasure); identifying "
                                 "data cannot be attached again")
            action = "identity.update" if patient.identity else "identity.create"
            row = _identity_row(identity)  # validated before anything changes
            if patient.identity is None:
                patient.identity = row
            else:
                for k in IDENTITY_FIELDS:
                    setattr(patient.identity, k, getattr(row, k))
            act.audit(action, "patient", code, after={"fields": _present(identity)})

    def forget_patient(self, actor: Actor, code: str) -> dict[str, Any]:
        """Erase the identifying data; the pseudonymous clinical history stays (GDPR art. 17).

        SQLite: ``secure_delete`` zeroes the freed pages and the WAL is checkpointed and
        truncated, so the name is in no file of the database afterwards. PostgreSQL: the row is
        deleted and the table vacuumed; no dump holds it. Backups taken before still do: they
        follow the clinic's retention policy.
        """
        with self._acting(actor, Action.PATIENT_FORGET, writes=True) as act:
            patient = act.patient(code, lock=True)
            had = patient.identity is not None
            if patient.identity is not None:
                act.db.delete(patient.identity)
                patient.identity = None
            patient.forgotten_at = self.clock()
            act.audit("patient.forget", "patient", code,
                      after={"identity_erased": had})
        return {"code": code, "identity_erased": had, "storage_scrubbed": self._scrub()}

    def _scrub(self) -> bool:
        """Push the erasure out of the WAL (SQLite) or the table's dead rows (PostgreSQL).

        Outside any transaction (neither statement may run inside one). False when it could
        not complete (a long reader on SQLite; not the table's owner on PostgreSQL): the data
        are deleted either way, and the next checkpoint/autovacuum finishes the job.
        """
        try:
            if dbmod.is_sqlite(self.engine.url):
                raw = self.engine.raw_connection()
                try:
                    busy = raw.driver_connection.execute(  # type: ignore[union-attr]
                        "PRAGMA wal_checkpoint(TRUNCATE)").fetchone()[0]
                finally:
                    raw.close()
                return busy == 0
            with self.engine.connect().execution_options(isolation_level="AUTOCOMMIT") as conn:
                conn.exec_driver_sql("VACUUM patient_identities")
            return True
        except sa.exc.DBAPIError:
            return False

    # ------------------------------------------------------------ limits and plans
    @staticmethod
    def _limits_row(db: Session, patient: Patient) -> PatientLimitsRow | None:
        return _latest(db, PatientLimitsRow, patient)

    def set_limits(self, actor: Actor, code: str, reason: str | None = None,
                   **limits: float) -> dict[str, Any]:
        """Prescribe new limits (``PatientLimits`` fields, deg, N, deg/s); unset fields keep the
        values in force (or PatientLimits' defaults for the first prescription)."""
        with self._acting(actor, Action.LIMITS_SET, writes=True) as act:
            patient = act.patient(code, lock=True)
            current = self._limits_row(act.db, patient)
            base = _limits_dict(current) if current else PatientLimits().model_dump()
            unknown = set(limits) - set(LIMIT_FIELDS)
            if unknown:
                raise InputError(f"unknown limit(s) {sorted(unknown)}; known: {list(LIMIT_FIELDS)}")
            merged = {**base, **{k: v for k, v in limits.items() if v is not None}}
            try:
                checked = PatientLimits(**merged).model_dump()
            except ValidationError as exc:
                raise InputError(f"limits for {code} refused: {_pydantic_reason(exc)}") from None
            row = self._prescribe(act, PatientLimitsRow, patient, checked, reason, "limits.set",
                                  _limits_dict(current) if current else None)
            return _limits_record(row, patient.affected_side)

    def _prescribe(self, act: _Act, table: type[_Prescription], patient: Patient,
                   checked: dict[str, Any], reason: str | None, action: str,
                   before: dict[str, Any] | None) -> _Prescription:
        """A new prescription row (limits or ankle setup: the newest is in force), by the
        actor, now, audited against the one it replaces (``before``)."""
        row = table(patient_id=patient.id, set_by=act.username, set_at=self.clock(),
                    reason=reason, **checked)
        act.db.add(row)
        act.audit(action, "patient", patient.code, before=before, after=checked)
        act.db.flush()
        return row

    def limits_in_force(self, actor: Actor, code: str) -> dict[str, Any]:
        """What the RT process needs: ``PatientLimits``' fields plus ``body_mass_kg`` (kg).

        Raises NotFound when no limits were ever prescribed: a session needs a clinician's
        prescription, never silent defaults.
        """
        with self._acting(actor, Action.PATIENT_READ) as act:
            patient = act.patient(code)
            row = self._limits_row(act.db, patient)
            if row is None:
                raise NotFound(f"patient {code} has no limits prescribed: a clinician sets them "
                               f"with `talus patients limits {code} ...`")
            return {**_limits_dict(row), "body_mass_kg": patient.body_mass_kg}

    # ------------------------------------------------------------ ankle setup
    @staticmethod
    def _ankle_row(db: Session, patient: Patient) -> PatientAnkleRow | None:
        return _latest(db, PatientAnkleRow, patient)

    def set_ankle(self, actor: Actor, code: str, reason: str | None = None,
                  **fields: Any) -> dict[str, Any]:
        """Record where the patient's ankle centre sits on the platform
        (``rt.model.ankle.AnkleSetup`` fields: side, height_above_sole_m, offset_x_m,
        offset_y_m, sole_above_sensor_m, source; m). Unset fields keep the values in force;
        ``side`` defaults to the affected side. A missing or implausible setup (no height, at or
        below the sole) is refused naming the field; the RT process also checks it lies on its
        platform."""
        from rt.errors import InputError as RtInputError
        from rt.model.ankle import AnkleSetup, parse_ankle_setup
        with self._acting(actor, Action.LIMITS_SET, writes=True) as act:
            patient = act.patient(code, lock=True)
            current = self._ankle_row(act.db, patient)
            base: dict[str, Any] = _ankle_dict(current) if current else {
                "side": patient.affected_side}
            unknown = set(fields) - set(AnkleSetup.model_fields)
            if unknown:
                raise InputError(f"unknown ankle field(s) {sorted(unknown)}; known: "
                                 f"{list(AnkleSetup.model_fields)}")
            merged = {**base, **{k: v for k, v in fields.items() if v is not None}}
            try:
                # The platform's radius is the RT process's to check; here the widest any
                # platform of this product could be (1 m) only catches unit mistakes.
                checked = parse_ankle_setup(merged, 1.0).model_dump()
            except RtInputError as exc:
                raise InputError(f"ankle setup for {code} refused: {exc}") from None
            row = self._prescribe(act, PatientAnkleRow, patient, checked, reason, "ankle.set",
                                  _ankle_dict(current) if current else None)
            return {**checked, "set_by": row.set_by, "set_at": _iso(row.set_at),
                    "reason": reason}

    def ankle_in_force(self, actor: Actor, code: str) -> dict[str, Any] | None:
        """The ankle setup in force (``AnkleSetup`` fields), None when none was entered."""
        with self._acting(actor, Action.PATIENT_READ) as act:
            row = self._ankle_row(act.db, act.patient(code))
            return _ankle_dict(row) if row is not None else None

    def limits_history(self, actor: Actor, code: str) -> list[dict[str, Any]]:
        with self._acting(actor, Action.PATIENT_READ) as act:
            patient = act.patient(code)
            return [_limits_record(r, patient.affected_side) for r in patient.limits]

    def assign_plan(self, actor: Actor, code: str, protocol_yaml: str,
                    parameters: dict[str, Any] | None = None) -> dict[str, Any]:
        """Assign a protocol (its YAML text, validated) to a patient."""
        protocol = _validate_protocol(protocol_yaml)
        with self._acting(actor, Action.PLAN_ASSIGN, writes=True) as act:
            patient = act.patient(code)
            plan = Plan(patient_id=patient.id, protocol_name=protocol.name,
                        protocol_kind=protocol.kind, protocol_yaml=protocol_yaml,
                        protocol_sha256=sha256_text(protocol_yaml), parameters=parameters or {},
                        assigned_by=actor.username, assigned_at=self.clock(), active=True)
            act.db.add(plan)
            act.db.flush()
            act.audit("plan.assign", "patient", code,
                      after={"plan": plan.id, "protocol": plan.protocol_name,
                             "sha256": plan.protocol_sha256})
            return _plan_dict(plan)

    def end_plan(self, actor: Actor, code: str, plan_id: int) -> dict[str, Any]:
        """Mark a plan finished (kept, with the sessions that used it)."""
        with self._acting(actor, Action.PLAN_ASSIGN, writes=True) as act:
            patient = act.patient(code)
            plan = act.db.get(Plan, plan_id)
            if plan is None or plan.patient_id != patient.id:
                raise NotFound(f"patient {code} has no plan {plan_id}")
            if not plan.active:
                raise InputError(f"plan {plan_id} of {code} has already ended")
            plan.active = False
            act.audit("plan.end", "patient", code, before={"plan": plan_id,
                      "active": True}, after={"plan": plan_id, "active": False})
            return _plan_dict(plan)

    def plans(self, actor: Actor, code: str) -> list[dict[str, Any]]:
        with self._acting(actor, Action.PATIENT_READ) as act:
            patient = act.patient(code)
            return [_plan_dict(p) for p in act.db.execute(
                sa.select(Plan).where(Plan.patient_id == patient.id).order_by(Plan.id)).scalars()]

    # ------------------------------------------------------------ sessions
    def start_session(self, actor: Actor, code: str, protocol_yaml: str,
                      plan_id: int | None = None) -> dict[str, Any]:
        """Open a session row with the protocol and the limits in force, snapshotted.

        Returns ``{"uid", "patient", "limits" (PatientLimits fields), "body_mass_kg",
        "protocol_sha256", "started_at"}``: what ``session_start.patient`` carries to the RT
        process. The recording's metadata gets ``patient`` (the code), never identifying data.
        """
        protocol = _validate_protocol(protocol_yaml)
        with self._acting(actor, Action.SESSION_RUN, writes=True) as act:
            patient = act.patient(code)
            if plan_id is not None:
                plan = act.db.get(Plan, plan_id)
                if plan is None or plan.patient_id != patient.id:
                    raise NotFound(f"patient {code} has no plan {plan_id}")
                if not plan.active:
                    raise InputError(f"plan {plan_id} of {code} has ended: assign a new one")
            row = self._limits_row(act.db, patient)
            if row is None:
                raise NotFound(f"patient {code} has no limits prescribed: a clinician sets them "
                               f"with `talus patients limits {code} ...` before a session")
            s = TherapySession(uid=str(uuid.uuid4()), patient_id=patient.id, plan_id=plan_id,
                               clinician=actor.username, protocol_name=protocol.name,
                               protocol_yaml=protocol_yaml,
                               protocol_sha256=sha256_text(protocol_yaml),
                               limits=_limits_dict(row), body_mass_kg=patient.body_mass_kg,
                               started_at=self.clock(), outcome=Outcome.RUNNING.value)
            act.db.add(s)
            act.audit("session.start", "session", s.uid,
                      after={"patient": code, "protocol": s.protocol_name,
                             "sha256": s.protocol_sha256})
            ankle = self._ankle_row(act.db, patient)
            return {"uid": s.uid, "patient": code, "limits": dict(s.limits),
                    "body_mass_kg": s.body_mass_kg, "protocol_sha256": s.protocol_sha256,
                    "started_at": s.started_at.isoformat(),
                    "ankle": _ankle_dict(ankle) if ankle is not None else None}

    def finish_session(self, actor: Actor, uid: str, outcome: Outcome | str,
                       stopped_by: str | None = None, summary: dict[str, Any] | None = None,
                       recording_path: str | None = None,
                       recording_sha256: str | None = None) -> dict[str, Any]:
        """Close a running session: outcome, who or which fault stopped it, the summary dict
        (``protocols.session.run_session``'s), and the recording's path and sha256."""
        end: Outcome = _enum(Outcome, outcome, "outcome")
        if end is Outcome.RUNNING:
            raise InputError("a session is finished with completed, stopped_by_user, "
                             "stopped_by_fault or refused")
        if end in (Outcome.STOPPED_BY_USER, Outcome.STOPPED_BY_FAULT) and not stopped_by:
            raise InputError(f"outcome {end.value} needs stopped_by (who, or which fault)")
        if recording_sha256 is not None and not re.fullmatch(r"[0-9a-f]{64}", recording_sha256):
            raise InputError("recording_sha256 must be 64 lower-case hex digits")
        with self._acting(actor, Action.SESSION_RUN, writes=True) as act:
            s = _session(act.db, uid, lock=True)
            if s.outcome != Outcome.RUNNING.value:
                raise InputError(f"session {uid} already finished ({s.outcome})")
            s.ended_at, s.outcome, s.stopped_by = self.clock(), end.value, stopped_by
            s.summary = summary
            s.recording_path, s.recording_sha256 = recording_path, recording_sha256
            act.audit("session.finish", "session", uid,
                      after={"outcome": end.value, "stopped_by": stopped_by,
                             "recording_sha256": recording_sha256})
            return _session_dict(s, _code_of(act.db, s.patient_id), full=True)

    def list_sessions(self, actor: Actor, code: str | None = None,
                      since: dt.datetime | None = None, until: dt.datetime | None = None,
                      full: bool = False) -> list[dict[str, Any]]:
        """Sessions, oldest first, optionally of one patient and started in [since, until).
        ``full`` adds the summary and the limits snapshot (what reports need)."""
        with self._acting(actor, Action.SESSION_READ) as act:
            # Plain columns, not ORM objects: listing 10 000 sessions is a report's daily
            # bread (bench/patients.py).
            t = TherapySession
            columns: list[Any] = [t.uid, Patient.code.label("patient"), t.clinician, t.plan_id,
                       t.protocol_name, t.protocol_sha256, t.started_at, t.ended_at, t.outcome,
                       t.stopped_by, t.recording_path, t.recording_sha256]
            if full:
                columns += [t.limits, t.body_mass_kg, t.summary]
            stmt = sa.select(*columns).join(Patient, Patient.id == t.patient_id)
            if code is not None:
                stmt = stmt.where(t.patient_id == act.patient(code).id)
            if since is not None:
                stmt = stmt.where(t.started_at >= since)
            if until is not None:
                stmt = stmt.where(t.started_at < until)
            stmt = stmt.order_by(t.started_at, t.id)
            return [{**row, "started_at": _iso(row["started_at"]),
                     "ended_at": _iso(row["ended_at"])}
                    for row in act.db.execute(stmt).mappings()]

    def get_session(self, actor: Actor, uid: str) -> dict[str, Any]:
        with self._acting(actor, Action.SESSION_READ) as act:
            s = _session(act.db, uid)
            d = _session_dict(s, _code_of(act.db, s.patient_id), full=True)
            d["protocol_yaml"] = s.protocol_yaml
            return d

    # ------------------------------------------------------------ export / import
    def export_patient(self, actor: Actor, code: str) -> dict[str, Any]:
        """The patient's pseudonymous record (patients.transfer), JSON-ready."""
        with self._acting(actor, Action.RECORD_EXPORT) as act:
            p = act.patient(code)
            sessions = act.db.execute(
                sa.select(TherapySession).where(TherapySession.patient_id == p.id)
                .order_by(TherapySession.started_at, TherapySession.id)).scalars().all()
            plans = act.db.execute(sa.select(Plan).where(Plan.patient_id == p.id)
                                   .order_by(Plan.id)).scalars().all()
            doc = {
                "kind": transfer.KIND, "schema_version": transfer.SCHEMA_VERSION,
                "exported_at": _iso(self.clock()), "exported_by": actor.username,
                "patient": {k: v for k, v in _patient_dict(p, None).items() if k != "version"},
                "limits": [{k: v for k, v in _limits_record(r, None).items() if k != "clinical"}
                           for r in p.limits],
                "plans": [{**_plan_dict(x), "protocol_yaml": x.protocol_yaml} for x in plans],
                "sessions": [{**{k: v for k, v in _session_dict(s, code, full=True).items()
                                 if k != "patient"}, "protocol_yaml": s.protocol_yaml}
                             for s in sessions],
                "recordings": [{"session_uid": s.uid, "path": s.recording_path,
                                "sha256": s.recording_sha256}
                               for s in sessions if s.recording_path],
            }
            act.audit("record.export", "patient", code,
                      after={"sessions": len(sessions)})
            return doc

    def import_patient(self, actor: Actor, document: Any) -> dict[str, Any]:
        """Import an exported record as a new patient with the same code (refused if the code
        or a session uid exists here). Returns ``show``'s dict."""
        rec = transfer.parse(document)
        code = _check_code(rec.patient.code)
        with self._acting(actor, Action.RECORD_IMPORT, writes=True) as act:
            if act.db.execute(sa.select(Patient.id).where(Patient.code == code)).first():
                raise AlreadyExists(f"patient code {code!r} exists in this database")
            uids = [s.uid for s in rec.sessions]
            clash = act.db.execute(sa.select(TherapySession.uid)
                                   .where(TherapySession.uid.in_(uids))).scalars().first() \
                if uids else None
            if clash:
                raise AlreadyExists(f"session {clash} exists in this database")
            data = rec.patient.model_dump()
            clinical = _clinical({k: data[k] for k in CLINICAL_FIELDS})
            p = Patient(code=code, created_at=data["created_at"], created_by=data["created_by"],
                        forgotten_at=data["forgotten_at"], **clinical)
            act.db.add(p)
            act.db.flush()
            for lim in rec.limits:
                act.db.add(PatientLimitsRow(patient_id=p.id, **lim.model_dump()))
            plan_ids: dict[int, int] = {}
            for plan in rec.plans:
                fields = plan.model_dump()
                old_id = fields.pop("id")
                row = Plan(patient_id=p.id, **fields)
                act.db.add(row)
                act.db.flush()
                plan_ids[old_id] = row.id
            for s in rec.sessions:
                fields = s.model_dump()
                fields["plan_id"] = plan_ids.get(fields["plan_id"]) if fields["plan_id"] else None
                _enum(Outcome, fields["outcome"], "outcome")
                act.db.add(TherapySession(patient_id=p.id, **fields))
            act.audit("record.import", "patient", code,
                      after={"sessions": len(rec.sessions), "limits": len(rec.limits),
                             "plans": len(rec.plans), "exported_at": rec.exported_at})
            act.db.flush()
            return _patient_dict(p, self._limits_row(act.db, p))

    # ------------------------------------------------------------ calibrations
    def add_calibration(self, actor: Actor, record: dict[str, Any],
                        certificate_path: str | None = None,
                        certificate_sha256: str | None = None) -> dict[str, Any]:
        """Store a calibration record (docs/calibration_record.md, schema 1) whole, with its
        headline figures as columns (:func:`calibration_figures`); audited."""
        fields = _calibration_fields(record)
        _check_certificate(certificate_path, certificate_sha256)
        with self._acting(actor, Action.CALIBRATION_WRITE, writes=True) as act:
            if act.db.execute(sa.select(Calibration.id)
                              .where(Calibration.record_id == fields["record_id"])).first():
                raise AlreadyExists(f"calibration {fields['record_id']} is already stored")
            cal = Calibration(**fields, certificate_path=certificate_path,
                              certificate_sha256=certificate_sha256,
                              added_by=actor.username, added_at=self.clock())
            act.db.add(cal)
            act.audit("calibration.add", "calibration", cal.record_id,
                      after={"plate": cal.plate_name, "serial": cal.plate_serial,
                             "sha256": cal.record_sha256, "passed": cal.passed,
                             "cop_rms_mm": cal.cop_rms_mm, "force_pct_fs": cal.force_pct_fs,
                             "certificate": certificate_path,
                             "certificate_sha256": certificate_sha256})
            return _calibration_dict(cal, full=False)

    def attach_calibration_certificate(self, actor: Actor, record_id: str, path: str,
                                       sha256: str) -> dict[str, Any]:
        """Name the certificate (PDF) of a stored calibration, once: a certificate already
        attached is never replaced (a new calibration gets a new record). Audited."""
        _check_certificate(path, sha256)
        with self._acting(actor, Action.CALIBRATION_WRITE, writes=True) as act:
            cal = _calibration(act.db, record_id)
            if cal.certificate_path is not None:
                raise AlreadyExists(f"calibration {record_id} already has its certificate "
                                    f"({cal.certificate_path}); it is never replaced")
            cal.certificate_path, cal.certificate_sha256 = path, sha256
            act.audit("calibration.certify", "calibration", record_id,
                      before={"certificate": None},
                      after={"certificate": path, "certificate_sha256": sha256})
            return _calibration_dict(cal, full=False)

    def list_calibrations(self, actor: Actor, plate_serial: str | None = None) -> list[dict[str, Any]]:
        with self._acting(actor, Action.CALIBRATION_READ) as act:
            stmt = sa.select(Calibration).order_by(Calibration.created_at)
            if plate_serial is not None:
                stmt = stmt.where(Calibration.plate_serial == plate_serial)
            return [_calibration_dict(c, full=False) for c in act.db.execute(stmt).scalars()]

    def get_calibration(self, actor: Actor, record_id: str) -> dict[str, Any]:
        with self._acting(actor, Action.CALIBRATION_READ) as act:
            cal = _calibration(act.db, record_id)
            return _calibration_dict(cal, full=True)

    # ------------------------------------------------------------ audit
    def verify_audit(self, actor: Actor, anchor: str | None = None) -> audit.Verification:
        """Check the chain; ``anchor`` "SEQ:HASH" is a head noted outside earlier."""
        point = audit.parse_anchor(anchor) if anchor else None
        with self._acting(actor, Action.AUDIT_READ) as act:
            return audit.verify(act.db, point)

    def export_audit(self, actor: Actor) -> list[dict[str, Any]]:
        with self._acting(actor, Action.AUDIT_READ) as act:
            entries = list(audit.export(act.db))
            act.audit("audit.export", "audit", None, after={"entries": len(entries)})
            return entries

    def note_database_action(self, actor: Actor, action: str, detail: dict[str, Any]) -> None:
        """Check DATABASE_ADMIN and log a backup/restore in the audit chain."""
        with self._acting(actor, Action.DATABASE_ADMIN, writes=True) as act:
            act.audit(action, "database", None, after=detail)


# ---------------------------------------------------------------- helpers (pure)

def _enum(kind: Any, value: Any, what: str) -> Any:
    try:
        return kind(value)
    except ValueError:
        raise InputError(f"unknown {what} {value!r}; one of "
                         f"{', '.join(m.value for m in kind)}") from None


def _check_username(username: str) -> None:
    if not _USERNAME.fullmatch(username or ""):
        raise InputError(f"user name {username!r}: 2-64 characters, lower-case letters, digits "
                         "and . _ -, starting with a letter")


def _check_code(code: str) -> str:
    if not _CODE.fullmatch(code):
        raise InputError(f"patient code {code!r}: 3-32 characters, A-Z, 0-9 and '-' (a "
                         "pseudonym: never a name, initials or a national id)")
    return code


def _clinical(values: dict[str, Any]) -> dict[str, Any]:
    unknown = set(values) - set(CLINICAL_FIELDS)
    if unknown:
        raise InputError(f"unknown clinical field(s) {sorted(unknown)}; known: "
                         f"{list(CLINICAL_FIELDS)}")
    out = {k: v for k, v in values.items() if v is not None}
    mass = out.get("body_mass_kg")
    if mass is not None and not 2.0 <= float(mass) <= 400.0:
        raise InputError(f"body mass {mass} kg is outside 2..400 kg")
    height = out.get("height_m")
    if height is not None and not 0.3 <= float(height) <= 2.6:
        raise InputError(f"height {height} m is outside 0.3..2.6 m (give metres)")
    if "affected_side" in out:
        out["affected_side"] = _enum(Side, out["affected_side"], "side").value
    return out


def _present(identity: Identity) -> list[str]:
    return [k for k in IDENTITY_FIELDS if getattr(identity, k) not in (None, "")]


def _identity_row(identity: Identity) -> PatientIdentity:
    if not identity.full_name or not identity.full_name.strip():
        raise InputError("identifying data needs at least the full name")
    return PatientIdentity(full_name=identity.full_name.strip(), birth_date=identity.birth_date,
                           national_id=identity.national_id, contact=identity.contact)


def _identity_dict(row: PatientIdentity | None) -> dict[str, Any] | None:
    if row is None:
        return None
    return {"full_name": row.full_name,
            "birth_date": row.birth_date.isoformat() if row.birth_date else None,
            "national_id": row.national_id, "contact": row.contact}


def _iso(t: dt.datetime | None) -> str | None:
    return t.isoformat() if t is not None else None


def _one(db: Session, stmt: sa.Select[tuple[_Row]], missing: str, lock: bool = False) -> _Row:
    """The one row ``stmt`` selects (locked for update with ``lock``); ``NotFound(missing)``
    when there is none."""
    row = db.execute(stmt.with_for_update() if lock else stmt).scalar_one_or_none()
    if row is None:
        raise NotFound(missing)
    return row


def _user(db: Session, username: str) -> User:
    return _one(db, sa.select(User).where(User.username == username), f"no user {username!r}")


def _user_dict(u: User) -> dict[str, Any]:
    return {"username": u.username, "role": u.role, "disabled": u.disabled,
            "failed_logins": u.failed_logins, "locked_until": _iso(u.locked_until),
            "created_at": _iso(u.created_at), "created_by": u.created_by}


def _limits_dict(row: PatientLimitsRow) -> dict[str, float]:
    return {k: getattr(row, k) for k in LIMIT_FIELDS}


#: The ankle-setup columns (``rt.model.ankle.AnkleSetup`` fields).
ANKLE_FIELDS = ("side", "height_above_sole_m", "offset_x_m", "offset_y_m",
                "sole_above_sensor_m", "source")


def _ankle_dict(row: PatientAnkleRow) -> dict[str, Any]:
    return {k: getattr(row, k) for k in ANKLE_FIELDS}


def _limits_record(row: PatientLimitsRow, side: str | None) -> dict[str, Any]:
    limits = _limits_dict(row)
    clinical = to_clinical(limits, side)
    return {**limits, "clinical": clinical.as_dict() if clinical else None,
            "set_by": row.set_by, "set_at": _iso(row.set_at), "reason": row.reason}


def _patient_dict(p: Patient, limits: PatientLimitsRow | None) -> dict[str, Any]:
    d: dict[str, Any] = {"code": p.code, **{k: getattr(p, k) for k in CLINICAL_FIELDS},
                         "created_at": _iso(p.created_at), "created_by": p.created_by,
                         "forgotten_at": _iso(p.forgotten_at), "version": p.version}
    if limits is not None:
        d["limits"] = _limits_record(limits, p.affected_side)
    return d


def _plan_dict(p: Plan) -> dict[str, Any]:
    return {"id": p.id, "protocol_name": p.protocol_name, "protocol_kind": p.protocol_kind,
            "protocol_sha256": p.protocol_sha256, "parameters": p.parameters,
            "assigned_by": p.assigned_by, "assigned_at": _iso(p.assigned_at), "active": p.active}


def _session(db: Session, uid: str, lock: bool = False) -> TherapySession:
    return _one(db, sa.select(TherapySession).where(TherapySession.uid == uid),
                f"no session {uid!r}", lock)


def _calibration(db: Session, record_id: str) -> Calibration:
    return _one(db, sa.select(Calibration).where(Calibration.record_id == record_id),
                f"no calibration {record_id!r}")


def _latest(db: Session, table: type[_Prescription], patient: Patient) -> _Prescription | None:
    """The patient's newest row of a prescription table (the one in force), None if none."""
    return db.execute(sa.select(table).where(table.patient_id == patient.id)
                      .order_by(table.id.desc()).limit(1)).scalar_one_or_none()


def _code_of(db: Session, patient_id: int) -> str:
    return db.execute(sa.select(Patient.code).where(Patient.id == patient_id)).scalar_one()


def _session_dict(s: TherapySession, code: str, full: bool) -> dict[str, Any]:
    d: dict[str, Any] = {
        "uid": s.uid, "patient": code, "clinician": s.clinician, "plan_id": s.plan_id,
        "protocol_name": s.protocol_name, "protocol_sha256": s.protocol_sha256,
        "started_at": _iso(s.started_at), "ended_at": _iso(s.ended_at), "outcome": s.outcome,
        "stopped_by": s.stopped_by, "recording_path": s.recording_path,
        "recording_sha256": s.recording_sha256}
    if full:
        d["limits"] = s.limits
        d["body_mass_kg"] = s.body_mass_kg
        d["summary"] = s.summary
    return d


def _validate_protocol(text: str) -> Any:
    from protocols.library import parse_protocol_text
    return parse_protocol_text(text, "<protocol>")


def _pydantic_reason(exc: ValidationError) -> str:
    return "; ".join(f"{'.'.join(str(x) for x in e['loc']) or 'limits'}: {e['msg']}"
                     for e in exc.errors())


def _check_certificate(path: str | None, sha256: str | None) -> None:
    if path is None and sha256 is not None:
        raise InputError("a certificate sha256 without the certificate's path")
    if path is not None and not path.strip():
        raise InputError("the calibration certificate's path is empty")
    if sha256 is not None and not re.fullmatch(r"[0-9a-f]{64}", sha256):
        raise InputError(f"certificate sha256 {sha256!r} is not 64 lowercase hex digits")


def calibration_figures(record: dict[str, Any]) -> dict[str, Any]:
    """The record's headline columns: the reference sensor's serial, and on held-out points
    after the fit (``nonlinear`` when present, else ``linear``) the COP error RMS and max (mm)
    and the worst of Fx, Fy, Fz (% FS). Absent or malformed entries give None."""
    def number(x: Any) -> float | None:
        return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else None

    ref = record.get("reference_sensor")
    raw = record.get("metrics")
    metrics: dict[str, Any] = raw if isinstance(raw, dict) else {}
    stage = next((s for s in ("nonlinear", "linear") if isinstance(metrics.get(s), dict)), None)
    m: dict[str, Any] = metrics[stage] if stage else {}
    axes = m.get("force_pct_fs")
    forces = [number(x) for x in axes[:3]] if isinstance(axes, list) else []
    forces_ok = [x for x in forces if x is not None]
    serial = ref.get("serial") if isinstance(ref, dict) else None
    return {"reference_serial": None if serial is None else str(serial)[:100],
            "cop_rms_mm": number(m.get("cop_rms_mm")), "cop_max_mm": number(m.get("cop_max_mm")),
            "force_pct_fs": max(forces_ok) if forces_ok else None, "figures_stage": stage}


def _calibration_fields(record: dict[str, Any]) -> dict[str, Any]:
    if not isinstance(record, dict) or record.get("kind") != "talus.calibration_record":
        raise InputError("not a calibration record (kind must be 'talus.calibration_record')")
    if record.get("schema_version") != 1:
        raise InputError(f"calibration record schema_version {record.get('schema_version')!r} "
                         "is not supported (1 is)")
    missing = [k for k in ("id", "created_utc", "operator", "plate", "matrix", "metrics")
               if k not in record]
    if missing:
        raise InputError(f"calibration record lacks {missing}")
    try:
        created = dt.datetime.fromisoformat(str(record["created_utc"]))
    except ValueError:
        raise InputError(f"calibration created_utc {record['created_utc']!r} is not ISO 8601") \
            from None
    if created.tzinfo is None:
        raise InputError("calibration created_utc must be UTC (end with Z)")
    plate = record["plate"] if isinstance(record["plate"], dict) else {}
    if not plate.get("name"):
        raise InputError("calibration record's plate has no name")
    verdict = record.get("verdict") or {}
    return {"record_id": str(record["id"]), "plate_name": str(plate["name"]),
            "plate_serial": plate.get("serial"), "created_at": created,
            "operator": str(record["operator"]), "passed": verdict.get("pass"),
            "matrix": record["matrix"], "metrics": record["metrics"], "record": record,
            "record_sha256": sha256_text(audit.canonical_json(record)),
            **calibration_figures(record)}


def _calibration_dict(c: Calibration, full: bool) -> dict[str, Any]:
    d: dict[str, Any] = {"record_id": c.record_id, "plate_name": c.plate_name,
                         "plate_serial": c.plate_serial, "created_at": _iso(c.created_at),
                         "operator": c.operator, "passed": c.passed,
                         "certificate_path": c.certificate_path,
                         "certificate_sha256": c.certificate_sha256,
                         "reference_serial": c.reference_serial, "cop_rms_mm": c.cop_rms_mm,
                         "cop_max_mm": c.cop_max_mm, "force_pct_fs": c.force_pct_fs,
                         "figures_stage": c.figures_stage,
                         "record_sha256": c.record_sha256, "added_by": c.added_by,
                         "added_at": _iso(c.added_at)}
    if full:
        d.update(matrix=c.matrix, metrics=c.metrics, record=c.record)
    return d


__all__ = [
    "LIMIT_FIELDS",
    "Actor",
    "ClinicalRecord",
    "ClinicalRom",
    "Identity",
    "Outcome",
    "Role",
    "Side",
    "utc_now",
]
