"""Golden files: writing them and naming the first difference from them."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

DATA_DIR = Path(__file__).resolve().parent / "data"
FORMAT = 1
# Items held as integers of 0.1 mm and the difference allowed [0.1 mm]: positions within 0.5 mm (a
# restructure may reorder float sums), DD corrections within one rounding step. Everything else is exact.
TOLERANCE_TENTH_MM = {"position": 5, "dd_iono": 1, "dd_trop": 1, "vrs_code": 1, "vrs_phase": 1}
# ... and conditioned float ambiguities [milli-cycles]: within one rounding step
TOLERANCE_MILLI_CYCLES = {"a_fixed_mcyc": 1}


_TOLERANCES = {**TOLERANCE_TENTH_MM, **TOLERANCE_MILLI_CYCLES}


def path_of(case: str) -> Path:
    return DATA_DIR / f"{case}.json.gz"


def dumps(case: str, result: dict) -> bytes:
    """The golden file's bytes: canonical JSON, gzip without a time stamp (the same run, the same bytes)."""
    doc = {"case": case, "format": FORMAT, "meta": result["meta"], "epochs": result["epochs"]}
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return gzip.compress(text.encode(), compresslevel=9, mtime=0)


def load(case: str) -> dict:
    return json.loads(gzip.decompress(path_of(case).read_bytes()))


def _short(v) -> str:
    s = json.dumps(v, sort_keys=True)
    return s if len(s) <= 300 else s[:300] + "..."


def _first_diff(a, b, tol: int, where: str = "") -> str | None:
    """Where a (recorded) and b (now) first differ, or None."""
    if where.endswith("['fixed_dd']") and isinstance(a, list) and isinstance(b, list) and a != b:
        gone = [x for x in a if x not in b]
        new = [x for x in b if x not in a]
        return f"{where} (satellite, reference, slot, cycles): recorded only {_short(gone)}, now only {_short(new)}"
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                return f"{where}[{k!r}] recorded {_short(a.get(k, '<absent>'))}, now {_short(b.get(k, '<absent>'))}"
            d = _first_diff(a[k], b[k], _TOLERANCES.get(k, tol), f"{where}[{k!r}]")
            if d:
                return d
        return None
    if isinstance(a, list) and isinstance(b, list):
        for i, (x, y) in enumerate(zip(a, b)):
            d = _first_diff(x, y, tol, f"{where}[{i}]")
            if d:
                return d
        if len(a) != len(b):
            return f"{where} length recorded {len(a)}, now {len(b)}"
        return None
    if tol and isinstance(a, int) and isinstance(b, int) and not isinstance(a, bool) and not isinstance(b, bool):
        return None if abs(a - b) <= tol else f"{where} recorded {a}, now {b} (allowed {tol})"
    if type(a) is not type(b) or a != b:
        return f"{where} recorded {_short(a)}, now {_short(b)}"
    return None


def first_difference(case: str, recorded: dict, now: dict) -> str | None:
    """A sentence naming the first epoch and item where `now` differs from the golden record."""
    rec_epochs, now_epochs = recorded["epochs"], now["epochs"]
    for i, (a, b) in enumerate(zip(rec_epochs, now_epochs)):
        for key in sorted(set(a) | set(b)):
            if key not in a or key not in b:
                return f"{case}: epoch {i} (t={a.get('t')}): item {key!r} " + (
                    "is new" if key not in a else "is gone")
            d = _first_diff(a[key], b[key], _TOLERANCES.get(key.rsplit(".", 1)[-1], 0), f"[{key!r}]")
            if d:
                return f"{case}: epoch {i} (t={a.get('t')}): item {d}"
    if len(rec_epochs) != len(now_epochs):
        return f"{case}: {len(rec_epochs)} epochs recorded, {len(now_epochs)} now (the first {min(len(rec_epochs), len(now_epochs))} agree)"
    d = _first_diff(recorded["meta"], now["meta"], 0)
    return f"{case}: meta{d}" if d else None
