"""Golden test: today's outputs of the estimators, the VRS streams, the RTCM encoder, the wire primitives and
the centre process, pinned epoch by epoch (tests/golden/data, written by `python -m tests.golden.record`).

A failure names the first epoch and item that differ. Bytes and integers must be equal; positions may
move by 0.5 mm and DD corrections and VRS observations by 0.1 mm (float sums in another order). Code that
moves or renames an API the cases call updates `probes.py`, never the data. When a difference is intended,
say why in the commit and rewrite that case's file with `python -m tests.golden.record CASE`.

    PYTHONPATH=$PWD python -m pytest -q tests/golden                 # every case
    PYTHONPATH=$PWD python -m pytest -q tests/golden -m "not slow"   # without the simulated centre run
    PYTHONPATH=$PWD python -m pytest -q tests/golden -k onboard_static
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import SHARED_DATA
from tests.golden.cases import CASES, GOLDEN_SOURCE, run
from tests.golden.compare import first_difference, load, path_of
from tests.golden.simd import needs_pinning, pinned_env

REPO = Path(__file__).resolve().parents[2]
# The cases in a process of their own: generous, it only stops a hang (all twelve take ~35 s of CPU).
CASE_TIMEOUT_S = 600


def _params():
    for name, (_, needs_shared, slow) in CASES.items():
        marks = ([pytest.mark.shared_data] if needs_shared else []) + ([pytest.mark.slow] if slow else [])
        yield pytest.param(name, marks=marks, id=name)


def _golden(case: str) -> dict:
    source, epochs, items = GOLDEN_SOURCE.get(case, (case, None, None))
    if not path_of(source).exists():
        pytest.fail(f"no golden file {path_of(source)}: run `python -m tests.golden.record {source}`")
    doc = load(source)
    if epochs is not None:
        doc["epochs"] = [{k: v for k, v in rec.items() if k in items} for rec in doc["epochs"][:epochs]]
    return doc


@pytest.fixture(scope="module")
def pinned_runs(request, tmp_path_factory) -> Path | None:
    """With numpy's AVX-512 loops on here: every golden case this session runs, computed once in one process at
    the AVX2 level (simd.py; the cases share the simulated run); None when they run in this process."""
    if not needs_pinning():
        return None
    cases = [item.callspec.params["case"] for item in request.session.items
             if getattr(item, "originalname", "") == "test_golden" and hasattr(item, "callspec")]
    cases = [c for c in dict.fromkeys(cases) if SHARED_DATA.is_dir() or not CASES[c][1]]
    out = tmp_path_factory.mktemp("golden")
    subprocess.run([sys.executable, "-m", "tests.golden.record", "--json", str(out), *cases], cwd=REPO,
                   env={**pinned_env(), "PYTHONPATH": str(REPO)}, check=True, timeout=CASE_TIMEOUT_S)
    return out


def _run(case: str, needs_shared: bool, pinned: Path | None) -> dict:
    if pinned is None:
        return run(case, SHARED_DATA if needs_shared else None)
    return json.loads((pinned / f"{case}.json").read_text())


@pytest.mark.parametrize("case", list(_params()))
def test_golden(case, pinned_runs):
    _, needs_shared, _ = CASES[case]
    if needs_shared and not SHARED_DATA.is_dir():
        pytest.skip(f"real recordings not available: {SHARED_DATA} is absent")
    recorded = _golden(case)
    now = _run(case, needs_shared, pinned_runs)
    diff = first_difference(case, recorded, now)
    assert diff is None, diff
