"""Import rules, checked in a fresh interpreter: augwire stands on the standard library and numpy only,
and the caster imports nothing from augnet."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]


def _modules_after(code: str) -> list[str]:
    """Top-level names in sys.modules after running `code` in a new interpreter from the repo root."""
    probe = code + "\nimport json, sys\nprint(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))"
    out = subprocess.run([sys.executable, "-c", probe], cwd=REPO_ROOT, capture_output=True, text=True,
                         check=True, env={"PYTHONPATH": str(REPO_ROOT), "PATH": "/usr/bin:/bin"})
    return json.loads(out.stdout.splitlines()[-1])


def test_augwire_needs_only_stdlib_and_numpy():
    loaded = _modules_after("import augwire.chunked, augwire.crc24q, augwire.errors, augwire.passwords, "
                            "augwire.rtcm_framing")
    foreign = [m for m in loaded if m not in sys.stdlib_module_names and m not in ("augwire", "numpy")
               and not m.startswith("_")]
    assert foreign == []


def test_passwords_do_not_load_numpy():
    assert "numpy" not in _modules_after("import augwire.passwords")


def test_caster_imports_nothing_from_augnet():
    code = ("import pkgutil, importlib, ntrip_caster\n"
            "for m in pkgutil.walk_packages(ntrip_caster.__path__, 'ntrip_caster.'):\n"
            "    importlib.import_module(m.name)")
    loaded = _modules_after(code)
    assert "ntrip_caster" in loaded and "augwire" in loaded
    assert "augnet" not in loaded
