"""State files (`augnet-up.json`, `augnet-console.json`): where tools find a console's URL and its bootstrap
credentials. Written owner-only (0600) from the first byte: created with that mode and renamed into place,
never written world-readable and narrowed afterwards."""

from __future__ import annotations

import json
import os
from pathlib import Path

PRIVATE_FILE_MODE = 0o600  # tokens and passwords inside


def read_state(path: Path | str | None) -> dict:
    """The state file's fields, or {} when there is none (or it is not a JSON object)."""
    if path is None:
        return {}
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def write_private(path: Path | str, data: dict) -> Path:
    """Write `data` as JSON to `path`, mode 0600, atomically (a reader sees the old file or the new one)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, PRIVATE_FILE_MODE)
    try:
        os.fchmod(fd, PRIVATE_FILE_MODE)  # a leftover temporary file keeps its mode through O_CREAT
        with os.fdopen(fd, "w") as f:
            fd = -1
            f.write(json.dumps(data, indent=2))
        os.replace(tmp, path)
    finally:
        if fd >= 0:
            os.close(fd)
        if tmp.exists():
            tmp.unlink()
    return path


def update_state(path: Path | str, **fields) -> Path:
    """Change some fields of a state file, keeping the others."""
    return write_private(path, {**read_state(path), **fields})
