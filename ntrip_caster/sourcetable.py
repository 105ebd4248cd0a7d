"""The NTRIP sourcetable: STR / CAS / NET records, rendered with CRLF and ENDSOURCETABLE.

Field order follows the NTRIP 2.0 description (ntrip.md). Fields may not contain ';' or line ends;
`render_*` replaces them so a config typo can never corrupt the table a client parses.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

END_OF_TABLE = b"ENDSOURCETABLE\r\n"


def _clean(value: object) -> str:
    text = str(value)
    return text.replace(";", ",").replace("\r", " ").replace("\n", " ")


def _fmt_coord(value: float) -> str:
    return f"{value:.2f}"


@dataclass(frozen=True, slots=True)
class StrRecord:
    """One mountpoint (`STR;...`)."""

    mountpoint: str
    identifier: str = ""
    format: str = "RTCM 3.3"
    format_details: str = ""
    carrier: int = 2  # 0 none, 1 L1, 2 L1+L2 (or more)
    nav_system: str = "GPS+GLO+GAL+BDS"
    network: str = ""
    country: str = ""
    latitude: float = 0.0
    longitude: float = 0.0
    nmea: int = 0  # 1 when the mountpoint needs the client's GGA
    solution: int = 0  # 0 single base, 1 network
    generator: str = "augnet"
    compression: str = "none"
    authentication: str = "N"  # N none, B basic, D digest
    fee: str = "N"
    bitrate: int = 0
    misc: str = ""

    def to_line(self) -> str:
        parts = ["STR"]
        for f in fields(self):
            value = getattr(self, f.name)
            parts.append(_fmt_coord(value) if f.name in ("latitude", "longitude") else _clean(value))
        return ";".join(parts)

    @classmethod
    def from_line(cls, line: str) -> "StrRecord":
        """Parse `STR;...` (extra trailing fields are folded into misc, missing ones defaulted)."""
        parts = line.rstrip("\r\n").split(";")
        if not parts or parts[0] != "STR" or len(parts) < 2:
            raise ValueError(f"not an STR record: {line[:60]!r}")
        names = [f.name for f in fields(cls)]
        values: dict[str, object] = {}
        body = parts[1:]
        if len(body) > len(names):
            body = body[: len(names) - 1] + [";".join(body[len(names) - 1:])]
        for name, raw in zip(names, body):
            kind = cls.__dataclass_fields__[name].type
            if kind in ("int", int):
                values[name] = int(raw) if raw.strip().lstrip("-").isdigit() else 0
            elif kind in ("float", float):
                try:
                    values[name] = float(raw)
                except ValueError:
                    values[name] = 0.0
            else:
                values[name] = raw
        return cls(**values)  # type: ignore[arg-type]


@dataclass(frozen=True, slots=True)
class CasRecord:
    """This caster (`CAS;...`)."""

    host: str
    port: int
    identifier: str = "augnet"
    operator: str = ""
    nmea: int = 0
    country: str = ""
    latitude: float = 0.0
    longitude: float = 0.0
    fallback_host: str = "0.0.0.0"
    fallback_port: int = 0
    misc: str = ""

    def to_line(self) -> str:
        parts = ["CAS"]
        for f in fields(self):
            value = getattr(self, f.name)
            parts.append(_fmt_coord(value) if f.name in ("latitude", "longitude") else _clean(value))
        return ";".join(parts)


@dataclass(frozen=True, slots=True)
class NetRecord:
    """A network of mountpoints (`NET;...`)."""

    identifier: str
    operator: str = ""
    authentication: str = "B"
    fee: str = "N"
    web_net: str = ""
    web_str: str = ""
    web_reg: str = ""
    misc: str = ""

    def to_line(self) -> str:
        return ";".join(["NET"] + [_clean(getattr(self, f.name)) for f in fields(self)])


def render_sourcetable(records: list[StrRecord | CasRecord | NetRecord]) -> bytes:
    """The sourcetable body: one CRLF-terminated record a line, then ENDSOURCETABLE."""
    return "".join(r.to_line() + "\r\n" for r in records).encode("utf-8") + END_OF_TABLE


def parse_sourcetable(body: bytes) -> list[StrRecord]:
    """The STR records of a sourcetable body (other records skipped)."""
    out = []
    for line in body.decode("utf-8", "replace").split("\n"):
        if line.startswith("STR;"):
            out.append(StrRecord.from_line(line))
    return out


def filter_records(records: list, query: str) -> list:
    """NTRIP 2.0 simple filtering (`GET /?STR;;;RTCM 3`): an STR record matches when every non-empty
    field of the query equals (case-insensitively) the same field of the record. CAS/NET records and
    the records of other types are kept only when the query names their type."""
    parts = query.split(";")
    if not parts or parts[0].upper() not in ("STR", "CAS", "NET"):
        return records
    kind = parts[0].upper()
    out = []
    for rec in records:
        line = rec.to_line().split(";")
        if line[0] != kind:
            continue
        if all(not q or (i < len(line) and line[i].lower() == q.lower()) for i, q in enumerate(parts)
               if i > 0):
            out.append(rec)
    return out
