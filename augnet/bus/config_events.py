"""Configuration change events: the console tells every caster node that an operator changed a caster
user or mountpoint in the store (decision 0180), and every centre that a station changed (decision 0240).

An event names what changed, never the new values: the store stays the one source of truth, and no
password hash travels on the bus (JetStream keeps messages on disk for minutes). A node that receives
one re-reads the store; a node that missed one catches up at its next periodic reconcile.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass

from augnet.bus.core import Bus

# The one subject of caster configuration changes (inside JetStream's `augnet.>` stream).
CASTER_CONFIG_SUBJECT = "augnet.config.caster"
# ... and of the station registry (the centre's membership: `augnet.system.station_membership`).
STATIONS_CONFIG_SUBJECT = "augnet.config.stations"
CHANGE_KINDS = ("user", "mountpoint", "station")
MAX_EVENT_BYTES = 1024  # an event is a kind, a name (<= 64 characters in the store) and an action


@dataclass(frozen=True, slots=True)
class CasterChange:
    kind: str  # "user" | "mountpoint" | "station"
    name: str
    action: str  # "add" | "edit" | "delete"

    def encode(self) -> bytes:
        return json.dumps(asdict(self), separators=(",", ":")).encode()


def decode_change(payload: bytes) -> CasterChange:
    """The event in `payload`; ValueError (saying why) for anything else."""
    if len(payload) > MAX_EVENT_BYTES:
        raise ValueError(f"caster change event of {len(payload)} bytes (at most {MAX_EVENT_BYTES})")
    try:
        data = json.loads(payload)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"caster change event is not JSON: {exc}") from exc
    if not isinstance(data, dict) or set(data) != {"kind", "name", "action"} \
            or not all(isinstance(v, str) for v in data.values()):
        raise ValueError("caster change event needs exactly kind, name, action (strings)")
    if data["kind"] not in CHANGE_KINDS:
        raise ValueError(f"caster change event: unknown kind {data['kind']!r}")
    return CasterChange(data["kind"], data["name"], data["action"])


async def publish_change(bus: Bus, change: CasterChange) -> None:
    subject = STATIONS_CONFIG_SUBJECT if change.kind == "station" else CASTER_CONFIG_SUBJECT
    await bus.publish(subject, change.encode())
