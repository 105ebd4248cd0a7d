"""Per-device identities (SID, SINIT, DATAVER per channel) and the link timing, from configuration.

SID, SINIT and DATAVER are 32-bit per device and per channel, fixed at design time by the signalling
data preparation (rssp1.md): configuration, never protocol constants. SINIT is the sender's timestamp
seed, T(0) = SINIT; every device in the captures seeds with its SID, so SINIT defaults to SID. A
receiver checks the TC_R of every SSR against the peer's SINIT (rssp1.endpoint, "TC binding"), so
both ends must hold the same SINIT for a device, as they must the same SID and DATAVER.

Timing is counted in main cycles. The field example in rssp1.md (250 ms cycle, deltaTime 3, lifeTime 4,
DelayTime 3) is FIELD_TIMING.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

U32 = 0xFFFFFFFF
U16 = 0xFFFF


def _pair(value: Any, name: str) -> tuple[int, int]:
    if isinstance(value, str):
        value = [v for v in value.replace(" ", "").split(",") if v]
    try:
        a, b = (int(v, 0) if isinstance(v, str) else int(v) for v in value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be two 32-bit values (channel 1, channel 2), got {value!r}") from exc
    for v in (a, b):
        if not 0 <= v <= U32:
            raise ValueError(f"{name} value {v:#x} is not a 32-bit unsigned integer")
    return a, b


@dataclass(frozen=True)
class DeviceConfig:
    """One RSSP-I device as its peers know it."""

    address: int
    sid: tuple[int, int]
    dataver: tuple[int, int] = (0, 0)
    sinit: tuple[int, int] | None = None  # None: T(0) = SID, as every device in the captures
    name: str = ""

    def __post_init__(self) -> None:
        if not 0 <= self.address <= U16:
            raise ValueError(f"RSSP-I address {self.address:#x} is not 16-bit")
        object.__setattr__(self, "sid", _pair(self.sid, "SID"))
        object.__setattr__(self, "dataver", _pair(self.dataver, "DATAVER"))
        if self.sinit is not None:
            object.__setattr__(self, "sinit", _pair(self.sinit, "SINIT"))

    @property
    def timestamp_seed(self) -> tuple[int, int]:
        return self.sinit if self.sinit is not None else self.sid

    @classmethod
    def from_mapping(cls, m: Mapping[str, Any]) -> "DeviceConfig":
        """From a YAML/JSON-like mapping: {address: 0x29, sid: [..,..], dataver: [..,..], sinit: [..]}."""
        address = m["address"]
        return cls(
            address=int(address, 0) if isinstance(address, str) else int(address),
            sid=m["sid"],
            dataver=m.get("dataver", (0, 0)),
            sinit=m.get("sinit"),
            name=str(m.get("name", "")),
        )


@dataclass(frozen=True)
class LinkTiming:
    """Main cycle and the freshness limits, in cycles (rssp1.md "Synchronisation and freshness").

    delta_time: an RSD whose TC is this many cycles or more after the last accepted one (frames lost)
        or older than the receiver's estimate of the sender's TC (delayed) breaks the link.
    life_time: an SSR counts only within this many cycles of the SSE it answers; at most one SSE is
        sent per life_time cycles.
    delay_time: this many local cycles without a good RSD drops the link.
    """

    cycle_s: float = 0.25
    delta_time: int = 3
    life_time: int = 4
    delay_time: int = 3

    def __post_init__(self) -> None:
        if not self.cycle_s > 0:
            raise ValueError("cycle must be positive")
        for name in ("delta_time", "life_time", "delay_time"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be at least one cycle")

    @property
    def resync_bound_cycles(self) -> int:
        """Worst case from a link loss ending to the link up again, when the bearer works.

        Detection takes at most delay_time cycles; the next SSE leaves within life_time cycles of the
        previous one; SSE -> SSR -> first verified RSD takes up to 3 more cycles on a bearer whose
        latency is under a cycle (each side acts on what it received in its next cycle).
        """
        return self.delay_time + self.life_time + 3


FIELD_TIMING = LinkTiming()


@dataclass(frozen=True)
class LinkConfig:
    """Both ends of one link as seen from `local`."""

    local: DeviceConfig
    peer: DeviceConfig
    timing: LinkTiming = field(default_factory=LinkTiming)


def link_config_from_mapping(m: Mapping[str, Any]) -> LinkConfig:
    """A link from configuration (YAML/JSON already parsed), e.g.

        {"local": {"address": "0x0101", "sid": ["0x1A2B3C4D", "0x5E6F7081"], "dataver": [1, 2]},
         "peer":  {"address": "0x0029", "sid": ["0x311616DC", "0x07643EDE"], "dataver": [10, 11]},
         "timing": {"cycle_s": 0.25, "delta_time": 3, "life_time": 4, "delay_time": 3}}
    """
    unknown = set(m) - {"local", "peer", "timing"}
    if unknown:
        raise ValueError(f"unknown link settings: {sorted(unknown)}")
    timing = m.get("timing", {})
    bad = set(timing) - {"cycle_s", "delta_time", "life_time", "delay_time"}
    if bad:
        raise ValueError(f"unknown timing settings: {sorted(bad)}")
    return LinkConfig(
        DeviceConfig.from_mapping(m["local"]), DeviceConfig.from_mapping(m["peer"]), LinkTiming(**timing)
    )
