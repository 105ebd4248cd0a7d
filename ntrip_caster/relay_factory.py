"""A stream factory that serves every client of a `vrs` mountpoint the stream of one source
mountpoint, through the per-client path a real VRS factory uses.

It is not a VRS (no synthesis: the centre's factory comes in a later issue); it exists so the
GGA-driven per-client machinery -- wait for a position, open, reposition, per-client sink with its
own backlog bound and chunk encoding -- can be exercised and load-tested end to end now.

Config: `factory = "ntrip_caster.relay_factory:from_env"` relays the mountpoint named by
$AUGNET_RELAY_SOURCE (default LOAD); or construct `MountRelayFactory("BASE01")` in code.
"""

from __future__ import annotations

import os
from typing import Any

from .gga import GgaFix
from .stream_factory import Sink


class _Handle:
    __slots__ = ("factory", "client_id", "fix")

    def __init__(self, factory: "MountRelayFactory", client_id: str, fix: GgaFix) -> None:
        self.factory = factory
        self.client_id = client_id
        self.fix = fix

    def update_position(self, fix: GgaFix) -> None:
        self.fix = fix
        self.factory.updates += 1

    def close(self) -> None:
        self.factory.sinks.pop(self.client_id, None)


class MountRelayFactory:
    def __init__(self, source_mount: str) -> None:
        self.source_mount = source_mount
        self.sinks: dict[str, Sink] = {}
        self.opened = 0
        self.updates = 0
        self._untap: Any = None

    def attach(self, caster: Any) -> None:
        """Called by the caster at start-up: read the source mountpoint in-process."""
        self._untap = caster.tap(self.source_mount, self._on_data)

    def _on_data(self, data: bytes) -> None:
        for sink in list(self.sinks.values()):
            sink(data)

    def open(self, client_id: str, mount: str, fix: GgaFix, sink: Sink) -> _Handle:
        self.sinks[client_id] = sink
        self.opened += 1
        return _Handle(self, client_id, fix)


def from_env() -> MountRelayFactory:
    return MountRelayFactory(os.environ.get("AUGNET_RELAY_SOURCE", "LOAD"))
