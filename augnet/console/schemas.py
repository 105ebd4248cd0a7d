"""Request and response models: the console's contract, published as its OpenAPI document.

Request models forbid unknown fields, so a misspelt field is a 422 that names it rather than a silent no-op.
"""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StringConstraints, field_validator

from augnet.store.models import AlarmState, Role, Severity

# NTRIP mountpoint and station names: letters, digits and - _ . (NTRIP 2.0 allows more, but these survive
# every client, URL and sourcetable we know of).
NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]*$"
RTCM_STATION_ID_MAX = 4095  # DF003 is 12 bits
MIN_PASSWORD_CHARS = 8
MAX_PASSWORD_CHARS = 256
# Ellipsoidal heights of land stations: Dead Sea shore (-430 m) to high passes (~5,100 m on the Qinghai-Tibet
# line), with margin.
MIN_HEIGHT_M = -1_000.0
MAX_HEIGHT_M = 9_000.0

Code = Annotated[str, StringConstraints(min_length=1, max_length=32, pattern=NAME_PATTERN)]
MountName = Annotated[str, StringConstraints(min_length=1, max_length=64, pattern=NAME_PATTERN)]
UserName = Annotated[str, StringConstraints(min_length=1, max_length=64, pattern=NAME_PATTERN)]
Password = Annotated[str, StringConstraints(min_length=MIN_PASSWORD_CHARS, max_length=MAX_PASSWORD_CHARS)]
Groups = Annotated[str, StringConstraints(max_length=256, pattern=r"^[A-Za-z0-9_.*,-]*$")]
Latitude = Annotated[float, Field(ge=-90.0, le=90.0, allow_inf_nan=False)]
Longitude = Annotated[float, Field(ge=-180.0, le=180.0, allow_inf_nan=False)]
Height = Annotated[float, Field(ge=MIN_HEIGHT_M, le=MAX_HEIGHT_M, allow_inf_nan=False)]
RtcmStationId = Annotated[int, Field(ge=0, le=RTCM_STATION_ID_MAX)]


class Request(BaseModel):
    model_config = ConfigDict(extra="forbid")

    @field_validator("*", mode="after")
    @classmethod
    def no_nul(cls, value: Any) -> Any:
        """PostgreSQL text cannot hold NUL; refuse it here, naming the field, on every backend alike."""
        if isinstance(value, str) and "\x00" in value:
            raise ValueError("must not contain the NUL character")
        return value


# --- auth and operators -----------------------------------------------------------------------------

class LoginIn(Request):
    name: Annotated[str, StringConstraints(min_length=1, max_length=64)]
    password: Annotated[str, StringConstraints(min_length=1, max_length=MAX_PASSWORD_CHARS)]


class TokenOut(BaseModel):
    token: str
    token_type: Literal["bearer"] = "bearer"
    name: str
    role: Role
    expires_at: dt.datetime | None


class OperatorOut(BaseModel):
    name: str
    role: Role
    enabled: bool


class OperatorIn(Request):
    name: UserName
    password: Password
    role: Role


class OperatorPatch(Request):
    role: Role | None = None
    enabled: bool | None = None
    password: Password | None = None


# --- stations -----------------------------------------------------------------------------------------

class StationIn(Request):
    code: Code
    name: Annotated[str, StringConstraints(max_length=128)] = ""
    lat_deg: Latitude
    lon_deg: Longitude
    h_m: Height
    rtcm_station_id: RtcmStationId
    mountpoint: MountName


class StationPatch(Request):
    name: Annotated[str, StringConstraints(max_length=128)] | None = None
    lat_deg: Latitude | None = None
    lon_deg: Longitude | None = None
    h_m: Height | None = None
    rtcm_station_id: RtcmStationId | None = None
    mountpoint: MountName | None = None
    enabled: bool | None = None


class StationLiveOut(BaseModel):
    up: bool
    last_data_age_s: float | None
    satellites: int


class StationOut(BaseModel):
    code: str
    name: str
    lat_deg: float
    lon_deg: float
    h_m: float
    x_m: float | None
    y_m: float | None
    z_m: float | None
    rtcm_station_id: int
    mountpoint: str | None
    enabled: bool
    along_km: float | None
    in_store: bool  # False: reported by the running system but not (yet) registered in the store
    live: StationLiveOut | None


# --- network -------------------------------------------------------------------------------------------

class BaselineOut(BaseModel):
    a: str
    b: str
    length_km: float
    state: Literal["fixed", "float", "none"]
    fixed_fraction: float
    residual_rms_cm: float | None


class NetworkOut(BaseModel):
    running: bool  # a live system feeds this console
    summary: dict[str, Any]
    stations_total: int
    stations_up: int
    baselines: list[BaselineOut]
    baselines_by_state: dict[str, int]


class LineOut(BaseModel):
    id: str | None = None
    length_km: float | None = None
    polyline: list[list[float]] = []


# --- trains --------------------------------------------------------------------------------------------

class TrainOut(BaseModel):
    id: str
    lat_deg: float | None
    lon_deg: float | None
    h_m: float | None
    track_id: str | None
    along_km: float | None
    cross_track_m: float | None
    fix_state: Literal["fix", "float", "dgps", "single", "none"]
    correction_age_s: float | None
    hpl_m: float | None
    vpl_m: float | None
    speed_kmh: float | None
    updated_unix: float
    age_s: float  # since the last update


class TrainSessionOut(BaseModel):
    mountpoint: str
    started_at: dt.datetime
    ended_at: dt.datetime | None
    bytes_sent: int
    fix_rate: float | None


class TrainDetailOut(BaseModel):
    id: str
    live: TrainOut | None
    registered: bool
    length_m: float | None
    sessions: list[TrainSessionOut]


# --- alarms --------------------------------------------------------------------------------------------

class AlarmOut(BaseModel):
    id: int
    kind: str
    subject: str
    severity: Severity
    message: str
    state: AlarmState
    raised_at: dt.datetime
    acknowledged_at: dt.datetime | None
    acknowledged_by: str | None
    cleared_at: dt.datetime | None


# --- caster --------------------------------------------------------------------------------------------

class MountpointIn(Request):
    name: MountName
    kind: Literal["source", "vrs", "nearest"]
    format: Annotated[str, StringConstraints(min_length=1, max_length=32)] = "RTCM 3.3"
    read_groups: Groups = ""
    write_groups: Groups = ""
    correction_bound: bool = False  # its VRS streams carry the RTCM 4001 correction-error bound (decision 0281)


class MountpointPatch(Request):
    kind: Literal["source", "vrs", "nearest"] | None = None
    format: Annotated[str, StringConstraints(min_length=1, max_length=32)] | None = None
    read_groups: Groups | None = None
    write_groups: Groups | None = None
    enabled: bool | None = None
    correction_bound: bool | None = None


class MountpointOut(BaseModel):
    name: str
    kind: str
    format: str | None
    read_groups: str | None
    write_groups: str | None
    enabled: bool
    correction_bound: bool | None  # None: not in the store
    in_store: bool
    stats: dict[str, Any] | None  # the running caster's counters for it (None: caster not running here)


class CasterUserIn(Request):
    name: UserName
    password: Password
    groups: Groups = ""


class CasterUserPatch(Request):
    password: Password | None = None
    groups: Groups | None = None
    enabled: bool | None = None


class CasterUserOut(BaseModel):
    name: str
    groups: str
    enabled: bool
    connected_clients: int  # sessions of this user in the running caster now


class CasterOut(BaseModel):
    running: bool
    started_at: float | None = None
    port: int | None = None
    clients_now: int = 0
    connections_now: int = 0
    counters: dict[str, Any] = {}
    mountpoints_live: int = 0


# --- history -------------------------------------------------------------------------------------------

class QualityOut(BaseModel):
    at: dt.datetime
    subject: str
    fixed_fraction: float
    residual_rms_m: float | None
    satellites: int


class AuditOut(BaseModel):
    id: int
    at: dt.datetime
    actor: str
    action: str
    target: str
    detail: dict[str, Any]
