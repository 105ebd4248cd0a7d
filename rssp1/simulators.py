"""The RBC and ATP simulators as runnable UDP services (`python -m rssp1 rbc-sim` / `atp-sim`).

Each reads one JSON link file (stdlib json, so the package stays dependency-free):

    {"local":  {"address": "0x0029", "sid": ["0x311616DC", "0x07643EDE"], "dataver": [10, 11]},
     "peer":   {"address": "0x0101", "sid": ["0x1A2B3C4D", "0x5E6F7081"], "dataver": [1, 2]},
     "timing": {"cycle_s": 0.25, "delta_time": 3, "life_time": 4, "delay_time": 3},
     "keys":   {"1": "<64 hex digits>"},                       optional: open-bearer envelope
     "max_correction_age_s": 10.0,                             RBC only
     "balises": {"70001": [3, 1000000]}}                       ATP only: group -> [track, chainage mm]

and prints one line per alarm as it is raised, so an operator (or a test) sees the time to alarm.
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any, Callable

from rssp1.atp import AtpSimulator, BaliseLocation
from rssp1.config import link_config_from_mapping
from rssp1.endpoint import Endpoint
from rssp1.envelope import Keyring, SealedEndpoint
from rssp1.rbc import DEFAULT_MAX_CORRECTION_AGE_S, RbcSimulator
from rssp1.transport import UdpLink


def load_link_file(path: str | Path) -> dict[str, Any]:
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: {exc}") from exc
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object")
    return data


def parse_host_port(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit():
        raise ValueError(f"{text!r}: expected HOST:PORT")
    return host or "0.0.0.0", int(port)


def endpoint_from(settings: dict[str, Any]):
    link = link_config_from_mapping({k: v for k, v in settings.items() if k in ("local", "peer", "timing")})
    endpoint = Endpoint(link.local, link.peer, link.timing)
    keys = settings.get("keys")
    if keys:
        endpoint = SealedEndpoint(endpoint, Keyring.from_mapping(keys))
    return endpoint, link.timing


def build_rbc(settings: dict[str, Any]) -> RbcSimulator:
    endpoint, _timing = endpoint_from(settings)
    return RbcSimulator(endpoint, max_correction_age_s=float(settings.get("max_correction_age_s", DEFAULT_MAX_CORRECTION_AGE_S)))


def build_atp(settings: dict[str, Any]) -> AtpSimulator:
    endpoint, _timing = endpoint_from(settings)
    balises = {int(k, 0): BaliseLocation(int(v[0]), int(v[1])) for k, v in settings.get("balises", {}).items()}
    return AtpSimulator(endpoint, balises)


async def serve(
    node, cycle_s: float, listen: tuple[str, int], peer: tuple[str, int], *,
    duration_s: float | None = None, echo: Callable[[str], None] = print,
) -> UdpLink:
    """Run `node` (RbcSimulator or AtpSimulator) on UDP until cancelled or `duration_s` has passed,
    echoing each alarm as it is raised."""
    link = await UdpLink.open(node, cycle_s, listen, peer)
    shown = 0
    cycles = None if duration_s is None else max(1, int(duration_s / cycle_s))
    runner = asyncio.create_task(link.run(cycles))
    try:
        while not runner.done():
            await asyncio.sleep(cycle_s / 4)
            for alarm in node.alarms[shown:]:
                fields = getattr(alarm, "code", None)
                name = fields.name if fields is not None else alarm.kind
                where = getattr(alarm, "section_id", None)
                echo(f"{alarm.at_s:.3f} ALARM {name}" + (f" section {where}" if where not in (None, 0xFFFF) else ""))
            shown = len(node.alarms)
        await runner
    finally:
        link.close()
    return link
