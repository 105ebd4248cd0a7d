"""Reading and writing topology files (augnet-topology/1 JSON, GeoJSON export, railML import)."""

from __future__ import annotations

import json
import os

from augnet.track.railml import MAX_RAILML_BYTES, topology_from_railml
from augnet.track.topology import Topology, TopologyError


def load_topology(path: str | os.PathLike) -> Topology:
    try:
        with open(path, encoding="utf-8") as f:
            d = json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise TopologyError("file", f"cannot read topology {os.fspath(path)}: {exc}") from None
    return Topology.from_dict(d)


def save_topology(topology: Topology, path: str | os.PathLike) -> None:
    with open(path, "w", encoding="utf-8") as f:
        json.dump(topology.to_dict(), f, indent=1)


def save_geojson(topology: Topology, path: str | os.PathLike) -> None:
    with open(path, "w", encoding="utf-8") as f:
        json.dump(topology.to_geojson(), f, indent=1)


def import_railml(path: str | os.PathLike) -> Topology:
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_RAILML_BYTES + 1)
    except OSError as exc:
        raise TopologyError("file", f"cannot read railML {os.fspath(path)}: {exc}") from None
    return topology_from_railml(data)
