"""What the services and the console do with the store. Every operator change writes an audit entry in the
same transaction as the change, so the log cannot miss one."""

from __future__ import annotations

import datetime as dt
import hashlib
import secrets

from sqlalchemy import delete, func, select
from sqlalchemy.orm import Session

from augnet.store.models import (
    Alarm,
    AlarmState,
    ApiToken,
    AuditEntry,
    CasterUser,
    Mountpoint,
    Operator,
    QualitySample,
    Role,
    SectionTrain,
    Severity,
    Station,
    Train,
    TrainSession,
    utcnow,
)

TOKEN_BYTES = 32  # 256-bit random API tokens
TOKEN_SESSION, TOKEN_BOOTSTRAP = "session", "bootstrap"  # ApiToken.kind
ROLE_RANK = {Role.VIEWER: 0, Role.OPERATOR: 1, Role.ADMIN: 2}


class NotFound(LookupError):
    pass


class Conflict(ValueError):
    pass


def audit(session: Session, actor: str, action: str, target: str, **detail) -> AuditEntry:
    entry = AuditEntry(actor=actor, action=action, target=target, detail=detail)
    session.add(entry)
    return entry


# --- stations ---------------------------------------------------------------------------------------

def add_station(session: Session, actor: str, code: str, xyz_m: tuple[float, float, float],
                rtcm_station_id: int, mountpoint: str, name: str = "") -> Station:
    if session.scalar(select(Station).where(Station.code == code)) is not None:
        raise Conflict(f"station {code} exists")
    st = Station(code=code, name=name, x_m=xyz_m[0], y_m=xyz_m[1], z_m=xyz_m[2],
                 rtcm_station_id=rtcm_station_id, mountpoint=mountpoint)
    session.add(st)
    audit(session, actor, "station.add", code, xyz_m=list(xyz_m), mountpoint=mountpoint)
    return st


def get_station(session: Session, code: str) -> Station:
    st = session.scalar(select(Station).where(Station.code == code))
    if st is None:
        raise NotFound(f"no station {code}")
    return st


def update_station(session: Session, actor: str, code: str, **changes) -> Station:
    st = get_station(session, code)
    allowed = {"name", "x_m", "y_m", "z_m", "rtcm_station_id", "mountpoint", "enabled"}
    unknown = set(changes) - allowed
    if unknown:
        raise ValueError(f"cannot change {sorted(unknown)} of a station")
    before = {k: getattr(st, k) for k in changes}
    for k, v in changes.items():
        setattr(st, k, v)
    action = "station.edit"
    if set(changes) == {"enabled"}:
        action = "station.enable" if changes["enabled"] else "station.disable"
    audit(session, actor, action, code, before=before, after=changes)
    return st


def list_stations(session: Session) -> list[Station]:
    return list(session.scalars(select(Station).order_by(Station.code)))


def delete_station(session: Session, actor: str, code: str) -> None:
    """The station leaves the registry (and so the running network: `augnet.system.station_membership`)."""
    st = get_station(session, code)
    audit(session, actor, "station.delete", code, xyz_m=[st.x_m, st.y_m, st.z_m], mountpoint=st.mountpoint,
          rtcm_station_id=st.rtcm_station_id)
    session.delete(st)


# --- alarms -----------------------------------------------------------------------------------------

def raise_alarm(session: Session, kind: str, subject: str, severity: Severity, message: str = "") -> Alarm:
    """Raise an alarm, or return the one already open for the same kind and subject (no duplicates while
    a condition persists)."""
    open_alarm = session.scalar(select(Alarm).where(Alarm.kind == kind, Alarm.subject == subject,
                                                    Alarm.state != AlarmState.CLEARED))
    if open_alarm is not None:
        return open_alarm
    alarm = Alarm(kind=kind, subject=subject, severity=severity, message=message)
    session.add(alarm)
    return alarm


def clear_alarm(session: Session, kind: str, subject: str) -> Alarm | None:
    alarm = session.scalar(select(Alarm).where(Alarm.kind == kind, Alarm.subject == subject,
                                               Alarm.state != AlarmState.CLEARED))
    if alarm is not None:
        alarm.state = AlarmState.CLEARED
        alarm.cleared_at = utcnow()
    return alarm


def acknowledge_alarm(session: Session, actor: str, alarm_id: int) -> Alarm:
    alarm = session.get(Alarm, alarm_id)
    if alarm is None:
        raise NotFound(f"no alarm {alarm_id}")
    if alarm.state is AlarmState.RAISED:
        alarm.state = AlarmState.ACKNOWLEDGED
        alarm.acknowledged_at = utcnow()
        alarm.acknowledged_by = actor
        audit(session, actor, "alarm.acknowledge", f"alarm:{alarm_id}", kind=alarm.kind, subject=alarm.subject)
    return alarm


def list_alarms(session: Session, include_cleared: bool = False, limit: int = 200) -> list[Alarm]:
    q = select(Alarm).order_by(Alarm.raised_at.desc(), Alarm.id.desc()).limit(limit)
    if not include_cleared:
        q = q.where(Alarm.state != AlarmState.CLEARED)
    return list(session.scalars(q))


# --- operators and tokens ---------------------------------------------------------------------------

def add_operator(session: Session, actor: str, name: str, password_hash: str, role: Role) -> Operator:
    if session.scalar(select(Operator).where(Operator.name == name)) is not None:
        raise Conflict(f"operator {name} exists")
    op = Operator(name=name, password_hash=password_hash, role=role)
    session.add(op)
    audit(session, actor, "operator.add", name, role=role.value)
    return op


def _digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def issue_token(session: Session, operator: Operator, lifetime: dt.timedelta | None = None,
                kind: str = TOKEN_SESSION) -> str:
    """A new random API token for the operator; only its SHA-256 is stored."""
    token = secrets.token_urlsafe(TOKEN_BYTES)
    expires = utcnow() + lifetime if lifetime else None
    session.add(ApiToken(operator=operator, token_sha256=_digest(token), expires_at=expires, kind=kind))
    return token


def token_row(session: Session, token: str) -> ApiToken | None:
    return session.scalar(select(ApiToken).where(ApiToken.token_sha256 == _digest(token)))


def is_bootstrap_token(session: Session, token: str | None) -> bool:
    """Whether `token` is this store's bootstrap token (and its operator still enabled)."""
    if not token:
        return False
    row = session.scalar(select(ApiToken).where(ApiToken.token_sha256 == _digest(token)))
    return row is not None and row.kind == TOKEN_BOOTSTRAP and row.operator.enabled


def rotate_bootstrap_token(session: Session, actor: str, operator: Operator, reason: str = "rotate") -> str:
    """Replace the store's one bootstrap token (whoever held it) with a new one for `operator`; never expires."""
    revoked = session.execute(delete(ApiToken).where(ApiToken.kind == TOKEN_BOOTSTRAP)).rowcount
    token = issue_token(session, operator, None, kind=TOKEN_BOOTSTRAP)
    audit(session, actor, "token.rotate", operator.name, kind=TOKEN_BOOTSTRAP, reason=reason, revoked=revoked)
    return token


def operator_for_token(session: Session, token: str) -> Operator | None:
    row = session.scalar(select(ApiToken).where(ApiToken.token_sha256 == _digest(token)))
    if row is None or not row.operator.enabled:
        return None
    if row.expires_at is not None:
        expires = row.expires_at if row.expires_at.tzinfo else row.expires_at.replace(tzinfo=dt.timezone.utc)
        if expires <= utcnow():
            return None
    return row.operator


def has_role(operator: Operator, needed: Role) -> bool:
    return ROLE_RANK[operator.role] >= ROLE_RANK[needed]


# --- quality history --------------------------------------------------------------------------------

def record_quality(session: Session, at: dt.datetime, subject: str, fixed_fraction: float,
                   residual_rms_m: float | None, satellites: int) -> QualitySample:
    sample = QualitySample(at=at, subject=subject, fixed_fraction=fixed_fraction,
                           residual_rms_m=residual_rms_m, satellites=satellites)
    session.add(sample)
    return sample


def quality_history(session: Session, subject: str | None = None, since: dt.datetime | None = None,
                    limit: int = 10_000) -> list[QualitySample]:
    q = select(QualitySample).order_by(QualitySample.at).limit(limit)
    if subject:
        q = q.where(QualitySample.subject == subject)
    if since:
        q = q.where(QualitySample.at >= since)
    return list(session.scalars(q))


def quality_rows(session: Session, subject: str | None = None, since: dt.datetime | None = None,
                 limit: int = 10_000) -> list[tuple[dt.datetime, str, float, float | None, int]]:
    """quality_history as plain (at, subject, fixed_fraction, residual_rms_m, satellites) rows: no ORM objects,
    for the console's polled history route."""
    q = select(QualitySample.at, QualitySample.subject, QualitySample.fixed_fraction, QualitySample.residual_rms_m,
               QualitySample.satellites).order_by(QualitySample.at).limit(limit)
    if subject:
        q = q.where(QualitySample.subject == subject)
    if since:
        q = q.where(QualitySample.at >= since)
    return [tuple(r) for r in session.execute(q)]


def audit_log(session: Session, limit: int = 200) -> list[AuditEntry]:
    return list(session.scalars(select(AuditEntry).order_by(AuditEntry.id.desc()).limit(limit)))


# --- console: alarms, operators, tokens -------------------------------------------------------------

def get_alarm(session: Session, alarm_id: int) -> Alarm:
    alarm = session.get(Alarm, alarm_id)
    if alarm is None:
        raise NotFound(f"no alarm {alarm_id}")
    return alarm


def open_alarm_counts(session: Session) -> dict[tuple[str, str], int]:
    """Alarms not cleared, counted by (state, severity)."""
    rows = session.execute(select(Alarm.state, Alarm.severity, func.count()).where(
        Alarm.state != AlarmState.CLEARED).group_by(Alarm.state, Alarm.severity))
    return {(state.value, sev.value): n for state, sev, n in rows}


def operator_count(session: Session) -> int:
    return session.scalar(select(func.count()).select_from(Operator)) or 0


def get_operator(session: Session, name: str) -> Operator:
    op = session.scalar(select(Operator).where(Operator.name == name))
    if op is None:
        raise NotFound(f"no operator {name}")
    return op


def list_operators(session: Session) -> list[Operator]:
    return list(session.scalars(select(Operator).order_by(Operator.name)))


def update_operator(session: Session, actor: str, name: str, *, role: Role | None = None,
                    enabled: bool | None = None, password_hash: str | None = None) -> Operator:
    """Change an operator's role, enabled flag or password. Disabling or a new password revokes every
    token the operator holds."""
    op = get_operator(session, name)
    detail: dict = {}
    if role is not None and role is not op.role:
        detail["role"] = {"before": op.role.value, "after": role.value}
        op.role = role
    if enabled is not None and enabled != op.enabled:
        detail["enabled"] = {"before": op.enabled, "after": enabled}
        op.enabled = enabled
    if password_hash is not None:
        op.password_hash = password_hash
        detail["password"] = "changed"
    if detail.get("enabled", {}).get("after") is False or password_hash is not None:
        session.execute(delete(ApiToken).where(ApiToken.operator_id == op.id))
        detail["tokens_revoked"] = True
    audit(session, actor, "operator.edit", name, **detail)
    return op


def revoke_token(session: Session, actor: str, token: str) -> bool:
    """Forget one API token (logout). True when it existed. The bootstrap token is not revoked this way
    (Conflict): a page opened with it trades it for a session token, and the CLI rotates it."""
    row = session.scalar(select(ApiToken).where(ApiToken.token_sha256 == _digest(token)))
    if row is None:
        return False
    if row.kind == TOKEN_BOOTSTRAP:
        raise Conflict("the bootstrap token is not revoked by logout: rotate it with `augnet console token --rotate`")
    session.delete(row)
    audit(session, actor, "token.revoke", row.operator.name)
    return True


# --- console: caster users and mountpoints ----------------------------------------------------------

def list_caster_users(session: Session) -> list[CasterUser]:
    return list(session.scalars(select(CasterUser).order_by(CasterUser.name)))


def get_caster_user(session: Session, name: str) -> CasterUser:
    user = session.scalar(select(CasterUser).where(CasterUser.name == name))
    if user is None:
        raise NotFound(f"no caster user {name}")
    return user


def add_caster_user(session: Session, actor: str, name: str, password_hash: str, groups: str = "") -> CasterUser:
    if session.scalar(select(CasterUser).where(CasterUser.name == name)) is not None:
        raise Conflict(f"caster user {name} exists")
    user = CasterUser(name=name, password_hash=password_hash, groups=groups)
    session.add(user)
    audit(session, actor, "caster_user.add", name, groups=groups)
    return user


def update_caster_user(session: Session, actor: str, name: str, *, groups: str | None = None,
                       enabled: bool | None = None, password_hash: str | None = None) -> CasterUser:
    user = get_caster_user(session, name)
    detail: dict = {}
    if groups is not None and groups != user.groups:
        detail["groups"] = {"before": user.groups, "after": groups}
        user.groups = groups
    if enabled is not None and enabled != user.enabled:
        detail["enabled"] = {"before": user.enabled, "after": enabled}
        user.enabled = enabled
    if password_hash is not None:
        user.password_hash = password_hash
        detail["password"] = "changed"
    audit(session, actor, "caster_user.edit", name, **detail)
    return user


def delete_caster_user(session: Session, actor: str, name: str) -> None:
    session.delete(get_caster_user(session, name))
    audit(session, actor, "caster_user.delete", name)


def list_mountpoints(session: Session) -> list[Mountpoint]:
    return list(session.scalars(select(Mountpoint).order_by(Mountpoint.name)))


def get_mountpoint(session: Session, name: str) -> Mountpoint:
    mp = session.scalar(select(Mountpoint).where(Mountpoint.name == name))
    if mp is None:
        raise NotFound(f"no mountpoint {name}")
    return mp


def add_mountpoint(session: Session, actor: str, name: str, kind: str, format: str = "RTCM 3.3",
                   read_groups: str = "", write_groups: str = "", correction_bound: bool = False) -> Mountpoint:
    if session.scalar(select(Mountpoint).where(Mountpoint.name == name)) is not None:
        raise Conflict(f"mountpoint {name} exists")
    mp = Mountpoint(name=name, kind=kind, format=format, read_groups=read_groups, write_groups=write_groups,
                    correction_bound=bool(correction_bound))
    session.add(mp)
    audit(session, actor, "mountpoint.add", name, kind=kind, read_groups=read_groups, write_groups=write_groups,
          correction_bound=bool(correction_bound))
    return mp


def update_mountpoint(session: Session, actor: str, name: str, **changes) -> Mountpoint:
    mp = get_mountpoint(session, name)
    allowed = {"kind", "format", "read_groups", "write_groups", "enabled", "correction_bound"}
    unknown = set(changes) - allowed
    if unknown:
        raise ValueError(f"cannot change {sorted(unknown)} of a mountpoint")
    before = {k: getattr(mp, k) for k in changes}
    for k, v in changes.items():
        setattr(mp, k, v)
    audit(session, actor, "mountpoint.edit", name, before=before, after=changes)
    return mp


def delete_mountpoint(session: Session, actor: str, name: str) -> None:
    """Conflict while a registered station streams to it (delete or re-point the station first)."""
    mp = get_mountpoint(session, name)
    users = [st.code for st in session.scalars(select(Station).where(Station.mountpoint == name))]
    if users:
        raise Conflict(f"mountpoint {name} carries station {', '.join(users)}: delete or re-point the station first")
    session.delete(mp)
    audit(session, actor, "mountpoint.delete", name, kind=mp.kind)


# --- console: trains --------------------------------------------------------------------------------

def list_trains(session: Session) -> list[Train]:
    return list(session.scalars(select(Train).order_by(Train.code)))


def train_sessions(session: Session, code: str, limit: int = 50) -> list[TrainSession]:
    """A train's most recent correction-service sessions, newest first (empty for an unknown train)."""
    return list(session.scalars(select(TrainSession).join(Train).where(Train.code == code)
                                .order_by(TrainSession.started_at.desc(), TrainSession.id.desc()).limit(limit)))


# --- the section register (augnet.system.section_register) ---------------------------------------------

def replace_section_trains(session: Session, section_id: int, direction: str, records: list[dict]) -> None:
    """One section and direction's trains, front first (`TrainRecord` fields as a dict), in place of the
    stored ones; a train stored in another section moved from there (it is in one place)."""
    codes = [r["train_id"] for r in records]
    session.execute(delete(SectionTrain).where(
        (SectionTrain.section_id == section_id) & (SectionTrain.direction == direction)))
    if codes:
        session.execute(delete(SectionTrain).where(SectionTrain.train_code.in_(codes)))
    session.flush()
    for i, r in enumerate(records):
        session.add(SectionTrain(section_id=section_id, direction=direction, position=i, train_code=r["train_id"],
                                 track=r["track"], km=r["km"], speed_m_s=r["speed_m_s"], length_m=r["length_m"],
                                 integrity=r["integrity"], correction_age_s=r["correction_age_s"],
                                 along_pl_m=r["along_pl_m"], cross_pl_m=r["cross_pl_m"], hpl_m=r["hpl_m"],
                                 report_time_s=r["time_s"]))


def section_trains(session: Session) -> dict[tuple[int, str], list[dict]]:
    """The stored register: (section, direction) -> trains front first."""
    out: dict[tuple[int, str], list[dict]] = {}
    rows = session.scalars(select(SectionTrain).order_by(SectionTrain.section_id, SectionTrain.direction,
                                                         SectionTrain.position))
    for r in rows:
        out.setdefault((r.section_id, r.direction), []).append(
            {"train_id": r.train_code, "track": r.track, "km": r.km, "speed_m_s": r.speed_m_s, "length_m": r.length_m,
             "integrity": r.integrity, "correction_age_s": r.correction_age_s, "along_pl_m": r.along_pl_m,
             "cross_pl_m": r.cross_pl_m, "hpl_m": r.hpl_m, "time_s": r.report_time_s})
    return out
