"""The clinical record's tables (SQLAlchemy 2 ORM). The schema is owned by the Alembic
migrations in ``patients/migrations``; a test checks that these models and the migrated schema
agree.

Pseudonymity: every other part of talus (sessions, recordings, reports) knows a patient only by
``Patient.code``. Identifying data lives in ``patient_identities``, read only through the service
layer by roles allowed to, and erased by ``forget``. History keeps user names as text (not
foreign keys) so that an exported record imports into another clinic's database and a disabled
user's history stays readable. Times are timezone-aware UTC.
"""
from __future__ import annotations

import datetime as dt
import enum
from typing import Any

import sqlalchemy as sa
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship


class UTCDateTime(sa.types.TypeDecorator[dt.datetime]):
    """Aware UTC datetimes on both back ends (SQLite hands back naive ones)."""

    impl = sa.DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: dt.datetime | None, dialect: Any) -> dt.datetime | None:
        if value is None:
            return None
        if value.tzinfo is None:
            raise ValueError("naive datetime given to the clinical record; use UTC-aware times")
        return value.astimezone(dt.UTC)

    def process_result_value(self, value: dt.datetime | None, dialect: Any) -> dt.datetime | None:
        if value is None:
            return None
        return value.replace(tzinfo=dt.UTC) if value.tzinfo is None \
            else value.astimezone(dt.UTC)


class Side(str, enum.Enum):
    """The affected side; it also decides which roll sign is inversion (patients.anatomy)."""

    LEFT = "left"
    RIGHT = "right"
    BOTH = "both"


class Outcome(str, enum.Enum):
    """How a session ended."""

    RUNNING = "running"              #: started, not finished (a crash leaves this)
    COMPLETED = "completed"
    STOPPED_BY_USER = "stopped_by_user"    #: ``stopped_by`` names who (user or "patient")
    STOPPED_BY_FAULT = "stopped_by_fault"  #: ``stopped_by`` names the supervisor's cause
    REFUSED = "refused"              #: pre-flight refused it; nothing moved


class Base(DeclarativeBase):
    pass


class User(Base):
    __tablename__ = "users"

    id: Mapped[int] = mapped_column(primary_key=True)
    username: Mapped[str] = mapped_column(sa.String(64), unique=True)
    role: Mapped[str] = mapped_column(sa.String(16))
    password_hash: Mapped[str] = mapped_column(sa.String(255))
    failed_logins: Mapped[int] = mapped_column(default=0)
    locked_until: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    disabled: Mapped[bool] = mapped_column(default=False)
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    created_by: Mapped[str | None] = mapped_column(sa.String(64))
    version: Mapped[int] = mapped_column(default=1)

    # A declarative directive SQLAlchemy reads once, when it maps the class
    __mapper_args__ = {"version_id_col": version}  # noqa: RUF012


class Patient(Base):
    __tablename__ = "patients"

    id: Mapped[int] = mapped_column(primary_key=True)
    code: Mapped[str] = mapped_column(sa.String(32), unique=True)
    body_mass_kg: Mapped[float | None] = mapped_column(sa.Float)
    height_m: Mapped[float | None] = mapped_column(sa.Float)
    affected_side: Mapped[str | None] = mapped_column(sa.String(8))
    diagnosis: Mapped[str | None] = mapped_column(sa.Text)
    notes: Mapped[str | None] = mapped_column(sa.Text)
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    created_by: Mapped[str] = mapped_column(sa.String(64))
    forgotten_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    #: Optimistic locking: an UPDATE names the version it read (no lost update).
    version: Mapped[int] = mapped_column(default=1)

    identity: Mapped[PatientIdentity | None] = relationship(
        back_populates="patient", cascade="all, delete-orphan", uselist=False)
    limits: Mapped[list[PatientLimitsRow]] = relationship(
        back_populates="patient", order_by="PatientLimitsRow.id")

    # A declarative directive SQLAlchemy reads once, when it maps the class
    __mapper_args__ = {"version_id_col": version}  # noqa: RUF012


class PatientIdentity(Base):
    """Identifying data: separate, erasable (GDPR art. 4(5) pseudonymisation, art. 17)."""

    __tablename__ = "patient_identities"

    patient_id: Mapped[int] = mapped_column(
        sa.ForeignKey("patients.id", ondelete="CASCADE"), primary_key=True)
    full_name: Mapped[str] = mapped_column(sa.String(200))
    birth_date: Mapped[dt.date | None] = mapped_column(sa.Date)
    national_id: Mapped[str | None] = mapped_column(sa.String(64))
    contact: Mapped[str | None] = mapped_column(sa.Text)

    patient: Mapped[Patient] = relationship(back_populates="identity")


class PatientLimitsRow(Base):
    """One prescription of limits; the newest row is in force (history is never edited).

    The fields are ``rt.safety.limits.PatientLimits``'s; see patients.anatomy for their
    clinical names and signs.
    """

    __tablename__ = "patient_limits"

    id: Mapped[int] = mapped_column(primary_key=True)
    patient_id: Mapped[int] = mapped_column(
        sa.ForeignKey("patients.id", ondelete="CASCADE"), index=True)
    roll_min_deg: Mapped[float] = mapped_column(sa.Float)
    roll_max_deg: Mapped[float] = mapped_column(sa.Float)
    pitch_min_deg: Mapped[float] = mapped_column(sa.Float)
    pitch_max_deg: Mapped[float] = mapped_column(sa.Float)
    max_force_n: Mapped[float] = mapped_column(sa.Float)
    max_angular_speed_deg_s: Mapped[float] = mapped_column(sa.Float)
    rom_tolerance_deg: Mapped[float] = mapped_column(sa.Float)
    set_by: Mapped[str] = mapped_column(sa.String(64))
    set_at: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    reason: Mapped[str | None] = mapped_column(sa.Text)

    patient: Mapped[Patient] = relationship(back_populates="limits")


class PatientAnkleRow(Base):
    """One entry of where the patient's ankle joint centre sits on the platform
    (``rt.model.ankle.AnkleSetup`` fields, m); the newest row is in force, history is never
    edited. Entered by hand or measured with the camera (``source``)."""

    __tablename__ = "patient_ankle_setups"

    id: Mapped[int] = mapped_column(primary_key=True)
    patient_id: Mapped[int] = mapped_column(
        sa.ForeignKey("patients.id", ondelete="CASCADE"), index=True)
    side: Mapped[str] = mapped_column(sa.String(8))
    height_above_sole_m: Mapped[float] = mapped_column(sa.Float)
    offset_x_m: Mapped[float] = mapped_column(sa.Float)
    offset_y_m: Mapped[float] = mapped_column(sa.Float)
    sole_above_sensor_m: Mapped[float] = mapped_column(sa.Float)
    source: Mapped[str] = mapped_column(sa.String(16))
    set_by: Mapped[str] = mapped_column(sa.String(64))
    set_at: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    reason: Mapped[str | None] = mapped_column(sa.Text)


class Plan(Base):
    """A protocol assigned to a patient: the YAML document stored as data, with its hash."""

    __tablename__ = "plans"

    id: Mapped[int] = mapped_column(primary_key=True)
    patient_id: Mapped[int] = mapped_column(
        sa.ForeignKey("patients.id", ondelete="CASCADE"), index=True)
    protocol_name: Mapped[str] = mapped_column(sa.String(120))
    protocol_kind: Mapped[str] = mapped_column(sa.String(40))
    protocol_yaml: Mapped[str] = mapped_column(sa.Text)
    protocol_sha256: Mapped[str] = mapped_column(sa.String(64))
    parameters: Mapped[dict[str, Any]] = mapped_column(sa.JSON, default=dict)
    assigned_by: Mapped[str] = mapped_column(sa.String(64))
    assigned_at: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    active: Mapped[bool] = mapped_column(default=True)


class TherapySession(Base):
    """One run of a protocol on a patient (what ``talus session run --patient`` stores)."""

    __tablename__ = "sessions"

    id: Mapped[int] = mapped_column(primary_key=True)
    #: Globally unique, so an exported record imports without clashing.
    uid: Mapped[str] = mapped_column(sa.String(36), unique=True)
    patient_id: Mapped[int] = mapped_column(
        sa.ForeignKey("patients.id", ondelete="CASCADE"))
    plan_id: Mapped[int | None] = mapped_column(sa.ForeignKey("plans.id", ondelete="SET NULL"))
    clinician: Mapped[str] = mapped_column(sa.String(64))
    protocol_name: Mapped[str] = mapped_column(sa.String(120))
    protocol_yaml: Mapped[str] = mapped_column(sa.Text)
    protocol_sha256: Mapped[str] = mapped_column(sa.String(64))
    limits: Mapped[dict[str, Any]] = mapped_column(sa.JSON)
    body_mass_kg: Mapped[float | None] = mapped_column(sa.Float)
    started_at: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    ended_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    outcome: Mapped[str] = mapped_column(sa.String(20))
    stopped_by: Mapped[str | None] = mapped_column(sa.String(200))
    summary: Mapped[dict[str, Any] | None] = mapped_column(sa.JSON)
    recording_path: Mapped[str | None] = mapped_column(sa.Text)
    recording_sha256: Mapped[str | None] = mapped_column(sa.String(64))

    __table_args__ = (sa.Index("ix_sessions_patient_started", "patient_id", "started_at"),)


class Calibration(Base):
    """A force-plate calibration record (/work/briefs/calibration_record.md), kept whole."""

    __tablename__ = "calibrations"

    id: Mapped[int] = mapped_column(primary_key=True)
    record_id: Mapped[str] = mapped_column(sa.String(64), unique=True)
    plate_name: Mapped[str] = mapped_column(sa.String(200))
    plate_serial: Mapped[str | None] = mapped_column(sa.String(100), index=True)
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime())
    operator: Mapped[str] = mapped_column(sa.String(200))
    passed: Mapped[bool | None] = mapped_column()
    matrix: Mapped[Any] = mapped_column(sa.JSON)
    metrics: Mapped[Any] = mapped_column(sa.JSON)
    certificate_path: Mapped[str | None] = mapped_column(sa.Text)
    #: The certificate's sha256 (attached with the record or later, once).
    certificate_sha256: Mapped[str | None] = mapped_column(sa.String(64))
    #: The reference sensor's serial (traceability: which ATI loaded the plate).
    reference_serial: Mapped[str | None] = mapped_column(sa.String(100))
    #: Headline figures on held-out points after the fit (``figures_stage``: ``nonlinear`` when
    #: the record has it, else ``linear``): COP error RMS and max (mm), the worst force axis
    #: (% of full scale, Fx/Fy/Fz).
    cop_rms_mm: Mapped[float | None] = mapped_column()
    cop_max_mm: Mapped[float | None] = mapped_column()
    force_pct_fs: Mapped[float | None] = mapped_column()
    figures_stage: Mapped[str | None] = mapped_column(sa.String(20))
    record: Mapped[dict[str, Any]] = mapped_column(sa.JSON)
    record_sha256: Mapped[str] = mapped_column(sa.String(64))
    added_by: Mapped[str] = mapped_column(sa.String(64))
    added_at: Mapped[dt.datetime] = mapped_column(UTCDateTime())


class AuditEntry(Base):
    """Append-only, hash-chained: ``hash = sha256(prev_hash + canonical row)`` (patients.audit).

    Text columns (not JSON) so the bytes hashed are the bytes stored, on both back ends.
    """

    __tablename__ = "audit_log"

    seq: Mapped[int] = mapped_column(primary_key=True, autoincrement=False)
    at: Mapped[str] = mapped_column(sa.String(40))
    username: Mapped[str | None] = mapped_column(sa.String(64))
    action: Mapped[str] = mapped_column(sa.String(40))
    entity: Mapped[str] = mapped_column(sa.String(40))
    entity_key: Mapped[str | None] = mapped_column(sa.String(80))
    before: Mapped[str | None] = mapped_column(sa.Text)
    after: Mapped[str | None] = mapped_column(sa.Text)
    prev_hash: Mapped[str] = mapped_column(sa.String(64))
    hash: Mapped[str] = mapped_column(sa.String(64))


class AuditHead(Base):
    """One row: the chain's last seq and hash. Locked (FOR UPDATE) by each append, so writers
    on several workstations extend the chain one at a time, never fork it."""

    __tablename__ = "audit_head"

    id: Mapped[int] = mapped_column(primary_key=True, autoincrement=False)
    seq: Mapped[int] = mapped_column()
    hash: Mapped[str] = mapped_column(sa.String(64))
