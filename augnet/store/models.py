"""The operator's store: SQLAlchemy 2 models (SQLite by default, PostgreSQL by URL).

Tables: reference stations, caster mountpoints and users, trains and their sessions, alarms with their
life cycle (raised -> acknowledged -> cleared), operator accounts with roles and API tokens, an audit log of
every operator action, and the network quality history. Passwords and tokens are stored only as hashes.
Times are timezone-aware UTC.
"""

from __future__ import annotations

import datetime as dt
import enum

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    Enum,
    Float,
    ForeignKey,
    Index,
    Integer,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.sql.expression import false
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship


def utcnow() -> dt.datetime:
    return dt.datetime.now(dt.timezone.utc)


class Base(DeclarativeBase):
    type_annotation_map = {dt.datetime: DateTime(timezone=True), dict: JSON}


class Role(str, enum.Enum):
    VIEWER = "viewer"  # reads everything
    OPERATOR = "operator"  # also acknowledges alarms, enables / disables stations
    ADMIN = "admin"  # also manages accounts, caster users, mountpoints and stations


class AlarmState(str, enum.Enum):
    RAISED = "raised"
    ACKNOWLEDGED = "acknowledged"
    CLEARED = "cleared"


class Severity(str, enum.Enum):
    INFO = "info"
    WARNING = "warning"
    CRITICAL = "critical"


class Station(Base):
    __tablename__ = "stations"
    id: Mapped[int] = mapped_column(primary_key=True)
    code: Mapped[str] = mapped_column(String(32), unique=True)  # e.g. "STA1"
    name: Mapped[str] = mapped_column(String(128), default="")
    x_m: Mapped[float] = mapped_column(Float)  # ECEF ARP, surveyed
    y_m: Mapped[float] = mapped_column(Float)
    z_m: Mapped[float] = mapped_column(Float)
    rtcm_station_id: Mapped[int] = mapped_column(Integer)  # DF003, 0..4095
    mountpoint: Mapped[str] = mapped_column(String(64))
    enabled: Mapped[bool] = mapped_column(Boolean, default=True)
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[dt.datetime] = mapped_column(default=utcnow, onupdate=utcnow)


class Mountpoint(Base):
    __tablename__ = "mountpoints"
    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    kind: Mapped[str] = mapped_column(String(16))  # source | vrs | nearest
    format: Mapped[str] = mapped_column(String(32), default="RTCM 3.3")
    read_groups: Mapped[str] = mapped_column(String(256), default="")  # comma separated; "*" = public
    write_groups: Mapped[str] = mapped_column(String(256), default="")
    enabled: Mapped[bool] = mapped_column(Boolean, default=True)
    # a VRS mountpoint's streams carry the centre's correction-error bound (RTCM 4001, decision 0280/0281):
    # opt-in, off by default, so a stream without it is byte for byte what it was
    correction_bound: Mapped[bool] = mapped_column(Boolean, default=False, server_default=false())


class CasterUser(Base):
    __tablename__ = "caster_users"
    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    password_hash: Mapped[str] = mapped_column(String(256))  # scrypt$... (augwire.passwords format)
    groups: Mapped[str] = mapped_column(String(256), default="")
    enabled: Mapped[bool] = mapped_column(Boolean, default=True)


class Train(Base):
    __tablename__ = "trains"
    id: Mapped[int] = mapped_column(primary_key=True)
    code: Mapped[str] = mapped_column(String(32), unique=True)
    length_m: Mapped[float] = mapped_column(Float, default=200.0)
    sessions: Mapped[list[TrainSession]] = relationship(back_populates="train", cascade="all, delete-orphan")


class TrainSession(Base):
    """One connection of a train to the correction service (NTRIP session)."""

    __tablename__ = "train_sessions"
    id: Mapped[int] = mapped_column(primary_key=True)
    train_id: Mapped[int] = mapped_column(ForeignKey("trains.id", ondelete="CASCADE"))
    mountpoint: Mapped[str] = mapped_column(String(64))
    started_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    ended_at: Mapped[dt.datetime | None] = mapped_column(default=None)
    bytes_sent: Mapped[int] = mapped_column(Integer, default=0)
    fix_rate: Mapped[float | None] = mapped_column(Float, default=None)
    train: Mapped[Train] = relationship(back_populates="sessions")


class Alarm(Base):
    __tablename__ = "alarms"
    id: Mapped[int] = mapped_column(primary_key=True)
    kind: Mapped[str] = mapped_column(String(64))  # e.g. satellite-excluded, station-down
    subject: Mapped[str] = mapped_column(String(64))  # what it is about: "G12", "STA3", "section 4"
    severity: Mapped[Severity] = mapped_column(Enum(Severity, native_enum=False, length=16))
    message: Mapped[str] = mapped_column(Text, default="")
    state: Mapped[AlarmState] = mapped_column(Enum(AlarmState, native_enum=False, length=16),
                                              default=AlarmState.RAISED)
    raised_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    acknowledged_at: Mapped[dt.datetime | None] = mapped_column(default=None)
    acknowledged_by: Mapped[str | None] = mapped_column(String(64), default=None)
    cleared_at: Mapped[dt.datetime | None] = mapped_column(default=None)
    __table_args__ = (Index("ix_alarms_state_raised", "state", "raised_at"),)


class Operator(Base):
    __tablename__ = "operators"
    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    password_hash: Mapped[str] = mapped_column(String(256))
    role: Mapped[Role] = mapped_column(Enum(Role, native_enum=False, length=16))
    enabled: Mapped[bool] = mapped_column(Boolean, default=True)
    tokens: Mapped[list[ApiToken]] = relationship(back_populates="operator", cascade="all, delete-orphan")


class ApiToken(Base):
    __tablename__ = "api_tokens"
    id: Mapped[int] = mapped_column(primary_key=True)
    operator_id: Mapped[int] = mapped_column(ForeignKey("operators.id", ondelete="CASCADE"))
    token_sha256: Mapped[str] = mapped_column(String(64), unique=True)  # tokens are random, so SHA-256 is enough
    created_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    expires_at: Mapped[dt.datetime | None] = mapped_column(default=None)
    # "session" (login, CLI), or "bootstrap": the one long-lived token per store that `augnet up` writes to its
    # state file; logout does not revoke it, `augnet console token --rotate` replaces it
    kind: Mapped[str] = mapped_column(String(16), default="session", server_default="session")
    operator: Mapped[Operator] = relationship(back_populates="tokens")


class AuditEntry(Base):
    __tablename__ = "audit_log"
    id: Mapped[int] = mapped_column(primary_key=True)
    at: Mapped[dt.datetime] = mapped_column(default=utcnow, index=True)
    actor: Mapped[str] = mapped_column(String(64))
    action: Mapped[str] = mapped_column(String(64))  # e.g. alarm.acknowledge, station.disable
    target: Mapped[str] = mapped_column(String(128))
    detail: Mapped[dict] = mapped_column(default=dict)


class QualitySample(Base):
    """Network quality over time: one row per baseline (or station) and period."""

    __tablename__ = "quality_history"
    id: Mapped[int] = mapped_column(primary_key=True)
    at: Mapped[dt.datetime] = mapped_column(index=True)
    subject: Mapped[str] = mapped_column(String(64))  # "STA1-STA2" for a baseline, "STA1" for a station
    fixed_fraction: Mapped[float] = mapped_column(Float)  # fraction of DD ambiguities fixed
    residual_rms_m: Mapped[float | None] = mapped_column(Float, default=None)
    satellites: Mapped[int] = mapped_column(Integer, default=0)
    __table_args__ = (UniqueConstraint("at", "subject", name="uq_quality_at_subject"),)


class SectionTrain(Base):
    """The section register's picture (augnet.system.section_register): one row per train in a line section,
    `position` 0 the front (nearest the section's exit) in its direction. Rewritten per section and direction
    when the running system's register changes; the console reads it when no system runs in its process."""

    __tablename__ = "section_trains"
    id: Mapped[int] = mapped_column(primary_key=True)
    section_id: Mapped[int] = mapped_column(Integer)
    direction: Mapped[str] = mapped_column(String(8))  # up / down
    position: Mapped[int] = mapped_column(Integer)
    train_code: Mapped[str] = mapped_column(String(32), unique=True)  # a train is in one place
    track: Mapped[str] = mapped_column(String(32), default="")
    km: Mapped[float] = mapped_column(Float)
    speed_m_s: Mapped[float] = mapped_column(Float)
    length_m: Mapped[float] = mapped_column(Float)
    integrity: Mapped[str] = mapped_column(String(16))
    correction_age_s: Mapped[float | None] = mapped_column(Float, default=None)
    along_pl_m: Mapped[float | None] = mapped_column(Float, default=None)
    cross_pl_m: Mapped[float | None] = mapped_column(Float, default=None)
    hpl_m: Mapped[float | None] = mapped_column(Float, default=None)
    report_time_s: Mapped[float] = mapped_column(Float, default=0.0)  # GPS time of the train's report
    updated_at: Mapped[dt.datetime] = mapped_column(default=utcnow)
    __table_args__ = (UniqueConstraint("section_id", "direction", "position", name="uq_section_trains_place"),)
