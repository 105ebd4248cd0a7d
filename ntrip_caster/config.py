"""Caster configuration: a TOML or YAML file, overridable from the command line.

    [caster]
    host = "127.0.0.1"          # bind address
    port = 2101
    identifier = "augnet"       # CAS record
    operator = "Railway GNSS"
    country = "CHN"
    admin_group = "admin"       # its users may GET /_stats (JSON statistics); "" disables it

    [limits]                    # any name of limits.py in lower case, e.g.
    max_clients = 20000
    max_clients_per_ip = 0
    max_client_backlog_bytes = 16384
    request_head_timeout_s = 10
    source_idle_timeout_s = 60

    [users.train0001]
    password_hash = "scrypt$14$8$...$..."    # `ntrip-caster hash-password`
    groups = ["trains"]

    [[mountpoints]]
    name = "BASE01"
    kind = "source"             # source | vrs | nearest
    read = ["trains"]           # groups that may read; ["*"] = anyone, no credentials
    write = ["stations"]        # groups whose users may publish (source mountpoints)
    latitude = 31.2
    longitude = 121.4
    # any other STR field: identifier, format, format_details, carrier, nav_system, network,
    # country, generator, bitrate, misc
    # vrs: factory = "package.module:attribute" (a StreamFactory), nmea is implied
    # nearest: bases = ["BASE01", "BASE02"] (default: every source mountpoint with a position)
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import yaml

from . import limits as L
from .auth import PUBLIC, User
from .sourcetable import StrRecord

MOUNT_KINDS = ("source", "vrs", "nearest")
_STR_FIELDS = {f.name for f in fields(StrRecord)} - {"mountpoint", "nmea", "solution", "authentication"}


class ConfigError(ValueError):
    """The configuration file or an option is invalid (message says where)."""


@dataclass(frozen=True, slots=True)
class Limits:
    max_request_head_bytes: int = L.MAX_REQUEST_HEAD_BYTES
    request_head_timeout_s: float = L.REQUEST_HEAD_TIMEOUT_S
    source_idle_timeout_s: float = L.SOURCE_IDLE_TIMEOUT_S
    max_source_chunk_bytes: int = L.MAX_SOURCE_CHUNK_BYTES
    max_client_backlog_bytes: int = L.MAX_CLIENT_BACKLOG_BYTES
    client_send_buffer_bytes: int = L.CLIENT_SEND_BUFFER_BYTES
    max_client_upload_bytes_per_s: int = L.MAX_CLIENT_UPLOAD_BYTES_PER_S
    max_clients: int = L.MAX_CLIENTS
    max_clients_per_mount: int = L.MAX_CLIENTS_PER_MOUNT
    max_clients_per_ip: int = L.MAX_CLIENTS_PER_IP
    max_pending_per_ip: int = L.MAX_PENDING_PER_IP
    auth_workers: int = L.AUTH_WORKERS
    auth_queue_max: int = L.AUTH_QUEUE_MAX
    gga_min_interval_s: float = L.GGA_MIN_INTERVAL_S
    reposition_min_interval_s: float = L.REPOSITION_MIN_INTERVAL_S
    reposition_max_interval_s: float = L.REPOSITION_MAX_INTERVAL_S
    reposition_min_move_m: float = L.REPOSITION_MIN_MOVE_M
    base_switch_hysteresis_m: float = L.BASE_SWITCH_HYSTERESIS_M
    shutdown_drain_s: float = L.SHUTDOWN_DRAIN_S
    max_auto_mounts: int = L.MAX_AUTO_MOUNTS


@dataclass(frozen=True, slots=True)
class MountConfig:
    name: str
    kind: str = "source"
    read: frozenset[str] = frozenset({PUBLIC})
    write: frozenset[str] = frozenset()
    str_fields: dict[str, Any] = field(default_factory=dict)
    factory: str | None = None  # vrs: "module:attribute"
    bases: tuple[str, ...] = ()  # nearest: candidate source mountpoints (empty = all)
    enabled: bool = True  # a disabled mountpoint is left out of the sourcetable and serves no reader

    def str_record(self) -> StrRecord:
        return StrRecord(
            mountpoint=self.name,
            nmea=0 if self.kind == "source" else 1,
            solution=1 if self.kind == "vrs" else 0,
            authentication="N" if PUBLIC in self.read else "B",
            **self.str_fields,
        )


@dataclass(frozen=True, slots=True)
class CasterConfig:
    host: str = "127.0.0.1"
    port: int = 2101
    identifier: str = "augnet"
    operator: str = ""
    country: str = ""
    realm: str = "augnet"
    # Users of this group may read `GET /_stats` (JSON statistics); empty disables the endpoint.
    admin_group: str = "admin"
    limits: Limits = Limits()
    users: dict[str, User] = field(default_factory=dict)
    mounts: tuple[MountConfig, ...] = ()
    # Accept a v1 SOURCE / v2 POST for a mountpoint not in the config (open test casters do; a
    # production caster should not). Such mountpoints are public to read.
    allow_unknown_sources: bool = False
    stats_path: str | None = None  # write a JSON stats snapshot here every stats_interval_s
    stats_interval_s: float = 5.0


def _groups(value: Any, where: str) -> frozenset[str]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ConfigError(f"{where}: expected a list of group names")
    return frozenset(value)


def config_from_dict(data: dict[str, Any]) -> CasterConfig:
    """Validate a parsed TOML/YAML document into a CasterConfig (ConfigError says what is wrong)."""
    if not isinstance(data, dict):
        raise ConfigError("configuration must be a mapping")
    unknown = set(data) - {"caster", "limits", "users", "mountpoints"}
    if unknown:
        raise ConfigError(f"unknown top-level sections: {sorted(unknown)}")
    caster = dict(data.get("caster") or {})
    known = {"host", "port", "identifier", "operator", "country", "realm", "allow_unknown_sources",
             "stats_path", "stats_interval_s", "admin_group"}
    if set(caster) - known:
        raise ConfigError(f"[caster]: unknown keys {sorted(set(caster) - known)}")

    lim_data = dict(data.get("limits") or {})
    lim_names = {f.name for f in fields(Limits)}
    if set(lim_data) - lim_names:
        raise ConfigError(f"[limits]: unknown keys {sorted(set(lim_data) - lim_names)}")
    for k, v in lim_data.items():
        if not isinstance(v, (int, float)) or isinstance(v, bool) or v < 0:
            raise ConfigError(f"[limits] {k}: expected a non-negative number, got {v!r}")
    limits = replace(Limits(), **lim_data)

    users: dict[str, User] = {}
    for name, u in (data.get("users") or {}).items():
        if not isinstance(u, dict) or not isinstance(u.get("password_hash"), str):
            raise ConfigError(f"[users.{name}]: needs password_hash (ntrip-caster hash-password)")
        if not u["password_hash"].startswith("scrypt$"):
            raise ConfigError(f"[users.{name}]: password_hash must be an scrypt hash, not a password")
        users[str(name)] = User(str(name), u["password_hash"], _groups(u.get("groups", []),
                                                                      f"[users.{name}] groups"))

    mounts: list[MountConfig] = []
    seen: set[str] = set()
    for i, m in enumerate(data.get("mountpoints") or []):
        where = f"mountpoints[{i}]"
        if not isinstance(m, dict) or not isinstance(m.get("name"), str) or not m["name"]:
            raise ConfigError(f"{where}: needs a name")
        m = dict(m)
        name = m.pop("name")
        if name in seen:
            raise ConfigError(f"{where}: mountpoint {name!r} defined twice")
        if name == "_stats":
            raise ConfigError(f"{where}: '_stats' is the statistics path, not a mountpoint name")
        seen.add(name)
        kind = m.pop("kind", "source")
        if kind not in MOUNT_KINDS:
            raise ConfigError(f"{where}: kind must be one of {MOUNT_KINDS}")
        read = _groups(m.pop("read", [PUBLIC]), f"{where} read")
        write = _groups(m.pop("write", []), f"{where} write")
        factory = m.pop("factory", None)
        if kind == "vrs" and not factory:
            raise ConfigError(f"{where}: a vrs mountpoint needs factory = 'module:attribute'")
        bases = tuple(m.pop("bases", ()))
        bad = set(m) - _STR_FIELDS
        if bad:
            raise ConfigError(f"{where}: unknown keys {sorted(bad)}")
        mounts.append(MountConfig(name, kind, read, write, m, factory, bases))

    try:
        return CasterConfig(
            host=str(caster.get("host", "127.0.0.1")), port=int(caster.get("port", 2101)),
            identifier=str(caster.get("identifier", "augnet")),
            operator=str(caster.get("operator", "")), country=str(caster.get("country", "")),
            realm=str(caster.get("realm", "augnet")),
            admin_group=str(caster.get("admin_group", "admin")),
            limits=limits, users=users, mounts=tuple(mounts),
            allow_unknown_sources=bool(caster.get("allow_unknown_sources", False)),
            stats_path=caster.get("stats_path"),
            stats_interval_s=float(caster.get("stats_interval_s", 5.0)),
        )
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"[caster]: {exc}") from exc


def load_config(path: str | Path) -> CasterConfig:
    """Read a .toml, .yaml or .yml file."""
    path = Path(path)
    try:
        text = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"cannot read {path}: {exc}") from exc
    try:
        if path.suffix.lower() == ".toml":
            data = tomllib.loads(text.decode("utf-8"))
        elif path.suffix.lower() in (".yaml", ".yml"):
            data = yaml.safe_load(text) or {}
        else:
            raise ConfigError(f"{path}: use a .toml, .yaml or .yml file")
    except (tomllib.TOMLDecodeError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: {exc}") from exc
    return config_from_dict(data)
